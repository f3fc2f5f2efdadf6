// A server's claims as other processes see them, on real Cyclone DDS: withdrawing one claim (its session finished,
// or raised to a new writer) must leave the server's other claims alive at every reader. With MANUAL_BY_PARTICIPANT
// liveliness it did not: Cyclone tracks such writers of a remote participant by one lease, that of the writer it
// saw first, and when that writer goes, the lease that replaces it expires at once (the difference of two equal
// durations), so every other writer of the participant reads not alive until it writes again. Servers took live
// scans over from owners that were finishing them. A second process holds the claims, as a server would.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>
#include <thread>

#include "test_domain.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/messages.hpp"
#include "wire/topics.hpp"

namespace facescan::wire {
namespace {

using namespace std::chrono_literals;

constexpr double kLeaseS = 3.0;  // the loopback profile's
constexpr auto kWithdrawAfter = 2s;
constexpr auto kHoldFor = 6s;

SessionOwnerData claimOf(const std::string& session_id) {
    SessionOwnerData o;
    o.session_id = session_id;
    o.owner_id = "s1";
    o.state = OwnerState::kActive;
    return o;
}

// Child process: a server's part. Claims "first" and then "second", each with its own writer, asserts the
// participant and writes its claims as the server does (Server::assertProgress, Server::refreshClaims), and
// withdraws "first" (deletes its writer) after kWithdrawAfter.
[[noreturn]] void holdTwoClaims(uint32_t domain) {
    auto participant = Participant::create({domain, "loopback"});
    if (!participant) _exit(10);
    auto topic = Topic<facescan_wire_SessionOwner>::create(*participant);
    if (!topic) _exit(11);
    const auto writerFor = [&](const std::string& session_id) {
        const Qos qos = withClaimLiveliness(claimWriterQos(claimStrength(1, "s1", session_id)), kLeaseS);
        return Writer<facescan_wire_SessionOwner>::create(*topic, &qos);
    };
    const SessionOwnerData first = claimOf("first");
    const SessionOwnerData second = claimOf("second");
    std::optional<Writer<facescan_wire_SessionOwner>> first_writer;
    if (auto w = writerFor(first.session_id))
        first_writer.emplace(std::move(*w));
    else
        _exit(12);
    if (!first_writer->waitForReaders(1, 20s) || !first_writer->write(toMessage(first)).isOk()) _exit(13);
    std::this_thread::sleep_for(200ms);  // discovered after the first: Cyclone's lease is the first writer's
    auto second_writer = writerFor(second.session_id);
    if (!second_writer || !second_writer->write(toMessage(second)).isOk()) _exit(14);
    const auto start = std::chrono::steady_clock::now();
    auto written = start;
    while (std::chrono::steady_clock::now() - start < kHoldFor) {
        std::this_thread::sleep_for(250ms);
        if (dds_assert_liveliness(participant->handle()) < 0) _exit(15);
        const auto now = std::chrono::steady_clock::now();
        if (first_writer && now - start >= kWithdrawAfter) first_writer.reset();
        if (now - written >= std::chrono::duration<double>(kLeaseS / 3)) {
            written = now;
            if (first_writer && !first_writer->write(toMessage(first)).isOk()) _exit(16);
            if (!second_writer->write(toMessage(second)).isOk()) _exit(17);
        }
    }
    _exit(0);
}

TEST(ClaimLiveliness, WithdrawingOneClaimLeavesTheServersOtherClaimsAliveElsewhere) {
    const uint32_t domain = facescan::testing::privateDomain(76);
    const pid_t child = fork();  // before this process starts DDS: a forked DDS instance hangs
    ASSERT_GE(child, 0);
    if (child == 0) holdTwoClaims(domain);
    auto participant = Participant::create({domain, "loopback"});
    ASSERT_TRUE(participant.isOk()) << participant.status().toString();
    auto topic = Topic<facescan_wire_SessionOwner>::create(*participant);
    ASSERT_TRUE(topic.isOk()) << topic.status().toString();
    const Qos qos = sessionOwnerQos();
    auto reader = Reader<facescan_wire_SessionOwner>::create(*topic, &qos);
    ASSERT_TRUE(reader.isOk()) << reader.status().toString();

    bool second_alive = false;
    bool first_gone = false;
    int second_lapses = 0;
    int wstatus = 0;
    while (waitpid(child, &wstatus, WNOHANG) == 0) {
        reader->waitForData(100ms);
        auto n = reader->take([&](const facescan_wire_SessionOwner& m, const dds_sample_info_t& info) {
            const std::string id = fromDds(m.session_id);  // keys are valid in invalid samples too
            const bool alive = info.instance_state == DDS_IST_ALIVE;
            if (id == "first" && !alive) first_gone = true;
            if (id != "second") return;
            if (alive)
                second_alive = true;
            else if (second_alive)
                ++second_lapses;
        });
        ASSERT_TRUE(n.isOk()) << n.status().toString();
    }
    ASSERT_TRUE(WIFEXITED(wstatus) && WEXITSTATUS(wstatus) == 0) << "claim holder's exit status " << wstatus;
    ASSERT_TRUE(second_alive) << "the second claim never arrived";
    EXPECT_TRUE(first_gone) << "the withdrawn claim never read as gone: the test saw nothing happen";
    EXPECT_EQ(second_lapses, 0) << "the claim that stayed read as not alive while its holder lived and wrote it";
}

}  // namespace
}  // namespace facescan::wire
