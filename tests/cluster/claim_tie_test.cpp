// Two claims at one epoch, over real DDS with the real server and agent. The ownership strength breaks such a tie
// (the epoch, then a hash of server and session), not what each claim holds: a server that placed the scan from a
// view that missed the owner's claim (cut off when the scan started) can win it once the cut heals, from the first
// frame, after the owner has confirmed frames and the agent has dropped them. This test process plays that server:
// it writes the winning claim at the owner's epoch, with nothing confirmed. The owner must not yield to it (the
// frames it confirmed would be gone for good) but claim the scan again at the next epoch and finish it whole.
#include <gtest/gtest.h>

#include <cstdio>

#include "cluster_rig.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/dds.hpp"
#include "wire/topics.hpp"

namespace facescan::testing {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

constexpr int kFrames = 200;

TEST(ClaimTie, AnOwnerWhoseConfirmedFramesTheTieWinnerLacksClaimsItAgainAndLosesNoFrame) {
    ClusterRig rig("claimtie", 75);
    // A session whose claim by "srv-z" outranks srv-a's at the same epoch.
    std::string session;
    for (int i = 0; session.empty(); ++i) {
        const std::string id = "tie-" + std::to_string(i);
        if (wire::claimStrength(1, "srv-z", id) > wire::claimStrength(1, "srv-a", id)) session = id;
    }
    rig.startServer("srv-a");
    ASSERT_TRUE(rig.waitForServers(1, 30s));
    rig.startAgent(session, kFrames, "max", ",period=900");
    ASSERT_EQ(rig.waitForOwner(session, 30s), "srv-a") << readText(rig.agentLog(session));
    // The owner's data dir confirms frames (a lone server), and the agent drops them.
    ASSERT_TRUE(standbyHoldsACopy(rig, session)) << readText(rig.agentLog(session));
    ASSERT_LT(rig.published(session), kFrames - 30) << "the recording ended too soon for the test";

    auto participant = wire::Participant::create({static_cast<uint32_t>(std::stoul(rig.domain())), "loopback"});
    ASSERT_TRUE(participant.isOk()) << participant.status().toString();
    auto owner_topic = wire::Topic<facescan_wire_SessionOwner>::create(*participant);
    ASSERT_TRUE(owner_topic.isOk());
    const wire::Qos qos = wire::claimWriterQos(wire::claimStrength(1, "srv-z", session));
    auto claim = wire::Writer<facescan_wire_SessionOwner>::create(*owner_topic, &qos);
    ASSERT_TRUE(claim.isOk());
    wire::SessionOwnerData tie;
    tie.session_id = session;
    tie.owner_id = "srv-z";
    tie.epoch = 1;
    tie.state = wire::OwnerState::kActive;  // serving from the first frame, nothing confirmed
    ASSERT_TRUE(claim->write(wire::toMessage(tie)).isOk());
    std::printf("claimed %s at epoch 1 as srv-z after %d frames were sent to srv-a\n", session.c_str(),
                rig.published(session));

    const fs::path summary = rig.dataDir("srv-a") / session / "summary.json";
    ASSERT_TRUE(waitUntil([&] { return fs::exists(summary); }, 120s))
        << readText(rig.serverLog("srv-a")) << readText(rig.agentLog(session));
    const std::string server_log = readText(rig.serverLog("srv-a"));
    EXPECT_NE(server_log.find("claiming it again at epoch 2"), std::string::npos) << server_log;
    EXPECT_EQ(server_log.find("gave it up"), std::string::npos) << server_log;
    EXPECT_EQ(server_log.find("lost"), std::string::npos) << server_log;
    const std::string text = readText(summary);
    EXPECT_EQ(summaryNumber(text, "received"), kFrames) << text;
    EXPECT_EQ(summaryNumber(text, "dropped"), 0) << text;
    ASSERT_EQ(rig.agent(session).wait(60s), 0) << readText(rig.agentLog(session));
    EXPECT_EQ(jsonField(text, "frames_digest"),
              lastMatch(readText(rig.agentLog(session)), "frames digest ([0-9a-f]{16})"))
        << "the integrated frames are not the agent's";
}

}  // namespace
}  // namespace facescan::testing
