// A recording's frames after a takeover, at the session itself (no DDS): frames ahead of the next one wait for the
// agent to resend what is missing, unless the agent says it no longer holds those frames (an earlier owner
// confirmed them and no copy of them survived it). Then they are counted dropped, said so, and the scan goes on
// from the oldest frame that exists instead of waiting for ever.
#include <gtest/gtest.h>

#include <chrono>
#include <opencv2/core.hpp>
#include <thread>

#include "service/session.hpp"
#include "wire/messages.hpp"

namespace facescan::service {
namespace {

class SessionGap : public ::testing::Test {
 protected:
    void SetUp() override {
        camera_.every_frame = true;
        ASSERT_TRUE(session_.setCamera(camera_).isOk());
        // An empty scene (zero depth): a valid payload that the pipeline rejects, never a decoding drop.
        const cv::Mat depth(camera_.intrinsics.height_px, camera_.intrinsics.width_px, CV_16UC1, cv::Scalar(0));
        ASSERT_TRUE(encoder_.encode(depth, cv::Mat(), frame_).isOk());
    }

    FrameFate push(uint32_t seq, uint32_t oldest_kept_seq) {
        frame_.seq = seq;
        facescan_wire_RgbdFrame msg = wire::toMessage("gap", frame_);
        msg.oldest_kept_seq = oldest_kept_seq;
        return session_.pushFrame(msg);
    }

    wire::CameraInfoData camera_;
    ServerParams params_;
    Session session_{"gap", params_, [] {}};
    wire::FrameEncoder encoder_;
    wire::EncodedFrame frame_;
};

TEST_F(SessionGap, AFrameAheadWaitsForTheResendWhileTheAgentStillHoldsTheMissingFrames) {
    EXPECT_EQ(push(0, 0), FrameFate::kAccepted);
    EXPECT_EQ(push(1, 0), FrameFate::kAccepted);
    // Frames 2-4 are on their way again (the agent holds them from 1 on): wait for them.
    EXPECT_EQ(push(5, 1), FrameFate::kAhead);
    EXPECT_EQ(session_.nextSeq(), 2u);
    EXPECT_EQ(push(2, 1), FrameFate::kAccepted);
    EXPECT_EQ(session_.stats().frames_dropped, 0u);
}

TEST_F(SessionGap, FramesTheAgentNoLongerHoldsAreCountedLostAndTheScanGoesOn) {
    EXPECT_EQ(push(0, 0), FrameFate::kAccepted);
    // The agent holds frames from 7 on: 1-6 were confirmed by an owner whose copy is gone.
    EXPECT_EQ(push(9, 7), FrameFate::kAhead);  // 7 and 8 are still to come, in order
    EXPECT_EQ(session_.nextSeq(), 7u);
    const SessionStats stats = session_.stats();
    EXPECT_EQ(stats.frames_dropped, 6u);
    EXPECT_NE(stats.detail.find("frames 1-6 lost"), std::string::npos) << stats.detail;
    EXPECT_EQ(push(7, 7), FrameFate::kAccepted);
    EXPECT_EQ(push(8, 7), FrameFate::kAccepted);
    EXPECT_EQ(push(9, 7), FrameFate::kAccepted);
    EXPECT_EQ(session_.nextSeq(), 10u);
    EXPECT_EQ(session_.stats().frames_dropped, 6u);
    // Each processed frame rewrites the detail; the loss is still said after them.
    const std::string later = session_.stats().detail;
    EXPECT_NE(later.find("frames 1-6 lost"), std::string::npos) << later;
}

TEST_F(SessionGap, AnOlderAgentThatSaysNothingOfItsFramesIsAlwaysWaitedFor) {
    EXPECT_EQ(push(0, 0), FrameFate::kAccepted);
    EXPECT_EQ(push(6, 0), FrameFate::kAhead);
    EXPECT_EQ(session_.nextSeq(), 1u);
    EXPECT_EQ(session_.stats().frames_dropped, 0u);
}

}  // namespace
}  // namespace facescan::service
