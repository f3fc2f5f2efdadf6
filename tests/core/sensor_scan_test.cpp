// A scan with a camera other than the Kinect v1, run as facescan-server runs it: the server adapts every stage to
// the camera its CameraInfo describes (recon/sensor_adapt.hpp), here the near-range structured-light synthetic
// sensor (synth::NoiseParams::nearRangeStructuredLight, 320x240) with the nose at 0.3 m, where the Kinect-tuned
// pipeline took the whole face for "too close"; and the active stereo and time-of-flight synthetic sensors, and a
// camera moving around a still head. The built-in head keeps the test independent of the data folder;
// the figures on the real scan are facescan-bench's (README).
#include <gtest/gtest.h>

#include <optional>
#include <vector>

#include "eval/accuracy.hpp"
#include "eval/scenario_figures.hpp"
#include "recon/scan_step.hpp"
#include "recon/sensor_adapt.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::recon {
namespace {

struct SensorRun {
    eval::ScenarioFigures figures;
    double mean_mm = 0;
    int move_back = 0;    // frames advised to move back
    double sigma_mm = 0;  // the sensor model's depth sigma at the nose tip's distance at rest
};

SensorRun runSensor(const std::string& options, bool adapt) {
    const StatusOr<synth::SyntheticSpec> spec = synth::parseSyntheticOptions(options);
    EXPECT_TRUE(spec.isOk()) << spec.status().toString();
    if (!spec.isOk()) return {};
    const synth::KinectSimulator sim(synth::builtinHead(), spec->sequence, spec->intrinsics);
    ReconParams params = ReconParams::faceDefaults();
    FacePipelineParams face;
    AdviceParams advice;
    if (adapt) adaptToSensor(spec->sensor_model, sim.intrinsics(), params, face, advice);
    Reconstructor rec(sim.intrinsics(), params);
    EXPECT_TRUE(rec.initStatus().isOk()) << rec.initStatus().toString();
    StatusOr<FacePipeline> pipeline =
        FacePipeline::create(face, sim.intrinsics(), ColourCamera::registeredTo(sim.intrinsics()));
    EXPECT_TRUE(pipeline.isOk()) << pipeline.status().toString();
    SensorRun run;
    run.sigma_mm = 1000.0 * spec->sensor_model.noise.sigmaM(spec->sequence.distance_m - 0.1f);
    std::vector<std::optional<Pose>> estimate, truth_poses;
    std::vector<int> head_pixels;
    const Pose T_c0_head = sim.poseAt(0);
    RgbdFrame frame;
    synth::FrameTruth truth;
    ScanStep step;
    for (int i = 0; i < sim.frameCount(); ++i) {
        sim.render(i, frame, &truth);
        scanFrame(*pipeline, rec, frame, step, advice);
        truth_poses.emplace_back(T_c0_head * truth.T_camera_head.inverse());
        estimate.push_back(step.frame.tracked ? std::optional<Pose>(step.frame.tracking.T_world_camera) : std::nullopt);
        head_pixels.push_back(truth.head_pixels);
        run.move_back += std::string(step.advice) == "move back";
    }
    const Mesh mesh = rec.extractMesh();
    run.figures = eval::scenarioFigures(sim, head_pixels, truth_poses, estimate, mesh);
    eval::printScenario(run.figures);
    if (mesh.n_vertices() > 0) {
        const Mesh& gt = sim.head().mesh;
        const auto acc = eval::measureAccuracy(mesh, gt, eval::findNoseTip(gt), {}, sim.poseAt(0).inverse());
        EXPECT_TRUE(acc.isOk()) << acc.status().toString();
        if (acc.isOk()) run.mean_mm = acc->mean_mm;
    }
    std::printf("%s (%s): mean %.3f mm (sensor sigma %.2f mm), advised to move back in %d frames\n", options.c_str(),
                adapt ? "adapted to the camera" : "Kinect v1 limits", run.mean_mm, run.sigma_mm, run.move_back);
    return run;
}

TEST(SensorScan, ANearRangeScanAtAThirdOfAMetreIsTrackedInEveryFrame) {
    const SensorRun run = runSensor("sensor=truedepth,frames=120,seed=5", true);
    EXPECT_GE(run.figures.tracked_in_view, 118) << "at least 98 % of 120 frames";
    EXPECT_EQ(run.figures.wrong_poses, 0) << "max error " << run.figures.max_pose_err_mm << " mm";
    EXPECT_EQ(run.figures.foreign_vertices, 0);
    EXPECT_EQ(run.move_back, 0) << "0.3 m is within the camera's advised range";
    EXPECT_GT(run.mean_mm, 0.0);
    EXPECT_LT(run.mean_mm, 0.25) << "the built-in head, 120 frames";
}

// The same frames with the Kinect v1's limits (what every stage assumed before it was told the camera): the face
// is "too close", so the scan cannot start.
TEST(SensorScan, TheKinectsLimitsRejectTheSameFrames) {
    const SensorRun run = runSensor("sensor=truedepth,frames=30,seed=5", false);
    EXPECT_LT(run.figures.tracked_in_view, 15);
}

// The active stereo (848x480, nose at 0.45 m) and time-of-flight (640x576, nose at 0.65 m) cameras with their
// own failure modes (stereo holes and shadows; flying pixels and multipath), and the camera moving around a still
// head (the background sliding through the image): every frame tracked, the model at most 0.6 times the sensor's
// single-frame sigma off the true head.
class SensorScanTarget : public ::testing::TestWithParam<const char*> {};

TEST_P(SensorScanTarget, TrackedAndWithinSixTenthsOfTheSensorsSigma) {
    const SensorRun run = runSensor(std::string(GetParam()) + ",frames=90", true);
    EXPECT_GE(run.figures.tracked_in_view, 89) << "at least 98 % of 90 frames";
    EXPECT_EQ(run.figures.wrong_poses, 0) << "max error " << run.figures.max_pose_err_mm << " mm";
    EXPECT_EQ(run.move_back, 0) << "scanned within the camera's advised range";
    EXPECT_GT(run.mean_mm, 0.0);
    EXPECT_LT(run.mean_mm, 0.6 * run.sigma_mm);
}

INSTANTIATE_TEST_SUITE_P(Sensors, SensorScanTarget,
                         ::testing::Values("sensor=d415,seed=5", "sensor=azure-kinect,seed=5",
                                           "sensor=kinect-v1,scenario=orbit,seed=5",
                                           "sensor=d415,scenario=orbit,seed=1"));

// The first frame pair starts from the centroids of two different cuts of the head (the first frame's mask from
// detection and segmentation, the second's from the model's prediction); on the near stereo camera with the
// built-in head, seeds 4 and 5 lost the track there until the fit was retried from the last pose.
TEST(SensorScan, TheStereoCamerasFirstFramePairIsTracked) {
    for (const char* seed : {"4", "5"}) {
        const SensorRun run = runSensor(std::string("sensor=d415,frames=12,seed=") + seed, true);
        EXPECT_EQ(run.figures.tracked_in_view, 12) << "seed " << seed;
        EXPECT_EQ(run.figures.losses, 0) << "seed " << seed;
        EXPECT_EQ(run.figures.wrong_poses, 0) << "seed " << seed;
    }
}

}  // namespace
}  // namespace facescan::recon
