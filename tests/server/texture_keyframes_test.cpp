// The texture's colour keyframes (service/texture_keyframes.hpp): which frames are kept as the head turns, the
// count and byte bounds, raw colour, and the views they decode to.
#include "service/texture_keyframes.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "wire/colour_codec.hpp"

namespace facescan::service {
namespace {

// The depth camera turned by yaw about the vertical (the head turning in front of it, seen from the head).
recon::Pose poseAt(float yaw_deg) {
    recon::Pose T = recon::Pose::Identity();
    T.linear() = Eigen::AngleAxisf(yaw_deg * 3.14159265f / 180, Eigen::Vector3f::UnitY()).toRotationMatrix();
    return T;
}

std::vector<uint8_t> jpeg(int width, int height, uint8_t grey) {
    std::vector<uint8_t> out;
    EXPECT_TRUE(wire::encodeColourJpeg(cv::Mat(height, width, CV_8UC3, cv::Scalar::all(grey)), 90, out).isOk());
    return out;
}

TEST(TextureKeyframes, KeepsViewsThatCoverTheHeadNotFramesWhereItHeldStill) {
    KeyframeParams params;
    params.min_angle_deg = 4.5f;  // every fifth degree of the turn
    TextureKeyframes keyframes(params);
    const std::vector<uint8_t> colour = jpeg(64, 48, 120);
    // 100 frames held still, then a turn of 40 degrees in 1-degree steps.
    uint32_t seq = 0;
    for (int i = 0; i < 100; ++i) keyframes.offer(seq++, wire::ColourCodecId::kJpeg, colour, poseAt(0));
    EXPECT_EQ(keyframes.count(), 1u);
    for (int yaw = 1; yaw <= 40; ++yaw) keyframes.offer(seq++, wire::ColourCodecId::kJpeg, colour, poseAt(float(yaw)));
    EXPECT_EQ(keyframes.count(), 9u);  // 0, 5, 10, ..., 40
    EXPECT_EQ(keyframes.bytes(), 9 * colour.size());
    EXPECT_EQ(keyframes.offered(), 140u);
}

TEST(TextureKeyframes, StaysWithinItsBoundsAndKeepsTheWidestCoverage) {
    const std::vector<uint8_t> colour = jpeg(64, 48, 120);
    KeyframeParams params;
    params.min_angle_deg = 2;
    params.max_keyframes = 5;
    TextureKeyframes keyframes(params);
    for (int yaw = -40; yaw <= 40; yaw += 2) {
        keyframes.offer(0, wire::ColourCodecId::kJpeg, colour, poseAt(float(yaw)));
        ASSERT_LE(keyframes.count(), 5u);
    }
    // The five kept spread over the whole turn, not the first five 2 degrees apart.
    const wire::CameraInfoData camera;
    wire::CameraInfoData small = camera;
    small.intrinsics.width_px = 64;
    small.intrinsics.height_px = 48;
    const auto views = keyframes.views(small, nullptr);
    ASSERT_EQ(views.size(), 5u);
    float lo = 90, hi = -90;
    for (const recon::TextureView& v : views) {
        const Eigen::Vector3f axis = v.T_colour_mesh.linear().transpose() * Eigen::Vector3f::UnitZ();
        const float yaw = std::atan2(axis.x(), axis.z()) * 180 / 3.14159265f;
        lo = std::min(lo, yaw), hi = std::max(hi, yaw);
    }
    EXPECT_GT(hi - lo, 60.0f) << "from " << lo << " to " << hi;

    // The byte bound: room for three payloads.
    KeyframeParams by_bytes;
    by_bytes.min_angle_deg = 2;
    by_bytes.max_bytes = size_t{1} << 20;
    TextureKeyframes bounded(by_bytes);
    const std::vector<uint8_t> big(400'000, 1);  // not decoded here: only its size counts
    for (int yaw = -40; yaw <= 40; yaw += 4) bounded.offer(0, wire::ColourCodecId::kJpeg, big, poseAt(float(yaw)));
    EXPECT_LE(bounded.bytes(), by_bytes.max_bytes);
    EXPECT_EQ(bounded.count(), 2u);
}

TEST(TextureKeyframes, RawColourIsNotKeptAndBadJpegIsLeftOutWithANote) {
    TextureKeyframes keyframes;
    EXPECT_FALSE(keyframes.offer(0, wire::ColourCodecId::kRawBgr, std::vector<uint8_t>(640 * 480 * 3), poseAt(0)));
    EXPECT_EQ(keyframes.rawSkipped(), 1u);
    EXPECT_EQ(keyframes.count(), 0u);

    wire::CameraInfoData camera;
    camera.intrinsics.width_px = 64;
    camera.intrinsics.height_px = 48;
    // The colour camera 3 cm to the side of the depth camera: views carry T_colour_depth after the depth pose.
    camera.T_colour_depth.translation() = Eigen::Vector3f(-0.03f, 0, 0);
    ASSERT_TRUE(keyframes.offer(1, wire::ColourCodecId::kJpeg, jpeg(64, 48, 200), poseAt(0)));
    ASSERT_TRUE(keyframes.offer(2, wire::ColourCodecId::kJpeg, std::vector<uint8_t>(100, 7), poseAt(30)));
    std::vector<std::string> notes;
    const auto views = keyframes.views(camera, &notes);
    ASSERT_EQ(views.size(), 1u);
    ASSERT_EQ(notes.size(), 1u);
    EXPECT_NE(notes[0].find("frame 2"), std::string::npos) << notes[0];
    EXPECT_NEAR(cv::mean(views[0].colour_bgr)[0], 200, 2);
    EXPECT_TRUE(views[0].T_colour_mesh.translation().isApprox(Eigen::Vector3f(-0.03f, 0, 0)));

    KeyframeParams bad;
    bad.max_keyframes = -1;
    EXPECT_FALSE(bad.validate().isOk());
}

// A takeover continues the texture from the old owner's keyframes (a replica carries them): they come back as they
// were, within this session's own bounds, and each change shows in version() so that a replica carries them only
// when they changed.
TEST(TextureKeyframes, SavedKeyframesRestoreWithinTheBoundsAndEveryChangeShowsInTheVersion) {
    const std::vector<uint8_t> colour = jpeg(64, 48, 120);
    KeyframeParams params;
    params.min_angle_deg = 5;
    TextureKeyframes owner(params);
    const uint64_t v0 = owner.version();
    for (int yaw = 0; yaw <= 40; yaw += 10) owner.offer(uint32_t(yaw), wire::ColourCodecId::kJpeg, colour, poseAt(yaw));
    ASSERT_EQ(owner.count(), 5u);
    EXPECT_GT(owner.version(), v0);
    const uint64_t v1 = owner.version();
    EXPECT_FALSE(owner.offer(99, wire::ColourCodecId::kJpeg, colour, poseAt(41)));  // too near 40: no change
    EXPECT_EQ(owner.version(), v1);
    const std::vector<wire::ReplicaKeyframe> saved = owner.save();
    ASSERT_EQ(saved.size(), 5u);
    EXPECT_EQ(saved[2].seq, 20u);

    TextureKeyframes taker(params);
    taker.restore(saved);
    EXPECT_EQ(taker.count(), 5u);
    EXPECT_EQ(taker.bytes(), owner.bytes());
    EXPECT_NE(taker.version(), 0u);
    // The restored views cover the head as the old owner's did: a frame near one of them adds nothing.
    EXPECT_FALSE(taker.offer(100, wire::ColourCodecId::kJpeg, colour, poseAt(21)));
    EXPECT_TRUE(taker.offer(101, wire::ColourCodecId::kJpeg, colour, poseAt(60)));

    KeyframeParams smaller = params;
    smaller.max_keyframes = 3;
    TextureKeyframes bounded(smaller);
    bounded.restore(saved);
    EXPECT_EQ(bounded.count(), 3u) << "another server's settings bound what it restores";
    bounded.restore({});
    EXPECT_EQ(bounded.count(), 0u);
}

}  // namespace
}  // namespace facescan::service
