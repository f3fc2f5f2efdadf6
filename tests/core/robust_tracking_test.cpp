// One seeded sequence per robustness case, run as facescan-server runs frames
// (recon/scan_step.hpp: model-based segmentation while tracking, detection otherwise, re-acquisition with
// verification after a loss, robust integration): the share of frames tracked, that no wrong pose is ever fused,
// and that nothing but the head ends up in the model. Plus the pieces on their own: a deliberately wrong
// re-acquisition hypothesis is rejected, robust integration keeps an occluder out even when the mask lets it in,
// a frame without a head is "no head", the advice, and no allocation in the tracked frame loop.
// The built-in head keeps the tests independent of the data folder; the figures for the real scan are
// facescan-bench's (README: robustness scenarios).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <optional>
#include <vector>

#include "allocation_counter.hpp"  // counts heap allocations (this executable only)
#include "eval/accuracy.hpp"
#include "eval/scenario_figures.hpp"
#include "recon/model_agreement.hpp"
#include "recon/scan_step.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::recon {
namespace {

float angleDeg(const Pose& t) { return Eigen::AngleAxisf(t.linear()).angle() * 57.29578f; }

synth::SequenceParams scenario(const char* name) {
    synth::SequenceParams p;
    EXPECT_TRUE(synth::applyScenario(name, p).isOk()) << name;
    return p;
}

FacePipeline makePipeline(const Intrinsics& k) {
    StatusOr<FacePipeline> p = FacePipeline::create({}, k, ColourCamera::registeredTo(k));
    EXPECT_TRUE(p.isOk()) << p.status().toString();
    return std::move(p).value();
}

// A whole sequence through scanFrame, with the truth kept for the figures.
struct ScenarioRun {
    std::vector<std::optional<Pose>> estimate, truth;
    std::vector<int> head_pixels;
    std::vector<ScanStep> steps;  // per frame (reason strings included)
    eval::ScenarioFigures figures;
    int head_found = 0, invalid_input = 0, occluding_pixels = 0;
};

ScenarioRun runScenario(const synth::SequenceParams& sp, const ReconParams& params = ReconParams::faceDefaults()) {
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    Reconstructor rec(sim.intrinsics(), params);
    EXPECT_TRUE(rec.initStatus().isOk()) << rec.initStatus().toString();
    FacePipeline pipeline = makePipeline(sim.intrinsics());
    ScenarioRun run;
    const Pose T_c0_head = sim.poseAt(0);
    RgbdFrame frame;
    synth::FrameTruth truth;
    for (int i = 0; i < sp.frames; ++i) {
        sim.render(i, frame, &truth);
        ScanStep step;
        scanFrame(pipeline, rec, frame, step);
        run.truth.emplace_back(T_c0_head * truth.T_camera_head.inverse());
        run.estimate.push_back(step.frame.tracked ? std::optional<Pose>(step.frame.tracking.T_world_camera)
                                                  : std::nullopt);
        run.head_pixels.push_back(truth.head_pixels);
        run.head_found += step.head.found;
        run.invalid_input += step.frame.tracking.status == TrackingStatus::kInvalidInput;
        run.occluding_pixels += step.frame.occluding_pixels;
        run.steps.push_back(std::move(step));
    }
    run.figures = eval::scenarioFigures(sim, run.head_pixels, run.truth, run.estimate, rec.extractMesh());
    eval::printScenario(run.figures);
    return run;
}

// Every frame tracked, no wrong pose, no torso in the model, and the head found from the model once tracked.
void expectEveryFrameTrackedFromTheModel(const ScenarioRun& run, int frames) {
    EXPECT_EQ(run.figures.tracked_in_view, frames);
    EXPECT_EQ(run.figures.wrong_poses, 0) << "max error " << run.figures.max_pose_err_mm << " mm";
    EXPECT_EQ(run.figures.foreign_vertices, 0) << "torso fused";
    int from_model = 0;
    for (const ScanStep& s : run.steps) from_model += s.head.from_model;
    EXPECT_GE(from_model, frames - 10) << "once tracked, the head comes from the model, not from detection";
}

TEST(Robustness, TheGentleSequenceIsTrackedInEveryFrameFromTheModel) {
    synth::SequenceParams sp = scenario("gentle");
    sp.frames = 90;
    sp.seed = 17;
    const ScenarioRun run = runScenario(sp);
    EXPECT_EQ(run.figures.losses, 0);
    expectEveryFrameTrackedFromTheModel(run, sp.frames);
}

// ReconParams::model_level 1 (the model cast at half resolution): ICP pairs the frame's levels with the coarser
// model's, the segmenter reads each depth pixel's prediction from the model pixel covering it, and the predicted
// box is in depth pixels. Before the segmenter knew the scale, every frame fell back to detection.
TEST(Robustness, AHalfResolutionModelTracksTheGentleSequenceFromTheModel) {
    synth::SequenceParams sp = scenario("gentle");
    sp.frames = 60;
    sp.seed = 17;
    ReconParams params = ReconParams::faceDefaults();
    params.model_level = 1;
    const ScenarioRun run = runScenario(sp, params);
    expectEveryFrameTrackedFromTheModel(run, sp.frames);
}

// The wide turn (the fastest motion of the scenarios), 60 frames, run with `params`: every frame must still be
// tracked from the model, and no pose further from the truth than with the defaults (a cast and a fusion after
// every frame), give or take a millimetre.
constexpr int kWideTurnFrames = 60;
ScenarioRun wideTurnAsWellAsTheDefault(const ReconParams& params, const char* what) {
    synth::SequenceParams sp = scenario("wide");
    sp.frames = kWideTurnFrames;
    sp.seed = 23;
    const ScenarioRun every = runScenario(sp);
    ScenarioRun other = runScenario(sp, params);
    expectEveryFrameTrackedFromTheModel(other, sp.frames);
    EXPECT_LT(other.figures.max_pose_err_mm, every.figures.max_pose_err_mm + 1.0f);
    std::printf("wide turn, worst pose error: %.2f mm by default, %.2f mm %s\n", every.figures.max_pose_err_mm,
                other.figures.max_pose_err_mm, what);
    return other;
}

// ReconParams::model_cast_every 2 (a loaded server's first economy): the frames between casts register against
// the cast of the frame before, from that frame's pose. The model is cast after half the frames (and the first
// two).
TEST(Robustness, CastingTheModelAfterEveryOtherFrameTracksTheWideTurnAsWell) {
    ReconParams params = ReconParams::faceDefaults();
    params.model_cast_every = 2;
    const ScenarioRun other = wideTurnAsWellAsTheDefault(params, "with a cast after every other frame");
    int casts = 0;
    for (const ScanStep& s : other.steps) casts += s.frame.model_cast;
    EXPECT_LE(casts, kWideTurnFrames / 2 + 2);
    EXPECT_GE(casts, kWideTurnFrames / 2);
}

// ReconParams::fuse_every 2 and 3 (a loaded server's last economy steps): one tracked frame in N is fused, and
// the model is cast after the fused ones only: frames 0 and 1 (the first two are always fused), then 1 + N,
// 1 + 2N, ...; a frame left out costs no integration, and is registered on the coarser levels only.
TEST(Robustness, FusingEveryOtherOrThirdFrameTracksTheWideTurnAsWell) {
    for (const int n : {2, 3}) {
        ReconParams params = ReconParams::faceDefaults();
        params.fuse_every = n;
        const ScenarioRun other =
            wideTurnAsWellAsTheDefault(params, n == 2 ? "fusing every other frame" : "fusing every third frame");
        int fused = 0;
        for (int i = 0; i < kWideTurnFrames; ++i) {
            const FrameResult& r = other.steps[static_cast<size_t>(i)].frame;
            ASSERT_TRUE(r.tracked) << i << ": " << r.reason;
            EXPECT_EQ(r.integrated, i < 2 || (i - 1) % n == 0) << "frame " << i << ", one in " << n;
            EXPECT_EQ(r.model_cast, r.integrated) << "frame " << i << ": cast after each fused frame, and only then";
            // ReconParams::unfused_finest_level (1 by default): the frames left out are registered coarse.
            EXPECT_EQ(r.finest_level, r.integrated ? 0 : 1) << "frame " << i;
            if (!r.integrated) {
                EXPECT_EQ(r.ms.integrate, 0.0f) << "frame " << i;
            }
            fused += r.integrated;
        }
        EXPECT_EQ(fused, 1 + (kWideTurnFrames - 2) / n + 1) << "one in " << n;
    }
}

// A live server that is behind skips frames: the frame after a gap may have moved further than one frame allows,
// so it is registered at every level (and verified, and then fused, when its fit moved that far) even where
// fuse_every would leave it out; the next frame, one period later (give or take the camera clock's jitter), is
// registered coarse again.
TEST(Robustness, AFrameAfterSkippedOnesIsRegisteredAtEveryLevel) {
    synth::SequenceParams sp = scenario("wide");
    sp.frames = 60;
    sp.seed = 29;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    ReconParams params = ReconParams::faceDefaults();
    params.fuse_every = 3;
    Reconstructor rec(sim.intrinsics(), params);
    FacePipeline pipeline = makePipeline(sim.intrinsics());
    RgbdFrame frame;
    int after_gap = 0, unfused_after_gap = 0, coarse = 0;
    for (int i = 0; i < sp.frames; ++i) {
        if (i > 5 && i % 5 == 0) continue;  // skipped, as a server that is behind does
        sim.render(i, frame, nullptr);
        frame.timestamp_ns += (i % 3) * 2'000'000;  // a camera's clock jitters: 2 ms is still the next frame
        ScanStep step;
        scanFrame(pipeline, rec, frame, step);
        ASSERT_TRUE(step.frame.tracked) << i << ": " << step.frame.reason;
        if (i > 10 && i % 5 == 1) {
            EXPECT_EQ(step.frame.finest_level, 0) << "frame " << i << ", after a skipped one";
            ++after_gap;
            unfused_after_gap += !step.frame.integrated;
        } else if (!step.frame.integrated) {
            EXPECT_EQ(step.frame.finest_level, 1) << "frame " << i;
            ++coarse;
        }
        if (step.frame.integrated) {
            EXPECT_EQ(step.frame.finest_level, 0) << "frame " << i << ", fused";
        }
    }
    EXPECT_EQ(after_gap, 10);  // frames 11, 16, ..., 56
    EXPECT_GE(coarse, 20);
    EXPECT_GE(unfused_after_gap, 3) << "the check above needs frames after a gap that are not fused";
}

// A loaded server switches a live session's model level (Reconstructor::setModelLevel): full resolution, half
// from frame 20, full again from frame 40; how often it casts (setModelCastEvery): after every other frame from
// frame 30 to 49; and how often it fuses (setFuseEvery): every other frame from frame 52. Every frame stays tracked
// from the model, and each switch applies at the next cast.
TEST(Robustness, SwitchingTheModelLevelMidScanKeepsTracking) {
    synth::SequenceParams sp = scenario("gentle");
    sp.frames = 60;
    sp.seed = 19;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
    FacePipeline pipeline = makePipeline(sim.intrinsics());
    const Pose T_c0_head = sim.poseAt(0);
    RgbdFrame frame;
    synth::FrameTruth truth;
    int from_model = 0;
    float worst_mm = 0.0f;
    for (int i = 0; i < sp.frames; ++i) {
        if (i == 20) rec.setModelLevel(1);
        if (i == 40) rec.setModelLevel(0);
        if (i == 30) rec.setModelCastEvery(2);
        if (i == 50) rec.setModelCastEvery(1);
        if (i == 52) rec.setFuseEvery(2);
        EXPECT_EQ(rec.modelLevel(), i <= 20 || i > 40 ? 0 : 1) << "frame " << i << ": the level of the last cast";
        sim.render(i, frame, &truth);
        ScanStep step;
        scanFrame(pipeline, rec, frame, step);
        ASSERT_TRUE(step.frame.tracked) << i << ": " << step.frame.reason;
        // From frame 30 the model is cast after every other frame: not after 30, 32, ..., 38. The change of level
        // at 40 casts at once, then again every other frame: not after 41, 43, ..., 49. From 50, every fused frame;
        // from 52 every other frame is fused (53, 55, ...), and only fused frames are cast after.
        const bool fused = i < 52 || i % 2 == 1;
        EXPECT_EQ(step.frame.integrated, fused) << "frame " << i;
        const bool skipped = (i >= 30 && i < 40 && i % 2 == 0) || (i > 40 && i < 50 && i % 2 == 1) || !fused;
        EXPECT_EQ(step.frame.model_cast, !skipped) << "frame " << i;
        from_model += step.head.from_model;
        const Pose err = (T_c0_head * truth.T_camera_head.inverse()).inverse() * step.frame.tracking.T_world_camera;
        worst_mm = std::max(worst_mm, 1000.0f * err.translation().norm());
    }
    EXPECT_GE(from_model, sp.frames - 10) << "the segmenter follows the model at either level";
    EXPECT_LT(worst_mm, 10.0f) << "no wrong pose across the switches";
    EXPECT_EQ(rec.trajectory().size(), static_cast<size_t>(sp.frames)) << "every tracked frame has its pose";
    EXPECT_EQ(rec.framesIntegrated(), 56);
}

TEST(Robustness, WideFastTurnsAboveATorsoAreTracked) {
    synth::SequenceParams sp = scenario("wide");
    sp.frames = 150;  // a whole yaw cycle: 0 -> 60 -> 0 -> -60 -> 0 deg at up to 2.8 deg a frame
    sp.seed = 18;
    const ScenarioRun run = runScenario(sp);
    EXPECT_GE(run.figures.trackedShare(), 0.95);
    EXPECT_EQ(run.figures.wrong_poses, 0) << "max error " << run.figures.max_pose_err_mm << " mm";
    EXPECT_EQ(run.figures.foreign_vertices, 0) << "torso fused";
    EXPECT_EQ(run.invalid_input, 0);
}

TEST(Robustness, ChinOnTheChestKeepsTheHeadAndFusesNoTorso) {
    synth::SequenceParams sp = scenario("chin");
    sp.frames = 90;  // one nod: 0 -> 30 deg down onto the chest -> 0
    sp.seed = 19;
    const ScenarioRun run = runScenario(sp);
    EXPECT_EQ(run.head_found, sp.frames) << "the head must be kept in every frame";
    EXPECT_EQ(run.figures.tracked_in_view, sp.frames);
    EXPECT_EQ(run.figures.wrong_poses, 0);
    EXPECT_EQ(run.figures.foreign_vertices, 0) << "torso fused";
    for (const ScanStep& s : run.steps) EXPECT_TRUE(s.head.from_model || !s.tracked_before);
}

TEST(Robustness, ReacquiresAfterTheHeadLeftTheViewAndCameBackTurned) {
    synth::SequenceParams sp = scenario("gap");
    sp.gap_start_frame = 25;
    sp.gap_turn_deg = -35.0f;  // leaves at yaw +10 deg, back at +19.5 - 35 deg: 25 deg from the last pose
    sp.frames = 25 + 2 * sp.gap_walk_frames + sp.gap_frames + 20;
    sp.seed = 20;
    const ScenarioRun run = runScenario(sp);
    EXPECT_EQ(run.figures.losses, 1);
    EXPECT_EQ(run.figures.reacquired, 1);
    EXPECT_LE(run.figures.worst_reacquire_frames, 10);
    EXPECT_GE(run.figures.worst_return_deg, 20.0) << "the gap must really turn the head";
    EXPECT_EQ(run.figures.wrong_poses, 0) << "max error " << run.figures.max_pose_err_mm << " mm";
    EXPECT_EQ(run.figures.foreign_vertices, 0);
    EXPECT_EQ(run.invalid_input, 0) << "a frame without a head is no_head, never invalid input";
    // Frames without a head are no_head and ask the person to come back; the scan before the loss is kept.
    int no_head = 0;
    for (const ScanStep& s : run.steps) no_head += s.frame.tracking.status == TrackingStatus::kNoHead;
    EXPECT_GE(no_head, sp.gap_frames);
    const ScanStep& out_of_view = run.steps[static_cast<size_t>(sp.gap_start_frame + sp.gap_walk_frames + 5)];
    EXPECT_STREQ(out_of_view.advice, "face lost: come back in front of the camera");
}

TEST(Robustness, AHandAcrossTheFaceLeavesNoTrace) {
    synth::SequenceParams sp = scenario("occluder");
    sp.occluder_start_frame = 20;
    sp.frames = 60;
    sp.seed = 21;
    const ScenarioRun run = runScenario(sp);
    EXPECT_GE(run.figures.trackedShare(), 0.95);
    EXPECT_EQ(run.figures.wrong_poses, 0);
    EXPECT_EQ(run.figures.foreign_vertices, 0) << "occluder surface in the mesh";
}

// Robust integration on its own: the mask lets the hand in (head and occluder labels), so only the comparison
// with the confident model can keep it out. Without it the hand is fused, so the test can fail.
TEST(RobustIntegration, AnOccluderInsideTheMaskIsNotFused) {
    synth::SequenceParams sp = scenario("occluder");
    sp.occluder_start_frame = 15;
    sp.occluder_frames = 20;
    sp.frames = 40;
    sp.seed = 22;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    const recon::Mesh head = sim.headInFirstCamera();
    const std::vector<uint8_t> head_only = sim.headVertexMask();
    for (const bool robust : {true, false}) {
        ReconParams params = ReconParams::faceDefaults();
        params.robust_integration = robust;
        params.reacquire.enabled = robust;
        Reconstructor rec(sim.intrinsics(), params);
        RgbdFrame frame;
        synth::FrameTruth truth;
        cv::Mat face_area;  // the head's silhouette before the hand came: the hand counts while it is in front
        int removed = 0, integrated = 0;
        for (int i = 0; i < sp.frames; ++i) {
            sim.render(i, frame, &truth);
            const cv::Mat head_px = truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead);
            if (i == sp.occluder_start_frame - 1) face_area = head_px.clone();
            cv::Mat mask = head_px;
            if (!face_area.empty())
                mask = head_px | ((truth.label == static_cast<uint8_t>(synth::PixelLabel::kOccluder)) & face_area);
            const FrameResult r = rec.processFrame(frame, mask);
            // A fused frame counts what left it before registration and before fusion: most of the hand in the mask.
            const int hand =
                cv::countNonZero((truth.label == static_cast<uint8_t>(synth::PixelLabel::kOccluder)) & mask);
            if (robust && r.integrated && hand > 3000) {
                EXPECT_GT(2 * r.occluding_pixels, hand) << "frame " << i << ": " << hand << " hand pixels in the mask";
            }
            removed += r.occluding_pixels;
            integrated += r.integrated;
        }
        const int foreign = eval::countVerticesFarFrom(rec.extractMesh(), head, 0.01f, &head_only);
        std::printf("robust integration %s: %d frames fused, %d occluder pixels left out, %d foreign vertices\n",
                    robust ? "on" : "off", integrated, removed, foreign);
        if (robust) {
            EXPECT_GT(removed, 1000);
            EXPECT_EQ(foreign, 0);
        } else {
            EXPECT_GT(foreign, 100) << "the occluder must reach the model without robust integration";
        }
    }
}

