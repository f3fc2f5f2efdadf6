// A camera held in portrait, upside down or tilted: the person lies on their side (or on their head) in the image.
// Detection and the head/torso split run on the frame turned upright (recon/image_roll.hpp); these tests check the
// turning itself against the pinhole model, and that a rolled or tilted synthetic frame is detected and segmented
// like the upright one, with the roll found from the frames (colour, and depth alone) or fixed by the caller.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <vector>

#include "eval/scenario_figures.hpp"
#include "recon/face_pipeline.hpp"
#include "recon/image_roll.hpp"
#include "recon/scan_step.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::recon {
namespace {

// Thesis eq. 4.8 on both sides: a point's pixel in this camera, turned upright as cv::rotate turns images, is the
// pixel of the turned point in the upright intrinsics.
TEST(ImageRoll, IntrinsicsAndPointsTurnWithTheImage) {
    Intrinsics k;
    k.width_px = 320, k.height_px = 240, k.fx_px = 217.5f, k.fy_px = 219.0f, k.cx_px = 161.2f, k.cy_px = 118.7f;
    for (const int deg : {0, 90, 180, 270}) {
        const ImageRoll roll = ImageRoll::fromDegrees(deg);
        const Intrinsics ku = roll.toUpright(k);
        // A marker pixel turned with the image lands where the upright intrinsics project the turned point.
        cv::Mat marker = cv::Mat::zeros(k.height_px, k.width_px, CV_8U);
        const Eigen::Vector3f p(0.031f, -0.052f, 0.4f);
        const Eigen::Vector2f px = k.project(p);
        marker.at<uint8_t>(static_cast<int>(std::lround(px.y())), static_cast<int>(std::lround(px.x()))) = 255;
        cv::Mat up;
        roll.toUpright(marker, up);
        ASSERT_EQ(up.cols, ku.width_px) << deg;
        ASSERT_EQ(up.rows, ku.height_px) << deg;
        cv::Point at;
        cv::minMaxLoc(up, nullptr, nullptr, nullptr, &at);
        const Eigen::Vector2f pu = ku.project(roll.toUpright(p));
        EXPECT_NEAR(pu.x(), at.x, 0.51f) << deg;
        EXPECT_NEAR(pu.y(), at.y, 0.51f) << deg;
        EXPECT_TRUE(roll.fromUpright(roll.toUpright(p)).isApprox(p)) << deg;
        // A box turned upright and back is the same box.
        const cv::Rect box(40, 30, 70, 50);
        const ImageRoll inverse = ImageRoll::fromDegrees(-deg);
        const cv::Rect box_up = inverse.rectFromUpright(box, up.size());
        EXPECT_EQ(roll.rectFromUpright(box_up, marker.size()), box) << deg;
        cv::Mat box_img = cv::Mat::zeros(marker.size(), CV_8U), box_img_up;
        box_img(box).setTo(255);
        roll.toUpright(box_img, box_img_up);
        EXPECT_EQ(cv::boundingRect(box_img_up), box_up) << deg;
        // The person's down, seen in this camera, gives the roll back.
        EXPECT_EQ(ImageRoll::fromDownDirection(roll.downCamera(), ImageRoll()), roll) << deg;
    }
    EXPECT_EQ(ImageRoll::fromDegrees(-90).degrees(), 270);
    EXPECT_EQ(ImageRoll::fromDegrees(450).degrees(), 90);
}

// A tilt between quarter turns resamples the image about its centre onto a canvas that holds all of it: a point's
// pixel still lands where the canvas's intrinsics project the turned point (within the nearest-pixel rounding), and
// boxes map to boxes that hold what was in them.
TEST(ImageRoll, TiltsTurnImagesIntrinsicsAndPointsAlike) {
    Intrinsics k;
    k.width_px = 320, k.height_px = 240, k.fx_px = 217.5f, k.fy_px = 219.0f, k.cx_px = 161.2f, k.cy_px = 118.7f;
    for (const int deg : {30, 45, 60, 135, 240, 315}) {
        const ImageRoll roll = ImageRoll::fromDegrees(deg);
        ASSERT_EQ(roll.degrees(), deg);
        ASSERT_FALSE(roll.quarterTurn());
        const Intrinsics ku = roll.toUpright(k);
        for (const Eigen::Vector3f& p : {Eigen::Vector3f(0.031f, -0.052f, 0.4f), Eigen::Vector3f(-0.1f, 0.06f, 0.5f)}) {
            cv::Mat marker = cv::Mat::zeros(k.height_px, k.width_px, CV_8U);
            const Eigen::Vector2f px = k.project(p);
            marker.at<uint8_t>(static_cast<int>(std::lround(px.y())), static_cast<int>(std::lround(px.x()))) = 255;
            cv::Mat up = cv::Mat::zeros(1, 1, CV_8U);
            // Dilated first: nearest-neighbour resampling may skip a lone pixel.
            cv::dilate(marker, marker, cv::Mat::ones(3, 3, CV_8U));
            roll.toUpright(marker, up);
            ASSERT_EQ(up.cols, ku.width_px) << deg;
            ASSERT_EQ(up.rows, ku.height_px) << deg;
            const cv::Moments m = cv::moments(up, true);
            ASSERT_GT(m.m00, 0) << deg;
            const Eigen::Vector2f pu = ku.project(roll.toUpright(p));
            // The focal lengths differ by 0.7 %: one focal length on the canvas moves a point by up to ~0.5 px.
            EXPECT_NEAR(pu.x(), m.m10 / m.m00, 1.0f) << deg;
            EXPECT_NEAR(pu.y(), m.m01 / m.m00, 1.0f) << deg;
            EXPECT_TRUE(roll.fromUpright(roll.toUpright(p)).isApprox(p)) << deg;
        }
        // The whole image fits on the canvas: nothing of the frame is lost.
        cv::Mat ones(k.height_px, k.width_px, CV_8U, cv::Scalar(1)), ones_up, back;
        roll.toUpright(ones, ones_up);
        EXPECT_NEAR(cv::countNonZero(ones_up), ones.total(), 0.02 * static_cast<double>(ones.total())) << deg;
        roll.fromUpright(ones_up, back, ones.size());
        EXPECT_GE(cv::countNonZero(back), static_cast<int>(ones.total()) - k.width_px - k.height_px) << deg;
        // A box turned upright holds the turned box's pixels, and turned back it holds the box.
        const cv::Rect box(40, 30, 70, 50);
        cv::Mat box_img = cv::Mat::zeros(ones.size(), CV_8U), box_img_up;
        box_img(box).setTo(255);
        roll.toUpright(box_img, box_img_up);
        const cv::Rect box_up = roll.rectToUpright(box, ones.size());
        EXPECT_EQ(cv::boundingRect(box_img_up) & box_up, cv::boundingRect(box_img_up)) << deg;
        EXPECT_EQ(roll.rectFromUpright(box_up, ones.size()) & box, box) << deg;
        EXPECT_EQ(ImageRoll::fromDownDirection(roll.downCamera(), ImageRoll()), roll) << deg;
    }
    EXPECT_EQ(ImageRoll::fromDegrees(-30).degrees(), 330);
    EXPECT_EQ(ImageRoll::fromDegrees(37).degrees(), 30);
}

// A down direction at `deg` degrees of roll.
Eigen::Vector3f downAt(float deg) {
    const float a = deg * 3.14159265f / 180.0f;
    return {-std::sin(a), std::cos(a), 0.1f};
}

// Directions go to the nearest step, and a roll in use is kept within three quarters of a step of the direction
// (no flicker between two steps).
TEST(ImageRoll, DownDirectionsGoToTheNearestStepAndHoldTheRollInUse) {
    const ImageRoll upright, tilt30 = ImageRoll::fromDegrees(30);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(7), upright).degrees(), 0);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(-11), upright).degrees(), 0) << "held";
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(-12), upright).degrees(), 345);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(10), ImageRoll::fromDegrees(180)).degrees(), 15);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(26), upright).degrees(), 30);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(41), upright).degrees(), 45);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(-58), upright).degrees(), 300);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(85), upright).degrees(), 90);
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(20), tilt30).degrees(), 30) << "held: within 11.25 deg of 30";
    EXPECT_EQ(ImageRoll::fromDownDirection(downAt(18), tilt30).degrees(), 15);
    EXPECT_EQ(ImageRoll::fromDownDirection(Eigen::Vector3f(0, 0, 1), tilt30), tilt30) << "along the optical axis";
}

