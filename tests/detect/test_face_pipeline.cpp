// The per-frame head policy: detect or follow the tracked box, segment, fall back to depth, explain failures.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "detect_data.hpp"
#include "recon/face_pipeline.hpp"
#include "test_data.hpp"

namespace facescan::recon {
namespace {

namespace dd = detect_data;

FacePipeline makePipeline(const Intrinsics& k, const ColourCamera& cam) {
    StatusOr<FacePipeline> p = FacePipeline::create({}, k, cam);
    EXPECT_TRUE(p.isOk()) << p.status().toString();
    return std::move(p).value();
}

TEST(FacePipeline, BiwiFullPathDetectsSegmentsThenTracks) {
    FACESCAN_REQUIRE_DATA(dir, "biwi_subject01_5frames");
    const Intrinsics k = dd::biwiDepthIntrinsics(dir);
    FacePipeline pipeline = makePipeline(k, dd::biwiColourCamera());
    RgbdFrame frame;
    cv::Rect tracked;
    for (const auto& name : dd::biwiFrames(dir)) {
        ASSERT_TRUE(dd::loadBiwiFrame(dir, name, frame));
        const bool first = tracked.empty();
        const HeadObservation obs = pipeline.process(frame, first ? nullptr : &tracked);
        ASSERT_TRUE(obs.found) << name << ": " << obs.reason;
        EXPECT_EQ(obs.detection_ran, first) << "detection runs only until the head is tracked";
        EXPECT_FALSE(obs.depth_only);
        EXPECT_EQ(obs.other_faces, 0);
        EXPECT_EQ(obs.roll_deg, 0) << name << ": a seated person, camera upright (no tilt read into the body)";
        // The head: rows ~172-300 of the depth image, 0.8-0.9 m away, head-sized; the torso below is gone.
        EXPECT_GE(obs.extent_m.x(), 0.12f);
        EXPECT_LE(obs.extent_m.x(), 0.22f);
        EXPECT_GE(obs.extent_m.y(), 0.15f);
        EXPECT_LE(obs.extent_m.y(), 0.25f);
        EXPECT_NEAR(obs.centroid_m.z(), 0.86f, 0.05f);
        const cv::Rect box = cv::boundingRect(obs.mask);
        EXPECT_GE(box.y, 160);
        EXPECT_LE(box.br().y, 320);
        EXPECT_EQ(cv::countNonZero(obs.depth_m > 0), cv::countNonZero(obs.mask)) << "outside the head is invalid";
        tracked = box;  // what the reconstructor's predictedHeadBox would offer
    }
}

TEST(FacePipeline, LostTrackingTriggersDetectionAndNoColourFallsBackToDepth) {
    FACESCAN_REQUIRE_DATA(dir, "biwi_subject01_5frames");
    const Intrinsics k = dd::biwiDepthIntrinsics(dir);
    FacePipeline pipeline = makePipeline(k, dd::biwiColourCamera());
    RgbdFrame frame;
    ASSERT_TRUE(dd::loadBiwiFrame(dir, "frame_00002.png", frame));
    const cv::Rect wrong(20, 20, 60, 60);  // the prediction points at empty space
    HeadObservation obs = pipeline.process(frame, &wrong);
    ASSERT_TRUE(obs.found) << obs.reason;
    EXPECT_TRUE(obs.detection_ran);
    EXPECT_FALSE(obs.depth_only);
    frame.colour_bgr.release();
    obs = pipeline.process(frame);
    ASSERT_TRUE(obs.found) << obs.reason;
    EXPECT_TRUE(obs.depth_only);
    EXPECT_GE(obs.extent_m.x(), 0.08f);
    EXPECT_LE(obs.extent_m.y(), 0.30f);
}

// Real upright cameras read no tilt into the body: a fresh pipeline (the roll unknown) on depth alone takes the
// person's down from the direction the body leaves the image, and it must come out upright for a seated person
// (Biwi, background removed) and for a head in profile before a room (PCL).
TEST(FacePipeline, RealUprightFramesReadNoTiltFromTheBody) {
    FACESCAN_REQUIRE_DATA(biwi, "biwi_subject01_5frames");
    const Intrinsics k = dd::biwiDepthIntrinsics(biwi);
    RgbdFrame frame;
    for (const auto& name : dd::biwiFrames(biwi)) {
        FacePipeline pipeline = makePipeline(k, dd::biwiColourCamera());
        ASSERT_TRUE(dd::loadBiwiFrame(biwi, name, frame));
        frame.colour_bgr.release();
        const HeadObservation obs = pipeline.process(frame);
        ASSERT_TRUE(obs.found) << name << ": " << obs.reason;
        EXPECT_TRUE(obs.depth_only);
        EXPECT_EQ(obs.roll_deg, 0) << name;
    }
    FACESCAN_REQUIRE_DATA(pcl, "pcl_kinect_person");
    const cv::Mat raw = cv::imread((pcl / "person_depth_mm.png").string(), cv::IMREAD_ANYDEPTH);
    ASSERT_EQ(raw.type(), CV_16UC1);
    RgbdFrame person;
    depthRawToMetres(raw, 0.001f, person.depth_m);
    FacePipeline pipeline = makePipeline(dd::pclIntrinsics(), ColourCamera::registeredTo(dd::pclIntrinsics()));
    const HeadObservation obs = pipeline.process(person);
    ASSERT_TRUE(obs.found) << obs.reason;
    EXPECT_EQ(obs.roll_deg, 0);
}

// Two real faces (the Biwi face pasted twice) on two head-shaped depth blobs at 0.8 m and 1.3 m, colour
// registered to depth, a wall at 2.5 m. The nearer face is scanned, the other counted.
TEST(FacePipeline, SeveralFacesScansTheNearestAndCountsTheOthers) {
    FACESCAN_REQUIRE_DATA(dir, "biwi_subject01_5frames");
    RgbdFrame biwi;
    ASSERT_TRUE(dd::loadBiwiFrame(dir, "frame_00000.png", biwi));
    const cv::Rect face = dd::biwiFaceBoxColour();
    const cv::Rect crop(face.x - face.width / 2, face.y - face.height / 2, face.width * 2, face.height * 2);
    const Intrinsics k;  // Kinect v1, f = 575.8 px
    RgbdFrame frame;
    frame.depth_m = cv::Mat(480, 640, CV_32F, cv::Scalar(2.5f));
    frame.colour_bgr = cv::Mat(480, 640, CV_8UC3, cv::Scalar(200, 200, 200));
    struct Person {
        cv::Point centre;
        float z_m;
    };
    for (const Person& p : {Person{{440, 230}, 1.3f}, Person{{190, 250}, 0.8f}}) {
        const float px_per_m = k.fx_px / p.z_m;
        cv::ellipse(frame.depth_m, p.centre, cv::Size(int(0.08f * px_per_m), int(0.115f * px_per_m)), 0, 0, 360,
                    cv::Scalar(p.z_m), cv::FILLED);
        // The face box is 0.17 m wide at that depth; the crop is twice the box.
        const int side = static_cast<int>(2 * 0.17f * px_per_m);
        cv::Mat patch;
        cv::resize(biwi.colour_bgr(crop), patch, cv::Size(side, side * crop.height / crop.width));
        const cv::Rect at(p.centre.x - patch.cols / 2, p.centre.y - patch.rows / 2, patch.cols, patch.rows);
        patch.copyTo(frame.colour_bgr(at));
    }
    FacePipeline pipeline = makePipeline(k, ColourCamera::registeredTo(k));
    const HeadObservation obs = pipeline.process(frame);
    ASSERT_TRUE(obs.found) << obs.reason;
    EXPECT_EQ(obs.other_faces, 1);
    EXPECT_NEAR(obs.centroid_m.z(), 0.8f, 0.02f);
    EXPECT_TRUE(obs.face_box.contains({190, 250})) << "the nearer face";
}

TEST(FacePipeline, BadInputGivesAReasonNeverACrash) {
    const Intrinsics k;
    FacePipeline pipeline = makePipeline(k, ColourCamera::registeredTo(k));
    RgbdFrame frame;
    HeadObservation obs = pipeline.process(frame);
    EXPECT_FALSE(obs.found);
    EXPECT_NE(obs.reason.find("empty"), std::string::npos);
    frame.depth_m = cv::Mat(480, 640, CV_16U, cv::Scalar(900));
    obs = pipeline.process(frame);
    EXPECT_NE(obs.reason.find("CV_32F"), std::string::npos);
    frame.depth_m = cv::Mat(240, 320, CV_32F, cv::Scalar(1.0f));
    obs = pipeline.process(frame);
    EXPECT_NE(obs.reason.find("size"), std::string::npos);
    frame.depth_m = cv::Mat(480, 640, CV_32F, cv::Scalar(0.0f));
    frame.colour_bgr = cv::Mat(480, 640, CV_8UC3, cv::Scalar(40, 40, 40));
    obs = pipeline.process(frame);
    EXPECT_FALSE(obs.found);
    EXPECT_NE(obs.reason.find("no valid depth"), std::string::npos);
    frame.depth_m.setTo(0.3f);  // everything closer than the Kinect's 0.4 m
    obs = pipeline.process(frame);
    EXPECT_FALSE(obs.found);
    EXPECT_NE(obs.reason.find("too close"), std::string::npos);
    const cv::Rect predicted(300, 200, 60, 60);
    obs = pipeline.process(frame, &predicted);
    EXPECT_FALSE(obs.found);
    EXPECT_NE(obs.reason.find("too close"), std::string::npos);
    EXPECT_FALSE(FacePipeline::create({}, Intrinsics{0, 0, 0, 0, 0, 0}, ColourCamera::registeredTo(k)).isOk());
}

}  // namespace
}  // namespace facescan::recon
