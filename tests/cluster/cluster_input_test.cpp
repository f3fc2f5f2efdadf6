// Bad input to a cluster member, over real DDS with the service in process:
//   - replicas that are truncated, corrupt, of another format version or out of order are refused, with a
//     reason, and a full replica is requested; good ones are acknowledged round by round;
//   - a flood of bogus session ids cannot take a real scan's place, and --max-sessions holds throughout;
//   - a session announced but never fed is released, and leaves no status behind that would list it for ever.
#include <gtest/gtest.h>

#include <random>
#include <thread>

#include "sample_replica.hpp"
#include "scratch_dir.hpp"
#include "service/server.hpp"
#include "test_agent.hpp"

namespace facescan::service {
namespace {

using namespace std::chrono_literals;
using testing::privateDomain;

ServerParams inputParams(uint32_t domain, const std::string& id) {
    ServerParams p;
    p.domain = {domain, "loopback"};
    p.data_dir = testing::scratchDir("facescan-input-" + id);  // removed once the test passed
    p.server_id = id;
    p.preset = "fast";
    p.recon = recon::ReconParams::fast();
    p.snapshot_hz = 0;
    p.join_settle_s = 0.3f;
    return p;
}

// A fake owner that sends replicas to the server under test and reads its acknowledgements.
struct FakeOwner {
    std::optional<wire::Participant> participant;
    std::optional<wire::Topic<facescan_wire_SessionReplica>> replica_topic;
    std::optional<wire::Topic<facescan_wire_ReplicaAck>> ack_topic;
    std::optional<wire::Writer<facescan_wire_SessionReplica>> writer;
    std::optional<wire::Reader<facescan_wire_ReplicaAck>> acks;