struct Found {
    HeadObservation obs;
    double iou = 0;  // of the mask with the renderer's head label
};

// One frame of the built-in head (torso and wall in, Kinect noise) with the camera rolled by roll_deg, through a
// fresh pipeline.
Found findHead(int roll_deg, const FacePipelineParams& params, bool colour, int frame_index = 0) {
    synth::SequenceParams p;
    p.roll_deg = static_cast<float>(roll_deg);
    const synth::KinectSimulator sim(synth::builtinHead(), p);
    RgbdFrame frame;
    synth::FrameTruth truth;
    sim.render(frame_index, frame, &truth);
    if (!colour) frame.colour_bgr.release();
    StatusOr<FacePipeline> pipeline =
        FacePipeline::create(params, sim.intrinsics(), ColourCamera::registeredTo(sim.intrinsics()));
    EXPECT_TRUE(pipeline.isOk()) << pipeline.status().toString();
    Found f;
    f.obs = pipeline->process(frame);
    if (f.obs.found) {
        const cv::Mat head = truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead);
        const double inter = cv::countNonZero(head & f.obs.mask), uni = cv::countNonZero(head | f.obs.mask);
        f.iou = uni > 0 ? inter / uni : 0;
    }
    return f;
}

TEST(FacePipelineRoll, RolledFrameIsDetectedAndSegmentedLikeTheUprightOne) {
    const Found upright = findHead(0, {}, true);
    ASSERT_TRUE(upright.obs.found) << upright.obs.reason;
    EXPECT_FALSE(upright.obs.depth_only);
    EXPECT_GT(upright.iou, 0.8);
    for (const int roll : {90, 180, 270}) {
        const Found f = findHead(roll, {}, true);
        ASSERT_TRUE(f.obs.found) << roll << ": " << f.obs.reason;
        EXPECT_FALSE(f.obs.depth_only) << roll << ": the cascade finds the face on the turned frame";
        EXPECT_EQ(f.obs.roll_deg, roll) << "found from the frame";
        EXPECT_GT(f.iou, 0.8) << roll;
        EXPECT_NEAR(f.iou, upright.iou, 0.05) << roll;
        // Width and height as the person stands; the centroid where the rolled camera sees the head.
        EXPECT_NEAR(f.obs.extent_m.x(), upright.obs.extent_m.x(), 0.01f) << roll;
        EXPECT_NEAR(f.obs.extent_m.y(), upright.obs.extent_m.y(), 0.01f) << roll;
        const Eigen::Vector3f expected = ImageRoll::fromDegrees(roll).fromUpright(upright.obs.centroid_m);
        EXPECT_LT((f.obs.centroid_m - expected).norm(), 0.01f) << roll;
        EXPECT_EQ(cv::countNonZero(f.obs.depth_m > 0), cv::countNonZero(f.obs.mask)) << "outside the head is invalid";
        EXPECT_TRUE((f.obs.mask_box & cv::boundingRect(f.obs.mask)) == cv::boundingRect(f.obs.mask))
            << roll << ": the mask lies in its box";
    }
}

