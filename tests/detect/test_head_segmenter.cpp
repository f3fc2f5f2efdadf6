// Head segmentation (thesis Algorithm 1, eq. 3.7-3.13) and the depth-only head finder.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "detect_data.hpp"
#include "recon/head_finder.hpp"
#include "recon/head_segmenter.hpp"
#include "test_data.hpp"
#ifdef FACESCAN_HAVE_SYNTH
#include "synth/kinect_simulator.hpp"
#endif

namespace facescan::recon {
namespace {

namespace dd = detect_data;

double maskIou(const cv::Mat& a, const cv::Mat& b) {
    const double inter = cv::countNonZero(a & b), uni = cv::countNonZero(a | b);
    return uni > 0 ? inter / uni : 0.0;
}

TEST(WidthCriterion, Eq311SplitsWhereTheWidthJumps) {
    // 12 rows 20 px wide (head), then 15 rows 70 px wide (torso).
    std::vector<int> rows(27, 20);
    for (size_t i = 12; i < rows.size(); ++i) rows[i] = 70;
    EXPECT_EQ(widthCriterionSplit(rows, 0, 26), 11);
    // Empty rows do not count as rows of either region (eq. 3.9-3.10 count rows that contain a pixel).
    rows.insert(rows.begin(), 3, 0);
    EXPECT_EQ(widthCriterionSplit(rows, 0, 29), 14);
    EXPECT_EQ(widthCriterionSplit(std::vector<int>{5}, 0, 0), -1);
}

#ifdef FACESCAN_HAVE_SYNTH
// The renderer's head + torso + wall scene; the seed is the renderer's face box.
TEST(HeadSegmenter, HeadMaskMatchesTheRendererHeadLabel) {
    for (float distance : {0.6f, 1.0f, 1.4f}) {
        synth::SequenceParams sp;
        sp.frames = 6;
        sp.distance_m = distance;
        sp.wall_distance_m = distance + 1.0f;
        const synth::KinectSimulator sim(synth::builtinHead(), sp);
        HeadSegmenter seg;
        RgbdFrame frame;
        synth::FrameTruth truth;
        HeadSegmentation out;
        for (int i = 0; i < sp.frames; i += 2) {
            sim.render(i, frame, &truth);
            ASSERT_FALSE(truth.face_box_px.empty());
            seg.segment(frame.depth_m, sim.intrinsics(), truth.face_box_px, out);
            ASSERT_TRUE(out.found) << out.reason << " at " << distance << " m, frame " << i;
            const cv::Mat head = truth.label == static_cast<int>(synth::PixelLabel::kHead);
            // Only pixels with a depth measurement can be segmented: score against the measured head.
            const cv::Mat measured_head = head & (frame.depth_m > 0);
            EXPECT_GE(maskIou(out.mask, measured_head), 0.9) << distance << " m, frame " << i;
            EXPECT_GE(out.split_row, 0) << "the torso is attached and must be cut off";
        }
    }
}
#endif

TEST(HeadSegmenter, BadInputGivesAReasonNeverACrash) {
    HeadSegmenter seg;
    HeadSegmentation out;
    const Intrinsics k;
    const cv::Rect box(280, 200, 80, 80);
    seg.segment(cv::Mat(), k, box, out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("empty"), std::string::npos);
    seg.segment(cv::Mat(480, 640, CV_16U, cv::Scalar(900)), k, box, out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("CV_32F"), std::string::npos);
    seg.segment(cv::Mat(480, 640, CV_32F, cv::Scalar(0.0f)), k, box, out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("no valid depth"), std::string::npos);
    EXPECT_EQ(cv::countNonZero(out.mask), 0);
    seg.segment(cv::Mat(480, 640, CV_32F, cv::Scalar(0.3f)), k, box, out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("too close"), std::string::npos);
    seg.segment(cv::Mat(480, 640, CV_32F, cv::Scalar(1.0f)), k, cv::Rect(700, 500, 20, 20), out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("outside"), std::string::npos);
    // A flat wall is not head-sized.
    seg.segment(cv::Mat(480, 640, CV_32F, cv::Scalar(1.0f)), k, box, out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("not head-sized"), std::string::npos);
}

// PCL's real Kinect frame: a person in profile at 0.6-0.8 m, a room behind (to 3.8 m), no colour. Looking at the
// depth image, the head occupies columns ~170-330 and rows ~160-300 (crown at row ~165, shoulders from ~330).
TEST(HeadFinder, SegmentsTheProfileHeadInThePclFrameByDepthAlone) {
    FACESCAN_REQUIRE_DATA(dir, "pcl_kinect_person");
    const cv::Mat raw = cv::imread((dir / "person_depth_mm.png").string(), cv::IMREAD_ANYDEPTH);
    ASSERT_EQ(raw.type(), CV_16UC1);
    cv::Mat depth;
    depthRawToMetres(raw, 0.001f, depth);
    const Intrinsics k = dd::pclIntrinsics();
    HeadFinder finder;
    HeadSegmentation out;
    finder.find(depth, k, out);
    ASSERT_TRUE(out.found) << out.reason;
    // Head-sized in metres (docs/design.md s1: 80-250 mm wide, 100-300 mm tall).
    EXPECT_GE(out.extent_m.x(), 0.08f);
    EXPECT_LE(out.extent_m.x(), 0.25f);
    EXPECT_GE(out.extent_m.y(), 0.10f);
    EXPECT_LE(out.extent_m.y(), 0.30f);
    // Where the head is: centroid projected into the image, and depth.
    const Eigen::Vector2f c = k.project(out.centroid_m);
    EXPECT_GT(c.x(), 170);
    EXPECT_LT(c.x(), 330);
    EXPECT_GT(c.y(), 160);
    EXPECT_LT(c.y(), 300);
    EXPECT_GT(out.centroid_m.z(), 0.6f);
    EXPECT_LT(out.centroid_m.z(), 0.9f);
    // Nothing of the room: every head pixel is within 0.3 m of the head's depth.
    double lo = 0, hi = 0;
    cv::minMaxLoc(out.depth_m, &lo, &hi, nullptr, nullptr, out.mask);
    EXPECT_LT(hi - lo, 0.3);
    EXPECT_GT(out.split_row, 0) << "the shoulders are attached and must be cut off";
    EXPECT_LT(out.split_row, 340);
}

TEST(HeadFinder, NoHeadInAnEmptyOrTooCloseScene) {
    HeadFinder finder;
    HeadSegmentation out;
    const Intrinsics k;
    finder.find(cv::Mat(480, 640, CV_32F, cv::Scalar(0.0f)), k, out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("no valid depth"), std::string::npos);
    finder.find(cv::Mat(480, 640, CV_32F, cv::Scalar(0.25f)), k, out);
    EXPECT_FALSE(out.found);
    EXPECT_NE(out.reason.find("too close"), std::string::npos);
    finder.find(cv::Mat(480, 640, CV_32F, cv::Scalar(2.0f)), k, out);  // a wall
    EXPECT_FALSE(out.found);
    EXPECT_FALSE(out.reason.empty());
    finder.find(cv::Mat(10, 10, CV_32F, cv::Scalar(1.0f)), k, out);  // wrong size
    EXPECT_FALSE(out.found);
}

}  // namespace
}  // namespace facescan::recon