// From the model's own pose (robust integration's pre-filter, every tracked frame) the association takes each pixel
// as its own pair, without transform or projection. It must pair as the projection does, which a pose a micrometre
// off still takes: the same counts, and the same hand pixels left out.
TEST(ModelAgreement, TheSameViewShortcutPairsAsTheProjectionDoes) {
    synth::SequenceParams sp = scenario("occluder");
    sp.occluder_start_frame = 12;
    sp.occluder_frames = 4;
    sp.frames = 16;
    sp.seed = 24;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    const ReconParams params = ReconParams::faceDefaults();
    Reconstructor rec(sim.intrinsics(), params);
    RgbdFrame frame;
    synth::FrameTruth truth;
    for (int i = 0; i < sp.occluder_start_frame; ++i) {
        sim.render(i, frame, &truth);
        ASSERT_TRUE(rec.processFrame(frame, truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead)).integrated);
    }
    HeadPrediction prediction;
    ASSERT_TRUE(rec.predictHead(prediction));
    sim.render(sp.occluder_start_frame + 2, frame, &truth);  // the hand in front of the face, inside the mask
    const cv::Mat mask = (truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead)) |
                         (truth.label == static_cast<uint8_t>(synth::PixelLabel::kOccluder));
    DepthFilter filter(sim.intrinsics(), params.filter);
    SurfacePyramid same, nudged;
    same.allocate(sim.intrinsics(), params.filter.levels);
    nudged.allocate(sim.intrinsics(), params.filter.levels);
    ASSERT_GT(filter.filter(frame.depth_m, mask, same), 1000);
    (void)filter.filter(frame.depth_m, mask, nudged);
    const Pose& at = prediction.T_world_camera;
    Pose off = at;
    off.translation().x() += 1e-6f;  // not the same matrix: the general path
    const PoseCheck a = checkPose(same.levels[0], *prediction.model, at, at, 0.005f, 0.01f);
    const PoseCheck b = checkPose(same.levels[0], *prediction.model, at, off, 0.005f, 0.01f);
    std::printf("same view: %d measured, %d associated, %d agreeing, %d conflicting; nudged: %d %d %d %d\n", a.measured,
                a.associated, a.agreeing, a.conflicting, b.measured, b.associated, b.agreeing, b.conflicting);
    EXPECT_EQ(a.measured, b.measured);
    EXPECT_NEAR(a.associated, b.associated, 2);
    EXPECT_NEAR(a.agreeing, b.agreeing, 2);
    EXPECT_NEAR(a.conflicting, b.conflicting, 2);
    const VoxelBlockGrid& grid = rec.volume().grid();
    const int removed = rejectOccludingDepth(same, *prediction.model, at, at, grid, 0.03f, params.confident_weight);
    const int removed_nudged =
        rejectOccludingDepth(nudged, *prediction.model, at, off, grid, 0.03f, params.confident_weight);
    std::printf("hand pixels left out: same view %d, nudged %d\n", removed, removed_nudged);
    EXPECT_GT(removed, 100);
    EXPECT_NEAR(removed, removed_nudged, 2);
}