TEST(FacePipelineRoll, DepthAloneFindsTheRollFromTheBody) {
    FacePipelineParams params;
    const Found upright = findHead(0, params, false);
    ASSERT_TRUE(upright.obs.found) << upright.obs.reason;
    EXPECT_TRUE(upright.obs.depth_only);
    for (const int roll : {90, 180, 270}) {
        const Found f = findHead(roll, params, false);
        ASSERT_TRUE(f.obs.found) << roll << ": " << f.obs.reason;
        EXPECT_TRUE(f.obs.depth_only);
        EXPECT_EQ(f.obs.roll_deg, roll) << "the torso leaves the image on the person's down side";
        EXPECT_GT(f.iou, 0.75) << roll;
    }
}

// A camera tilted between quarter turns (a phone held at a slant): the body's direction gives the tilt, the cascade
// finds the face on the frame turned by it, and the head/torso split runs across the neck, as upright.
TEST(FacePipelineRoll, TiltedFrameIsFoundAtItsTiltWithColourAndWithDepthAlone) {
    const Found upright = findHead(0, {}, true);
    ASSERT_TRUE(upright.obs.found) << upright.obs.reason;
    for (const bool colour : {true, false}) {
        for (const int roll : {15, 30, 45, 300, 210}) {
            const Found f = findHead(roll, {}, colour);
            ASSERT_TRUE(f.obs.found) << roll << ": " << f.obs.reason;
            EXPECT_EQ(f.obs.depth_only, !colour) << roll;
            // The body's direction is measured, not given: within a step of the truth.
            const int apart = std::abs(f.obs.roll_deg - roll);
            EXPECT_LE(std::min(apart, 360 - apart), ImageRoll::kStepDeg) << roll << ": found " << f.obs.roll_deg;
            EXPECT_NEAR(f.iou, upright.iou, 0.08) << roll << (colour ? " colour" : " depth alone");
            EXPECT_NEAR(f.obs.extent_m.y(), upright.obs.extent_m.y(), 0.02f) << roll << ": height as the person stands";
            EXPECT_EQ(cv::countNonZero(f.obs.depth_m > 0), cv::countNonZero(f.obs.mask)) << roll;
        }
    }
}