    FakeOwner(uint32_t domain, const std::string& standby) {
        participant.emplace(wire::Participant::create({domain, "loopback"}).value());
        replica_topic.emplace(wire::Topic<facescan_wire_SessionReplica>::create(*participant).value());
        ack_topic.emplace(wire::Topic<facescan_wire_ReplicaAck>::create(*participant).value());
        writer.emplace(
            wire::Writer<facescan_wire_SessionReplica>::create(*replica_topic, nullptr, wire::serverPartition(standby))
                .value());
        acks.emplace(
            wire::Reader<facescan_wire_ReplicaAck>::create(*ack_topic, nullptr, wire::serverPartition("fake-owner"))
                .value());
    }
    // Sends `bytes` as round/base of the sample replica and returns the acknowledgement (round, need_full, error).
    std::optional<std::tuple<uint32_t, bool, std::string>> send(const std::vector<uint8_t>& bytes, uint32_t round,
                                                                uint32_t base_round) {
        facescan_wire_SessionReplica m{};
        const std::string session = "scan-1", target = "stby", source = "fake-owner";
        m.session_id = wire::stringView(session);
        m.target_id = wire::stringView(target);
        m.source_id = wire::stringView(source);
        m.epoch = 2;
        m.round = round;
        m.base_round = base_round;
        m.next_seq = 77;
        m.payload = wire::octetView(bytes.data(), bytes.size());
        if (!writer->write(m).isOk()) return std::nullopt;
        std::optional<std::tuple<uint32_t, bool, std::string>> got;
        const auto deadline = std::chrono::steady_clock::now() + 10s;
        while (!got && std::chrono::steady_clock::now() < deadline) {
            acks->waitForData(100ms);
            (void)acks->take([&](const facescan_wire_ReplicaAck& a, const dds_sample_info_t& info) {
                if (info.valid_data) got = std::make_tuple(a.round, a.need_full, wire::fromDds(a.error));
            });
        }
        return got;
    }
};

std::vector<uint8_t> encoded(const wire::ReplicaData& r) {
    std::vector<uint8_t> bytes;
    EXPECT_TRUE(wire::encodeReplica(r, bytes).isOk());
    return bytes;
}

TEST(ReplicaInput, BadReplicasAreRefusedWithAReasonAndAFullOneIsRequested) {
    const uint32_t domain = privateDomain(51);
    auto server = Server::create(inputParams(domain, "stby"));
    ASSERT_TRUE(server.isOk()) << server.status().toString();
    FakeOwner owner(domain, "stby");
    ASSERT_TRUE(owner.writer->waitForReaders(1, 10s));

    wire::ReplicaData full = testing::sampleReplica(6, true, "scan-1", "fake-owner");
    const std::vector<uint8_t> good = encoded(full);
    auto expectRefused = [&](const std::vector<uint8_t>& bytes, const std::string& why, const std::string& what) {
        auto ack = owner.send(bytes, 1, 0);
        ASSERT_TRUE(ack) << what << ": no acknowledgement";
        EXPECT_TRUE(std::get<1>(*ack)) << what << ": not refused";
        EXPECT_NE(std::get<2>(*ack).find(why), std::string::npos) << what << ": " << std::get<2>(*ack);
    };
    // Truncated, corrupt (a flipped byte in the compressed body), another format version.
    expectRefused(std::vector<uint8_t>(good.begin(), good.begin() + static_cast<ptrdiff_t>(good.size() / 2)),
                  "truncated", "truncated");
    std::vector<uint8_t> corrupt = good;
    corrupt[good.size() / 2] ^= 0x40;
    expectRefused(corrupt, "corrupt", "corrupt");
    std::vector<uint8_t> future = good;
    future[4] = 9;  // format version 9
    expectRefused(future, "not compatible", "another version");
    EXPECT_EQ((*server)->standbySessions(), 0) << "nothing refused may be kept";

    // A good full one is acknowledged and kept; a delta that does not continue it is refused.
    auto ack = owner.send(good, 1, 0);
    ASSERT_TRUE(ack);
    EXPECT_FALSE(std::get<1>(*ack)) << std::get<2>(*ack);
    EXPECT_EQ(std::get<0>(*ack), 1u);
    EXPECT_EQ((*server)->standbySessions(), 1);
    wire::ReplicaData gap = testing::sampleReplica(2, false, "scan-1", "fake-owner");
    gap.round = 9;
    gap.base_round = 7;
    auto refused = owner.send(encoded(gap), 9, 7);
    ASSERT_TRUE(refused);
    EXPECT_TRUE(std::get<1>(*refused));
    EXPECT_NE(std::get<2>(*refused).find("round"), std::string::npos) << std::get<2>(*refused);
    // Header and payload that disagree (a forged header) are refused as well.
    auto forged = owner.send(good, 3, 0);
    ASSERT_TRUE(forged);
    EXPECT_TRUE(std::get<1>(*forged));
}

TEST(FloodInput, BogusSessionIdsCannotStarveARealScanAndMaxSessionsHolds) {
    const uint32_t domain = privateDomain(52);
    ServerParams params = inputParams(domain, "flooded");
    params.max_sessions = 2;
    params.first_frame_timeout_s = 2.0f;  // bogus claims are released quickly (and the next one is tried)
    auto server = Server::create(params);
    ASSERT_TRUE(server.isOk()) << server.status().toString();

    // The flood: one participant announces 300 sessions that never send a frame, and sends garbage frames to 50
    // more sessions nobody announced.
    std::atomic<bool> flooding{true};
    std::thread flood([&] {
        auto p = wire::Participant::create({domain, "loopback"});
        auto info_topic = wire::Topic<facescan_wire_CameraInfo>::create(*p);
        auto frame_topic = wire::Topic<facescan_wire_RgbdFrame>::create(*p);
        auto info = wire::Writer<facescan_wire_CameraInfo>::create(*info_topic);
        std::mt19937 rng(7);
        wire::CameraInfoData camera;
        camera.source = "bogus";
        for (int i = 0; i < 300 && flooding; ++i) {
            camera.session_id = "bogus-" + std::to_string(rng());
            (void)info->write(wire::toMessage(camera));
        }
        std::vector<uint8_t> garbage(2000, 0x5a);
        for (int i = 0; i < 50 && flooding; ++i) {
            const std::string id = "nobody-" + std::to_string(rng());
            auto frames =
                wire::Writer<facescan_wire_RgbdFrame>::create(*frame_topic, nullptr, wire::sessionPartition(id));
            wire::EncodedFrame f;
            f.depth = garbage;
            (void)frames->write(wire::toMessage(id, f));
        }
        while (flooding) std::this_thread::sleep_for(50ms);  // the bogus sessions stay announced
    });

    int most_open = 0;
    std::atomic<bool> watching{true};
    std::thread watch([&] {
        while (watching) {
            most_open = std::max(most_open, (*server)->openSessions());
            std::this_thread::sleep_for(20ms);
        }
    });
    std::this_thread::sleep_for(1s);  // the flood is in
    const testing::EncodedSequence seq = testing::renderSequence(20);
    auto agent = testing::TestAgent::create(domain, "real-scan", seq.intrinsics, /*every_frame=*/true);
    ASSERT_TRUE(agent.isOk());
    ASSERT_TRUE((*agent)->waitForServer(10s));
    ASSERT_TRUE((*agent)->sendCamera().isOk());
    EXPECT_TRUE((*agent)->waitForOwner(20s)) << "the real scan got no server";
    ASSERT_TRUE((*agent)->stream(seq, 20, 0, /*end_of_stream=*/true).isOk());
    auto client = testing::TestClient::create(domain);
    ASSERT_TRUE(client.isOk());
    auto status = (*client)->waitForStatus(
        "real-scan", [](const testing::StatusCopy& s) { return s.state == facescan_wire_STATE_FINISHED; }, 30s);
    ASSERT_TRUE(status) << "the real scan never finished";
    EXPECT_EQ(status->frames_received, 20u);
    EXPECT_GT(status->frames_integrated, 15u);
    watching = false;
    watch.join();
    flooding = false;
    flood.join();
    EXPECT_LE(most_open, 2) << "--max-sessions 2 was exceeded";
    // One agent writer gets one session placed at a time: the flood holds at most one slot.
    int bogus_held = 0;
    for (const SessionStats& s : (*server)->sessions()) bogus_held += s.session_id.rfind("bogus-", 0) == 0 ? 1 : 0;
    EXPECT_LE(bogus_held, 1);
    std::filesystem::remove_all(params.data_dir);
}

// An agent that announces a scan and goes before its first frame: the server releases the session, and its last
// status ("waiting for frames") must leave the server's history with it. Otherwise `facescan sessions` lists the
// scan on this server for as long as it runs, even after another server has finished it.
TEST(FloodInput, ASessionReleasedForWantOfFramesIsNoLongerListed) {
    const uint32_t domain = privateDomain(53);
    ServerParams params = inputParams(domain, "releasing");
    params.first_frame_timeout_s = 1.0f;
    auto server = Server::create(params);
    ASSERT_TRUE(server.isOk()) << server.status().toString();
    auto client = testing::TestClient::create(domain);
    ASSERT_TRUE(client.isOk());
    {
        const testing::EncodedSequence seq = testing::renderSequence(1);
        auto agent = testing::TestAgent::create(domain, "silent", seq.intrinsics, /*every_frame=*/false);
        ASSERT_TRUE(agent.isOk());
        ASSERT_TRUE((*agent)->waitForServer(10s));
        ASSERT_TRUE((*agent)->sendCamera().isOk());
        ASSERT_TRUE((*agent)->waitForOwner(20s)) << "the announced scan got no server";
        const auto waiting = (*client)->waitForStatus(
            "silent", [](const testing::StatusCopy& s) { return s.state == facescan_wire_STATE_WAITING; }, 10s);
        ASSERT_TRUE(waiting) << "the server never said it waits for frames";
    }  // the agent goes without a frame
    const auto deadline = std::chrono::steady_clock::now() + 20s;
    while ((*server)->openSessions() > 0 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(50ms);
    ASSERT_EQ((*server)->openSessions(), 0) << "the session was never released";
    // A client that subscribes now gets what the server's status writer still holds: nothing for this scan.
    auto late = testing::TestClient::create(domain);
    ASSERT_TRUE(late.isOk());
    ASSERT_TRUE((*late)->waitForServer(10s));
    const auto stale = (*late)->waitForStatus(
        "silent", [](const testing::StatusCopy&) { return true; }, 3s);
    EXPECT_FALSE(stale) << "a released session is still listed: state " << (stale ? stale->state : 0) << ", "
                        << (stale ? stale->detail : "");
    std::filesystem::remove_all(params.data_dir);
}

}  // namespace
}  // namespace facescan::service