// A deliberately wrong re-acquisition hypothesis (the true pose turned 25 deg or 5 deg, or moved 4 cm or 1 cm) fails
// verification; the true pose passes.
TEST(Reacquisition, VerificationRejectsADeliberatelyWrongHypothesis) {
    synth::SequenceParams sp;
    sp.frames = 20;
    sp.seed = 23;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
    RgbdFrame frame;
    synth::FrameTruth truth;
    FrameResult r;
    for (int i = 0; i < sp.frames; ++i) {
        sim.render(i, frame, &truth);
        r = rec.processFrame(frame, truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead));
        ASSERT_TRUE(r.integrated) << i << ": " << r.reason;
    }
    const Pose right = r.tracking.T_world_camera;
    const PoseCheck good = rec.verifyPose(right);
    std::printf("right pose: inliers %.2f conflicts %.3f rmse %.2f mm\n", good.agreeShare(), good.conflictShare(),
                1000 * good.rmse_m);
    EXPECT_TRUE(rec.acceptsCheck(good));
    // Wrong hypotheses: turned about the head's centre (25 deg as a hypothesis step; 5 deg about each axis, just
    // past the 3 deg that counts as a wrong pose), or moved (4 cm; 1 cm along each axis).
    const Eigen::Vector3f centre = rec.headRegion().centre_world;
    auto turned = [&](float deg, const Eigen::Vector3f& axis) {
        Pose t = Pose::Identity();
        t.linear() = Eigen::AngleAxisf(deg / 57.29578f, axis).toRotationMatrix();
        t.translation() = centre - t.linear() * centre;
        return Pose(t * right);
    };
    auto moved = [&](const Eigen::Vector3f& by_m) {
        Pose t = Pose::Identity();
        t.translation() = by_m;
        return Pose(t * right);
    };
    std::vector<Pose> wrong_poses = {turned(25.0f, Eigen::Vector3f::UnitY()), moved({0.04f, 0.0f, 0.0f})};
    for (int axis = 0; axis < 3; ++axis) {
        wrong_poses.push_back(turned(5.0f, Eigen::Vector3f::Unit(axis)));
        wrong_poses.push_back(moved(0.01f * Eigen::Vector3f::Unit(axis)));
    }
    for (const Pose& wrong : wrong_poses) {
        const PoseCheck bad = rec.verifyPose(wrong);
        const Pose off = right.inverse() * wrong;
        std::printf("wrong pose (%.1f deg, camera %.1f mm off): inliers %.2f conflicts %.3f rmse %.2f mm\n",
                    angleDeg(off), 1000 * off.translation().norm(), bad.agreeShare(), bad.conflictShare(),
                    1000 * bad.rmse_m);
        EXPECT_FALSE(rec.acceptsCheck(bad));
    }
}