TEST(FacePipelineRoll, AFixedRollIsUsedAsGiven) {
    FacePipelineParams params;
    params.roll_deg = 90;
    const Found f = findHead(90, params, true);
    ASSERT_TRUE(f.obs.found) << f.obs.reason;
    EXPECT_EQ(f.obs.roll_deg, 90);
    EXPECT_GT(f.iou, 0.8);
    // Fixed at the wrong roll, the cascade is not tried at the others: no face, whatever the depth-only path does.
    params.roll_deg = 0;
    params.depth_only_fallback = false;
    const Found wrong = findHead(90, params, true);
    EXPECT_FALSE(wrong.obs.found);
    EXPECT_EQ(wrong.obs.roll_deg, 0);
    // A slant between quarter turns, given: the cascade runs on the frame turned by it, as found in the test
    // above, and exactly there.
    params.roll_deg = 30;
    params.depth_only_fallback = true;
    for (const bool colour : {true, false}) {
        const Found tilted = findHead(30, params, colour);
        ASSERT_TRUE(tilted.obs.found) << tilted.obs.reason;
        EXPECT_EQ(tilted.obs.roll_deg, 30);
        EXPECT_GT(tilted.iou, 0.8);
    }
    for (const int bad : {40, 360, -15, 1}) {
        params.roll_deg = bad;
        EXPECT_FALSE(params.validate().isOk()) << bad;
    }
    for (const char* text : {"30", "345", "0", "auto"}) EXPECT_TRUE(parseRoll(text).isOk()) << text;
    for (const char* text : {"40", "360", "-30", "030", "+30", "30.0", "", "portrait"}) {
        const auto bad = parseRoll(text);
        ASSERT_FALSE(bad.isOk()) << text;
        EXPECT_NE(bad.status().message().find("steps of 15"), std::string::npos) << bad.status().message();
    }
}

