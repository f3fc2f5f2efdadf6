// facescan-server under load, over real Cyclone DDS (loopback profile, a private domain per test): sessions beyond
// --max-sessions, a session flooded with frames it cannot use beside one scanning a head, frames skipped behind a
// slow first one, and a joining session whose build is slow. No mocks: the server runs the real pipeline.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <functional>
#include <opencv2/core.hpp>
#include <thread>

#include "server_rig.hpp"
#include "server_session_fixtures.hpp"
#include "wire/messages.hpp"

namespace facescan::service {
namespace {

using namespace std::chrono_literals;
using testing::EncodedSequence;
using testing::privateDomain;
using testing::StatusCopy;
using testing::TestAgent;

// Calls send(0), send(1), ... on a thread of its own until destroyed (an agent streaming all test long).
class Feed {
 public:
    explicit Feed(std::function<void(uint32_t)> send)
        : thread_([this, send = std::move(send)] {
              for (uint32_t seq = 0; !stop_; ++seq) send(seq);
          }) {}
    ~Feed() {
        stop_ = true;
        thread_.join();
    }

 private:
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

TEST(ServerSession, SessionsBeyondMaxSessionsAreRefusedWithAReason) {
    const uint32_t domain = privateDomain(15);
    ServerParams params = testParams(domain, "max");
    params.max_sessions = 1;
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto first = makeAgent(domain, "first", false);
    ASSERT_TRUE(first);
    ASSERT_TRUE(rig.client->waitForStatus(
        "first", [](const StatusCopy&) { return true; }, 5s));
    auto second = makeAgent(domain, "second", false, /*expect_owner=*/false);
    ASSERT_TRUE(second);
    auto refused = rig.client->waitForStatus(
        "second", [](const StatusCopy& s) { return s.state == facescan_wire_STATE_REFUSED; }, 5s);
    ASSERT_TRUE(refused) << "no refusal in the status";
    EXPECT_NE(refused->detail.find("--max-sessions 1"), std::string::npos) << refused->detail;
    auto reply = rig.client->command("second", facescan_wire_CMD_GET_STATUS, 5s);
    ASSERT_TRUE(reply.isOk());
    EXPECT_FALSE(reply->ok);
    EXPECT_NE(reply->error.find("refused"), std::string::npos) << reply->error;
    auto ok = rig.client->command("first", facescan_wire_CMD_GET_STATUS, 5s);
    ASSERT_TRUE(ok.isOk());
    EXPECT_TRUE(ok->ok) << ok->error;
}

// Bad input: one session fed frames that are no use (a depth image full of noise, a head filling the
// frame at 0.4 m) and a stream faster than it can process, next to a session scanning a head. The bad frames are
// rejected at detection (their cost is bounded there); the flooded session skips frames and its status says it
// is behind; the other keeps integrating. (Throttling itself is tested with CPU time in frame_load_test.)
testing::EncodedSequence badSequence() {
    testing::EncodedSequence out = testing::renderSequence(4, 1, 0.4f);  // the head fills the frame
    const recon::Intrinsics& k = out.intrinsics;
    wire::FrameEncoder encoder;
    cv::Mat depth(k.height_px, k.width_px, CV_16UC1), colour(k.height_px, k.width_px, CV_8UC3);
    cv::RNG rng(16);
    for (int i = 0; i < 4; ++i) {
        rng.fill(depth, cv::RNG::UNIFORM, 400, 1500);  // millimetres, as the test agent's CameraInfo says
        rng.fill(colour, cv::RNG::UNIFORM, 0, 256);
        out.frames.emplace_back();
        EXPECT_TRUE(encoder.encode(depth, colour, out.frames.back()).isOk());
    }
    return out;
}

TEST(ServerSession, ASessionThatFallsBehindIsReportedAndDoesNotStallAnother) {
    const uint32_t domain = privateDomain(17);
    const ServerParams params = testParams(domain, "behind");
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    const testing::EncodedSequence bad = badSequence();
    auto flooded = makeAgent(domain, "flooded", /*every_frame=*/false);
    auto steady = makeAgent(domain, "steady", false);
    ASSERT_TRUE(flooded && steady);
    // Bad frames and head frames (which cost the full loop) as fast as the writer takes them, all test long.
    Feed flood([&](uint32_t seq) {
        const auto& frames = seq % 2 ? bad.frames : sequence().frames;
        (void)flooded->sendFrame(seq, frames[seq / 2 % frames.size()]);
        if (seq % 64 == 0) std::this_thread::sleep_for(1ms);  // leave the writer's peer a breath
    });

    // The session that cannot keep up says so, by name, first in its detail; while the face is lost (the noise
    // frames), right after the advice to the person.
    auto behind = rig.client->waitForStatus(
        "flooded", [](const StatusCopy& s) { return s.behind && s.frames_skipped > 0; }, 30s);
    ASSERT_TRUE(behind) << "the flooded session was never reported behind";
    if (behind->state == facescan_wire_STATE_LOST) {
        EXPECT_NE(behind->detail.find("; behind: "), std::string::npos) << behind->detail;
    } else {
        EXPECT_EQ(behind->detail.rfind("behind: ", 0), 0u) << behind->detail;
    }

    // Meanwhile the other session scans (the single-session test's bar: throughput depends on the machine, live
    // mode skips what it cannot process; a stalled loop would integrate next to nothing). At 15 frames a second,
    // over 3 s: at 30, a CI run on a machine busy with other work integrated 7 of the 45 frames in their 1.5 s
    // (53 ms of CPU a frame beside the flood), a throughput, not a stall.
    ASSERT_TRUE(steady->stream(sequence(), 45, 15.0f, /*end_of_stream=*/false).isOk());
    auto status = rig.client->waitForStatus(
        "steady", [](const StatusCopy& s) { return s.frames_received == 45 && settled(s); }, 30s);
    ASSERT_TRUE(status) << "the steady session never settled";
    EXPECT_GE(status->frames_integrated, 10u) << status->detail << "; skipped " << status->frames_skipped;
    EXPECT_EQ(status->frames_dropped, 0u);
    auto still = rig.client->waitForStatus(
        "flooded", [](const StatusCopy& s) { return s.behind; }, 10s);
    ASSERT_TRUE(still) << "the flooded session stopped being reported behind";
    std::printf(
        "flooded: %s (received %u, skipped %u)\nsteady: %s (integrated %u of 45, skipped %u, capture-to-pose "
        "p95 %.1f ms)\n",
        still->detail.c_str(), still->frames_received, still->frames_skipped, status->detail.c_str(),
        status->frames_integrated, status->frames_skipped, status->latency_p95_ms);
}

// A live server that is behind skips frames, so the frame after the first one it fused may come many
// frames later (behind a slow first frame: 7-11 frames, the head turned by up to ~10 deg). Here the agent sends
// frame 0, then frame 11 on: every frame processed after the gap is tracked (the motion limits scale with the frame
// periods between the source timestamps, at the CameraInfo's rate), where the session used to stay lost with a
// model of one frame, searching every frame.
TEST(ServerSession, ALiveSessionTracksOnWhenFramesAfterItsFirstWereSkipped) {
    const uint32_t domain = privateDomain(18);
    const ServerParams params = testParams(domain, "skipped");
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto agent = makeAgent(domain, "skip-1", /*every_frame=*/false);
    ASSERT_TRUE(agent);
    const EncodedSequence& seq = sequence();
    ASSERT_TRUE(agent->sendFrame(0, seq.frames[0]).isOk());
    ASSERT_TRUE(rig.client->waitForStatus(
        "skip-1", [](const StatusCopy& s) { return s.frames_integrated == 1; }, 20s));
    constexpr uint32_t kFirstAfterGap = 11, kEnd = 21;
    for (uint32_t i = kFirstAfterGap; i < kEnd; ++i) {
        ASSERT_TRUE(agent->sendFrame(i, seq.frames[i]).isOk());
        std::this_thread::sleep_for(100ms);  // time to process each on a loaded machine
    }
    auto status = rig.client->waitForStatus(
        "skip-1", [](const StatusCopy& s) { return s.frames_received == 11 && settled(s); }, 20s);
    ASSERT_TRUE(status) << "status never settled";
    EXPECT_EQ(status->frames_rejected, 0u) << status->detail;
    EXPECT_GE(status->frames_integrated, 3u) << status->detail << "; skipped " << status->frames_skipped;
    EXPECT_EQ(status->state, static_cast<uint32_t>(facescan_wire_STATE_SCANNING)) << status->detail;
}

// A session's engine (every per-frame buffer and the detector's cascade: 25 ms on an idle 2-core server,
// over 100 ms with four sessions running) was built on the server's intake thread, so every running session got no
// frame meanwhile and skipped them. Here a joining camera of 3072 x 3072 pixels makes the build take long (hundreds
// of ms); the running session must keep getting its frames all the while.
TEST(ServerSession, AJoiningSessionsBuildDoesNotHoldUpTheFramesOfARunningOne) {
    const uint32_t domain = privateDomain(19);
    const ServerParams params = testParams(domain, "joining");
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto running = makeAgent(domain, "running", /*every_frame=*/false);
    ASSERT_TRUE(running);
    std::atomic<uint32_t> sent{0};
    Feed feed([&](uint32_t seq) {
        (void)running->sendFrame(seq, sequence().frames[seq % sequence().frames.size()]);
        sent = seq + 1;
        std::this_thread::sleep_for(33ms);
    });
    // Lost at the intake: a live reader keeps the last 8 samples, so an intake held up for longer loses frames on
    // the way (seq gaps, frames_dropped). Frames skipped behind a busy worker are the CPU's doing, not the intake's,
    // and grow with whatever else the machine runs.
    const auto lost = [](const StatusCopy& s) { return s.frames_dropped; };
    auto before = rig.client->waitForStatus(
        "running", [](const StatusCopy& s) { return s.frames_integrated >= 10; }, 30s);
    ASSERT_TRUE(before) << "the running session never scanned";

    recon::Intrinsics big = sequence().intrinsics;
    big.width_px = big.height_px = 3072;
    big.cx_px = big.cy_px = 1535.5f;
    auto joiner = TestAgent::create(domain, "joiner", big, /*every_frame=*/false);
    ASSERT_TRUE(joiner.isOk()) << joiner.status().toString();
    ASSERT_TRUE((*joiner)->waitForServer(10s));
    const uint32_t sent_at_join = sent;
    const auto t_join = std::chrono::steady_clock::now();
    ASSERT_TRUE((*joiner)->sendCamera().isOk());
    ASSERT_TRUE((*joiner)->waitForOwner(60s)) << "the server never took the joining session";
    const double join_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_join).count();
    // The status of a moment later counts every frame sent until the joiner's reader matched.
    const uint32_t sent_until_owned = sent;
    auto after = rig.client->waitForStatus(
        "running", [&](const StatusCopy& s) { return s.frames_received >= sent_until_owned + 3; }, 30s);
    ASSERT_TRUE(after) << "the running session stopped receiving frames";
    const uint32_t during = sent_until_owned - sent_at_join;
    const uint32_t lost_during = lost(*after) - lost(*before);
    std::printf(
        "joining took %.2f s: the running session lost %u of the %u frames sent meanwhile (and after) at its "
        "intake\n",
        join_s, lost_during, during);
    // With the intake thread stuck in the build, 16 of 28 were lost here.
    EXPECT_LE(lost_during, during / 3) << after->detail;
}

}  // namespace
}  // namespace facescan::service
