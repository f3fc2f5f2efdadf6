// The takeover rule (takeover.hpp): the newest copy wins, a copy of a later epoch than the last claim seen is refused
// (the view is behind: that data belongs to a newer owner), and so is a copy older than what the agent still keeps.
#include "service/takeover.hpp"

#include <gtest/gtest.h>

namespace facescan::service {
namespace {

wire::SessionOwnerData claim(uint32_t epoch, uint32_t confirmed_seq) {
    wire::SessionOwnerData c;
    c.session_id = "s1";
    c.owner_id = "srv-dead";
    c.epoch = epoch;
    c.confirmed_seq = confirmed_seq;
    return c;
}

wire::ReplicaData copy(uint32_t epoch, uint32_t next_seq) {
    wire::ReplicaData r;
    r.session_id = "s1";
    r.epoch = epoch;
    r.next_seq = next_seq;
    return r;
}

TEST(Takeover, TheNewestCopyWinsAndTheNewClaimIsOneEpochLater) {
    const wire::ReplicaData standby = copy(2, 40), disk = copy(2, 55);
    const TakeoverChoice c = chooseTakeover(claim(2, 30), &standby, &disk, false);
    ASSERT_EQ(c.kind, TakeoverChoice::Kind::kFromCopy);
    EXPECT_EQ(c.copy, &disk);
    EXPECT_EQ(c.epoch, 3u);
    const wire::ReplicaData older_disk = copy(1, 90);
    EXPECT_EQ(chooseTakeover(claim(2, 30), &standby, &older_disk, false).copy,
              &standby);  // the epoch before the frames
}

TEST(Takeover, AReplicaOfALaterEpochThanTheClaimSeenIsLeftUntouched) {
    const wire::ReplicaData disk = copy(4, 80);
    const TakeoverChoice c = chooseTakeover(claim(2, 30), nullptr, &disk, false);
    EXPECT_EQ(c.kind, TakeoverChoice::Kind::kRefuse);
    EXPECT_EQ(c.copy, nullptr);
    EXPECT_NE(c.why.find("belongs to epoch 4, later than the last claim seen (server 'srv-dead', epoch 2)"),
              std::string::npos)
        << c.why;
    EXPECT_NE(c.why.find("leaves that data untouched"), std::string::npos) << c.why;
}

TEST(Takeover, ACopyOlderThanTheAgentsKeptFramesIsRefusedAndNoCopyStartsOverOnlyFromTheFirstFrame) {
    const wire::ReplicaData standby = copy(2, 20);
    const TakeoverChoice old = chooseTakeover(claim(2, 30), &standby, nullptr, false);
    EXPECT_EQ(old.kind, TakeoverChoice::Kind::kRefuse);
    EXPECT_NE(old.why.find("older than what the agent still keeps (from frame 30)"), std::string::npos) << old.why;
    EXPECT_EQ(chooseTakeover(claim(1, 0), nullptr, nullptr, false).kind, TakeoverChoice::Kind::kFromFirstFrame);
    EXPECT_EQ(chooseTakeover(claim(1, 12), nullptr, nullptr, false).kind, TakeoverChoice::Kind::kWait);
}

TEST(Takeover, ALiveScanContinuesFromAnOlderCopyOrWithoutOneSinceItNeverWaitsForMissedFrames) {
    const wire::ReplicaData standby = copy(2, 20);
    const TakeoverChoice old = chooseTakeover(claim(2, 30), &standby, nullptr, true);
    EXPECT_EQ(old.kind, TakeoverChoice::Kind::kFromCopy);
    EXPECT_EQ(old.copy, &standby);
    EXPECT_EQ(old.epoch, 3u);
    EXPECT_EQ(chooseTakeover(claim(1, 12), nullptr, nullptr, true).kind, TakeoverChoice::Kind::kFromFirstFrame);
    // Still never over a copy of a later epoch: the view is behind, whatever the scan.
    const wire::ReplicaData later = copy(4, 80);
    EXPECT_EQ(chooseTakeover(claim(2, 30), nullptr, &later, true).kind, TakeoverChoice::Kind::kRefuse);
}

}  // namespace
}  // namespace facescan::service