TEST(ScanStep, AFrameWithoutAHeadIsNoHeadAndTheAdviceSaysWhatToDo) {
    synth::SequenceParams sp;
    sp.frames = 8;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
    FacePipeline pipeline = makePipeline(sim.intrinsics());
    ScanStep step;
    RgbdFrame frame;
    RgbdFrame wall;
    wall.depth_m = cv::Mat(480, 640, CV_32F, cv::Scalar(1.6f));
    scanFrame(pipeline, rec, wall, step);
    EXPECT_EQ(step.frame.tracking.status, TrackingStatus::kNoHead);
    EXPECT_STREQ(step.advice, "face the camera");
    for (int i = 0; i < sp.frames; ++i) {
        sim.render(i, frame);
        scanFrame(pipeline, rec, frame, step);
        ASSERT_TRUE(step.frame.integrated) << step.frame.reason;
    }
    EXPECT_STREQ(step.advice, "");
    scanFrame(pipeline, rec, wall, step);
    EXPECT_EQ(step.frame.tracking.status, TrackingStatus::kNoHead) << "not invalid input";
    EXPECT_STREQ(step.advice, "face lost: come back in front of the camera");
    // Found but not fusable (a turned head after a loss is verified first): hold still.
    step.head.found = true;
    step.head.centroid_m = Eigen::Vector3f(0, 0, 0.7f);
    step.frame.integrated = step.frame.tracked = false;
    EXPECT_STREQ(adviceFor(step, rec), "face lost: hold still");
    // Tracked but not fused (ReconParams::fuse_every) is no loss: the advice is about distance again.
    step.frame.tracked = true;
    step.head.centroid_m.z() = 1.3f;
    EXPECT_STREQ(adviceFor(step, rec), "move closer");
    step.head.centroid_m.z() = 0.45f;
    EXPECT_STREQ(adviceFor(step, rec), "move back");
}

TEST(ScanStep, TheTrackedFrameLoopAllocatesNothing) {
    synth::SequenceParams sp;
    sp.frames = 16;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    std::vector<RgbdFrame> frames(static_cast<size_t>(sp.frames));
    for (int i = 0; i < sp.frames; ++i) sim.render(i, frames[static_cast<size_t>(i)]);
    Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
    FacePipeline pipeline = makePipeline(sim.intrinsics());
    ScanStep step;
    long before = 0;
    int from_model = 0;
    for (int i = 0; i < sp.frames; ++i) {
        if (i == 6) before = testing::heapAllocations();
        scanFrame(pipeline, rec, frames[static_cast<size_t>(i)], step);
        ASSERT_TRUE(step.frame.integrated) << i << ": " << step.frame.reason;
        from_model += i >= 6 && step.head.from_model;
    }
    EXPECT_EQ(from_model, sp.frames - 6) << "the frames checked must take the model-based path";
    EXPECT_EQ(testing::heapAllocations() - before, 0) << "model-based segmentation, tracking, robust integration";
}

}  // namespace
}  // namespace facescan::recon