// A camera held at 30 degrees as the head walks out of view: what is left in the frame's corner is a sliver of
// shoulder at its lower edge. On the turned canvas the border's repeated pixels smear it into a head-sized blob
// (18205 pixels, 488 of them in the frame), which the depth-only finder took for the head. It is no head now.
TEST(FacePipelineRoll, AHeadMeasuredMostlyPastTheFramesBorderIsNoHead) {
    synth::SequenceParams sp;
    ASSERT_TRUE(synth::applyScenario("gap", sp).isOk());
    sp.gap_start_frame = 25;
    sp.gap_turn_deg = -55.0f;
    sp.frames = 27;
    sp.seed = 20;
    sp.roll_deg = 30.0f;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    RgbdFrame frame;
    sim.render(26, frame, nullptr);
    FacePipelineParams params;
    params.roll_deg = 30;
    StatusOr<FacePipeline> pipeline =
        FacePipeline::create(params, sim.intrinsics(), ColourCamera::registeredTo(sim.intrinsics()));
    ASSERT_TRUE(pipeline.isOk()) << pipeline.status().toString();
    const HeadObservation obs = pipeline->process(frame);
    EXPECT_FALSE(obs.found) << cv::countNonZero(obs.mask) << " pixels taken for the head";
    EXPECT_NE(obs.reason.find("mostly past this frame's border"), std::string::npos) << obs.reason;
    // The same frame's start, before the walk: the head is found at the tilt as ever.
    sim.render(0, frame, nullptr);
    const HeadObservation start = pipeline->process(frame);
    EXPECT_TRUE(start.found) << start.reason;
}

// A whole sequence through scanFrame, as the server runs it: figures against the truth and the advice per frame.
struct RollRun {
    eval::ScenarioFigures figures;
    std::vector<std::string> advice;
    std::vector<int> roll_deg;  // the roll each frame's head was found at (-1: no head)
};

RollRun runScan(synth::SequenceParams sp, int roll_deg) {
    sp.roll_deg = static_cast<float>(roll_deg);
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
    EXPECT_TRUE(rec.initStatus().isOk()) << rec.initStatus().toString();
    StatusOr<FacePipeline> pipeline =
        FacePipeline::create({}, sim.intrinsics(), ColourCamera::registeredTo(sim.intrinsics()));
    EXPECT_TRUE(pipeline.isOk()) << pipeline.status().toString();
    RollRun run;
    std::vector<std::optional<Pose>> estimate, truth_poses;
    std::vector<int> head_pixels;
    const Pose T_c0_head = sim.poseAt(0);
    RgbdFrame frame;
    synth::FrameTruth truth;
    ScanStep step;
    for (int i = 0; i < sp.frames; ++i) {
        sim.render(i, frame, &truth);
        scanFrame(*pipeline, rec, frame, step);
        truth_poses.emplace_back(T_c0_head * truth.T_camera_head.inverse());
        estimate.push_back(step.frame.tracked ? std::optional<Pose>(step.frame.tracking.T_world_camera) : std::nullopt);
        head_pixels.push_back(truth.head_pixels);
        run.advice.emplace_back(step.advice);
        run.roll_deg.push_back(step.head.found ? step.head.roll_deg : -1);
    }
    run.figures = eval::scenarioFigures(sim, head_pixels, truth_poses, estimate, rec.extractMesh());
    eval::printScenario(run.figures);
    return run;
}

