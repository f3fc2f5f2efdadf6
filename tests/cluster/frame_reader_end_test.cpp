// How a session's frame reader that nothing takes from any more ends, over real DDS with the real server and agent
// (service/lingering_reader.hpp): this test process holds a second reader of a recording's frames and takes
// nothing from it. Cyclone 0.10 then retries the delivery to the full reader on this process's receive thread, and
// the process hears nothing else (no announcement of the server gets through); deleted in that state, the reader
// would wait for ever. Drained as the server drains it (drainedAndUnwritten, from a thread that deletes nothing),
// it lets the process hear again at once, says when its agent is gone, and is then deleted without waiting.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <future>

#include "cluster_rig.hpp"
#include "service/lingering_reader.hpp"
#include "wire/dds.hpp"
#include "wire/topics.hpp"

namespace facescan::testing {
namespace {

using namespace std::chrono_literals;

// Announcements that arrive within `window`.
int announcementsWithin(wire::Reader<facescan_wire_ServerAnnounce>& reader, std::chrono::milliseconds window) {
    int n = 0;
    const auto end = std::chrono::steady_clock::now() + window;
    do {
        auto got = reader.take(
            [&](const facescan_wire_ServerAnnounce&, const dds_sample_info_t& info) { n += info.valid_data ? 1 : 0; });
        EXPECT_TRUE(got.isOk()) << got.status().toString();
        std::this_thread::sleep_for(50ms);
    } while (std::chrono::steady_clock::now() < end);
    return n;
}

TEST(FrameReaderEnd, AReaderNothingTakesFromLingersDrainedAndEndsOnceItsAgentHasGone) {
    ClusterRig rig("readerend", 70);
    rig.startServer("srv-a");
    ASSERT_TRUE(rig.waitForServers(1, 30s));
    auto participant = wire::Participant::create({static_cast<uint32_t>(std::stoul(rig.domain())), "loopback"});
    ASSERT_TRUE(participant.isOk()) << participant.status().toString();
    auto frame_topic = wire::Topic<facescan_wire_RgbdFrame>::create(*participant);
    auto announce_topic = wire::Topic<facescan_wire_ServerAnnounce>::create(*participant);
    ASSERT_TRUE(frame_topic.isOk() && announce_topic.isOk());
    const wire::Qos qos = wire::frameReaderQos();  // the server's own
    auto created = wire::Reader<facescan_wire_RgbdFrame>::create(*frame_topic, &qos, wire::sessionPartition("rec"));
    auto announcements = wire::Reader<facescan_wire_ServerAnnounce>::create(*announce_topic);
    ASSERT_TRUE(created.isOk() && announcements.isOk());
    auto frames = std::make_unique<wire::Reader<facescan_wire_RgbdFrame>>(std::move(*created));
    ASSERT_GT(announcementsWithin(*announcements, 1s), 0) << "the server announces itself four times a second";

    rig.startAgent("rec", 3000, "max", ",period=900");
    ASSERT_EQ(rig.waitForOwner("rec", 30s), "srv-a") << readText(rig.agentLog("rec"));
    // The agent's writer waits for this reader too: it fills (16 frames) and the agent stalls.
    ASSERT_TRUE(waitUntil([&] { return rig.published("rec") >= 1; }, 60s)) << readText(rig.agentLog("rec"));
    std::this_thread::sleep_for(2s);
    (void)announcementsWithin(*announcements, 0ms);  // what arrived before the reader filled
    const int while_full = announcementsWithin(*announcements, 2s);
    std::printf("announcements heard in 2 s with a full frame reader: %d\n", while_full);
    // The premise: without it the rest proves nothing (a Cyclone that no longer blocks its receive thread).
    ASSERT_EQ(while_full, 0) << "the full reader did not stop this process's receive thread";

    // Drained every 50 ms, as the server's intake drains a reader it gave up.
    const dds_entity_t reader = frames->handle();
    std::atomic<bool> stop{false}, unwritten{false};
    std::thread drainer([&] {
        while (!stop) {
            if (service::drainedAndUnwritten(reader)) {
                unwritten = true;
                return;
            }
            std::this_thread::sleep_for(50ms);
        }
    });
    const int drained = announcementsWithin(*announcements, 2s);
    std::printf("announcements heard in 2 s with the reader drained: %d\n", drained);
    EXPECT_GT(drained, 0) << "drained, the reader lets the receive thread on";
    EXPECT_FALSE(unwritten.load()) << "its agent still writes";

    rig.agent("rec").kill9();
    // Its writer goes with the agent's lease (3 s).
    EXPECT_TRUE(waitUntil([&] { return unwritten.load(); }, 30s)) << "the reader still counts a writer";
    stop = true;
    drainer.join();
    // Nothing can fill it any more: its deletion ends (before the fix it waited for ever on a full reader).
    auto deleted = std::async(std::launch::async, [&] { frames.reset(); });
    ASSERT_EQ(deleted.wait_for(20s), std::future_status::ready) << "deleting the drained, unwritten reader hangs";
}

}  // namespace
}  // namespace facescan::testing
