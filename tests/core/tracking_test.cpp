// The pipeline against the synthetic Kinect: a head turning in front of the camera (the camera flies around the
// head in the head's frame) with known poses; registration must follow the true trajectory.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "recon/icp.hpp"
#include "recon/reconstructor.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::recon {
namespace {

float rotationDeg(const Pose& t) {
    return std::acos(std::clamp((t.linear().trace() - 1.0f) * 0.5f, -1.0f, 1.0f)) * 57.29578f;
}

struct Rendered {
    RgbdFrame frame;
    cv::Mat mask;
    Pose T_c0_ci;  // true camera i in camera 0 (world)
};

Rendered renderFrame(const synth::KinectSimulator& sim, int i) {
    Rendered r;
    synth::FrameTruth truth;
    sim.render(i, r.frame, &truth);
    r.mask = truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead);
    r.T_c0_ci = sim.poseAt(0) * truth.T_camera_head.inverse();
    return r;
}

// ICP of frame k against frame 0's point cloud, from the true pose and from the previous one: both converge to
// the truth (the head constrains all six degrees of freedom).
TEST(IcpOnHead, ConvergesToTruePoseFromTruthAndFromIdentity) {
    synth::SequenceParams sp;
    sp.frames = 20;
    sp.noise = false;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    const Intrinsics k = sim.intrinsics();
    const FilterParams fp;
    DepthFilter filter(k, fp);
    SurfacePyramid target, source;
    target.allocate(k, 3);
    source.allocate(k, 3);
    const Rendered f0 = renderFrame(sim, 0), f5 = renderFrame(sim, 5);
    ASSERT_GT(filter.filter(f0.frame.depth_m, f0.mask, target), 1000);
    ASSERT_GT(filter.filter(f5.frame.depth_m, f5.mask, source), 1000);
    Icp icp(IcpParams{});
    for (const Pose& start : {f5.T_c0_ci, Pose(Pose::Identity())}) {
        Pose estimate = start;
        const TrackingResult r = icp.align(source, target, Pose::Identity(), start, estimate);
        ASSERT_EQ(r.status, TrackingStatus::kTracked) << trackingStatusName(r.status);
        const Pose err = f5.T_c0_ci.inverse() * estimate;
        EXPECT_LT(err.translation().norm(), 0.001f);
        EXPECT_LT(rotationDeg(err), 0.2f);
    }
}

// Known-transform recovery over seeded random motions: frame 4 of a noise-free sequence against frame 0's
// point cloud, ICP started from the true pose disturbed by a random rigid motion (up to 15 mm and 4 deg, a few
// frames of fast head motion at 30 Hz). Nearly every start must converge to the truth; a start that is rejected
// (kLargeMotion, kDiverged) counts as a failure, a wrong pose reported as tracked is counted separately and must
// not happen at all.
TEST(IcpOnHead, RecoversKnownTransformsFromSeededRandomStarts) {
    synth::SequenceParams sp;
    sp.frames = 20;
    sp.noise = false;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    const Intrinsics k = sim.intrinsics();
    DepthFilter filter(k, FilterParams{});
    SurfacePyramid target, source;
    target.allocate(k, 3);
    source.allocate(k, 3);
    const Rendered f0 = renderFrame(sim, 0), f4 = renderFrame(sim, 4);
    ASSERT_GT(filter.filter(f0.frame.depth_m, f0.mask, target), 1000);
    ASSERT_GT(filter.filter(f4.frame.depth_m, f4.mask, source), 1000);
    Icp icp(IcpParams{});
    std::mt19937 rng(20261122);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    constexpr int kTrials = 40;
    int recovered = 0, wrong_but_tracked = 0;
    for (int trial = 0; trial < kTrials; ++trial) {
        Eigen::Vector3f t(unit(rng), unit(rng), unit(rng)), axis(unit(rng), unit(rng), unit(rng));
        t *= 0.015f * std::abs(unit(rng)) / std::max(t.norm(), 1e-6f);
        const float angle_rad = 4.0f / 57.29578f * std::abs(unit(rng));
        Pose disturbance = Pose::Identity();
        disturbance.linear() = Eigen::AngleAxisf(angle_rad, axis.normalized()).toRotationMatrix();
        disturbance.translation() = t;
        const Pose start = f4.T_c0_ci * disturbance;
        Pose estimate = start;
        const TrackingResult r = icp.align(source, target, Pose::Identity(), start, estimate);
        const Pose err = f4.T_c0_ci.inverse() * estimate;
        const bool close = err.translation().norm() < 0.001f && rotationDeg(err) < 0.3f;
        if (r.status == TrackingStatus::kTracked && close) ++recovered;
        if (r.status == TrackingStatus::kTracked && !close) ++wrong_but_tracked;
    }
    std::printf("recovered %d of %d random starts, %d wrong poses reported as tracked\n", recovered, kTrials,
                wrong_but_tracked);
    EXPECT_GE(recovered, kTrials * 95 / 100);
    EXPECT_EQ(wrong_but_tracked, 0);
}

// The camera flies around the head (the head turns in front of a fixed camera) with the Kinect noise model:
// every frame is tracked against the model and the trajectory stays within millimetres of the truth.
TEST(Reconstructor, FollowsTheTrueTrajectoryOfANoisyTurningHead) {
    synth::SequenceParams sp;
    sp.frames = 60;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
    ASSERT_TRUE(rec.initStatus().isOk());
    float max_err_m = 0.0f, max_rot_deg = 0.0f;
    for (int i = 0; i < sp.frames; ++i) {
        const Rendered f = renderFrame(sim, i);
        const FrameResult r = rec.processFrame(f.frame, f.mask);
        ASSERT_TRUE(r.integrated) << "frame " << i << ": " << trackingStatusName(r.tracking.status) << " " << r.reason;
        const Pose err = f.T_c0_ci.inverse() * r.tracking.T_world_camera;
        max_err_m = std::max(max_err_m, err.translation().norm());
        max_rot_deg = std::max(max_rot_deg, rotationDeg(err));
    }
    EXPECT_EQ(rec.framesIntegrated(), sp.frames);
    EXPECT_EQ(rec.trajectory().size(), static_cast<size_t>(sp.frames));
    EXPECT_LT(max_err_m, 0.004f);  // measured ~1-2 mm on this sequence
    EXPECT_LT(max_rot_deg, 0.5f);
    cv::Rect box;
    EXPECT_TRUE(rec.predictedHeadBox(box));
    EXPECT_GT(box.area(), 5000);
    const Mesh mesh = rec.extractMesh();
    EXPECT_GT(mesh.n_faces(), 10000u);
}

}  // namespace
}  // namespace facescan::recon