// The head leaves the view of a camera held in portrait and comes back turned: it is re-acquired (the hypotheses
// turn about the person's vertical axis, the image's x here), no wrong pose is fused, nothing but the head is in
// the model, and the advice is the upright camera's, frame by frame (it names no image direction).
TEST(ScanRoll, ReacquiresInPortraitAndAdvisesAsUpright) {
    synth::SequenceParams sp;
    ASSERT_TRUE(synth::applyScenario("gap", sp).isOk());
    sp.gap_start_frame = 25;
    // Back 46 deg from the last pose before the gap: only the hypotheses about the person's vertical axis reach it
    // (about the image's vertical axis instead, the head is never re-acquired).
    sp.gap_turn_deg = -55.0f;
    sp.frames = 25 + 2 * sp.gap_walk_frames + sp.gap_frames + 20;
    sp.seed = 20;
    const RollRun upright = runScan(sp, 0);
    for (const int roll : {90, 270}) {
        const RollRun rolled = runScan(sp, roll);
        EXPECT_EQ(rolled.figures.losses, 1) << roll;
        EXPECT_EQ(rolled.figures.reacquired, 1) << roll;
        EXPECT_LE(rolled.figures.worst_reacquire_frames, 10) << roll;
        EXPECT_EQ(rolled.figures.wrong_poses, 0) << roll << ": max error " << rolled.figures.max_pose_err_mm << " mm";
        EXPECT_EQ(rolled.figures.foreign_vertices, 0) << roll << ": torso fused";
        EXPECT_GE(rolled.figures.trackedShare(), upright.figures.trackedShare() - 0.03) << roll;
        int same_advice = 0;
        for (size_t i = 0; i < rolled.advice.size(); ++i) {
            same_advice += rolled.advice[i] == upright.advice[i];
            if (rolled.roll_deg[i] >= 0) {
                EXPECT_EQ(rolled.roll_deg[i], roll) << "frame " << i;
            }
        }
        EXPECT_GE(same_advice, static_cast<int>(rolled.advice.size()) - 3) << roll;
        const size_t out_of_view = static_cast<size_t>(sp.gap_start_frame + sp.gap_walk_frames + 5);
        EXPECT_EQ(rolled.advice[out_of_view], "face lost: come back in front of the camera") << roll;
    }
}

// Upside down, with the wide turns: tracked as upright, the roll found from the first frame on.
TEST(ScanRoll, UpsideDownWideTurnsTrackLikeUpright) {
    synth::SequenceParams sp;
    ASSERT_TRUE(synth::applyScenario("wide", sp).isOk());
    sp.frames = 80;
    const RollRun rolled = runScan(sp, 180);
    EXPECT_GE(rolled.figures.trackedShare(), 0.98);
    EXPECT_EQ(rolled.figures.wrong_poses, 0);
    EXPECT_EQ(rolled.figures.foreign_vertices, 0) << "torso fused";
    EXPECT_EQ(rolled.roll_deg.front(), 180);
}

// A camera tilted by 30 degrees for the whole scan: the model keeps the face (the chin plane lies along the tilted
// person's down), and nothing of the torso is fused.
TEST(ScanRoll, ATiltedCameraScansTheWholeFace) {
    synth::SequenceParams sp;
    sp.frames = 60;
    const RollRun upright = runScan(sp, 0);
    const RollRun tilted = runScan(sp, 30);
    EXPECT_GE(tilted.figures.trackedShare(), 0.98);
    EXPECT_EQ(tilted.figures.wrong_poses, 0);
    EXPECT_EQ(tilted.figures.foreign_vertices, 0) << "torso fused";
    EXPECT_GE(tilted.figures.mesh_vertices, 0.93 * upright.figures.mesh_vertices) << "the face was cut";
    EXPECT_EQ(tilted.roll_deg.front(), 30);
}

// The camera turns from upright to portrait during the scan (0.6 deg a frame): tracking follows it, and the roll of
// each frame comes from the tracked model's down axis seen through the pose, so the pipeline knows the camera is
// in portrait by the end without a detection.
TEST(ScanRoll, ACameraTurnedDuringTheScanIsFollowed) {
    synth::SequenceParams sp;
    sp.frames = 150;
    sp.roll_turn_deg = 90.0f;
    const RollRun run = runScan(sp, 0);
    EXPECT_GE(run.figures.trackedShare(), 0.98);
    EXPECT_EQ(run.figures.wrong_poses, 0);
    EXPECT_EQ(run.figures.foreign_vertices, 0) << "torso fused";
    EXPECT_EQ(run.roll_deg.front(), 0);
    EXPECT_EQ(run.roll_deg.back(), 90) << "the roll follows the camera";
    // Through the tilts between, in order: never back, never more than a step's jump past the snap.
    for (size_t i = 1; i < run.roll_deg.size(); ++i) {
        if (run.roll_deg[i] >= 0 && run.roll_deg[i - 1] >= 0) {
            EXPECT_GE(run.roll_deg[i], run.roll_deg[i - 1]) << "frame " << i;
        }
    }
}

}  // namespace
}  // namespace facescan::recon
