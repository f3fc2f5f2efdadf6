// Thesis eq. 3.1-3.6 and the depth-accelerated detector on synthetic and real (Biwi) frames.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "detect_data.hpp"
#include "recon/face_detector.hpp"
#include "test_data.hpp"
#ifdef FACESCAN_HAVE_SYNTH
#include "synth/kinect_simulator.hpp"
#endif

namespace facescan::recon {
namespace {

namespace dd = detect_data;

TEST(FaceWidthRange, Eq31ScalesWithFocalOverDepth) {
    FaceDetectorParams p;
    p.face_width_min_m = 0.12f;
    p.face_width_max_m = 0.25f;
    const FaceWidthRangePx w = faceWidthRange(500.0f, 1.0f, p);
    EXPECT_FLOAT_EQ(w.min_px, 60.0f);
    EXPECT_FLOAT_EQ(w.max_px, 125.0f);
    const FaceWidthRangePx w2 = faceWidthRange(500.0f, 2.0f, p);  // twice as far: half as wide
    EXPECT_FLOAT_EQ(w2.min_px, 30.0f);
    EXPECT_FLOAT_EQ(w2.max_px, 62.5f);
    const FaceWidthRangePx none = faceWidthRange(500.0f, 0.0f, p);  // invalid depth: empty range
    EXPECT_EQ(none.max_px, 0.0f);
}

TEST(DepthBoundary, Eq32MarksBothSidesOfEveryStep) {
    cv::Mat z(6, 7, CV_32F, cv::Scalar(1.0f));
    z(cv::Rect(3, 0, 4, 6)) = 1.5f;  // a vertical step between columns 2 and 3
    z.at<float>(5, 0) = 0.0f;        // a hole (invalid depth is a value too)
    z.at<float>(0, 1) = 1.03f;       // below the threshold: no boundary
    cv::Mat b;
    depthBoundaryMap(z, 0.1f, b);
    for (int v = 0; v < z.rows; ++v) {
        for (int u = 0; u < z.cols; ++u) {
            // Brute force eq. 3.2 over the left/upper neighbour, marking both pixels of a pair.
            bool expect = false;
            const int du[4] = {-1, 1, 0, 0}, dv[4] = {0, 0, -1, 1};
            for (int n = 0; n < 4; ++n) {
                const int uu = u + du[n], vv = v + dv[n];
                if (uu < 0 || vv < 0 || uu >= z.cols || vv >= z.rows) continue;
                expect |= std::fabs(z.at<float>(v, u) - z.at<float>(vv, uu)) > 0.1f;
            }
            EXPECT_EQ(b.at<uchar>(v, u) != 0, expect) << "at " << u << "," << v;
        }
    }
}

TEST(DistanceTransform, Eq33To35MatchesBruteForceEuclidean) {
    cv::RNG rng(7);
    cv::Mat b(40, 53, CV_8U, cv::Scalar(0));
    for (int i = 0; i < 12; ++i) b.at<uchar>(rng.uniform(0, b.rows), rng.uniform(0, b.cols)) = 255;
    cv::Mat d;
    distanceToBoundary(b, d);
    double worst_rel = 0;
    for (int v = 0; v < b.rows; ++v) {
        for (int u = 0; u < b.cols; ++u) {
            double best = std::numeric_limits<double>::max();
            for (int y = 0; y < b.rows; ++y) {
                for (int x = 0; x < b.cols; ++x) {
                    if (b.at<uchar>(y, x)) best = std::min(best, std::hypot(x - u, y - v));
                }
            }
            const double got = d.at<float>(v, u);
            if (best == 0) {
                EXPECT_EQ(got, 0.0) << u << "," << v;
            } else {
                worst_rel = std::max(worst_rel, std::fabs(got - best) / best);
            }
        }
    }
    // The 3x3 two-pass chamfer (Borgefors 0.955 / 1.3693) stays within 4.5% of Euclidean; the thesis' 1/sqrt(2)
    // weights within 8%.
    EXPECT_LT(worst_rel, 0.05);
}

TEST(DistanceTransform, NoBoundaryMeansFarFromEverything) {
    cv::Mat b(10, 10, CV_8U, cv::Scalar(0)), d;
    distanceToBoundary(b, d);
    double lo = 0;
    cv::minMaxLoc(d, &lo);
    EXPECT_GT(lo, 1e6);
}

TEST(CandidateMask, HeadInFrontOfWallIsCandidateAndWallIsNot) {
    // A 0.16 m x 0.22 m head (ellipse) at 1 m in front of a wall at 2 m; f = 500 px.
    cv::Mat z(240, 320, CV_32F, cv::Scalar(2.0f));
    cv::ellipse(z, cv::Point(160, 120), cv::Size(40, 55), 0, 0, 360, cv::Scalar(1.0f), cv::FILLED);
    FaceDetectorParams p;
    cv::Mat b, d, m;
    depthBoundaryMap(z, p.boundary_jump_m, b);
    distanceToBoundary(b, d);
    faceCandidateMask(z, d, 500.0f, p, m);
    EXPECT_GT(m.at<uchar>(125, 160), 0) << "face centre must be a candidate";
    EXPECT_EQ(m.at<uchar>(30, 40), 0) << "the wall has no face-sized silhouette";
    EXPECT_EQ(m.at<uchar>(120, 130), 0) << "the cheek is too close to the silhouette to be a face centre";
}

#ifdef FACESCAN_HAVE_SYNTH
TEST(CandidateMask, ContainsTheTrueFaceCentreOnSyntheticFrames) {
    synth::SequenceParams sp;
    sp.frames = 8;
    sp.yaw_amplitude_deg = 20;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    StatusOr<FaceDetector> det = FaceDetector::create({});
    ASSERT_TRUE(det.isOk()) << det.status().toString();
    RgbdFrame frame;
    synth::FrameTruth truth;
    for (int i = 0; i < sp.frames; i += 2) {
        sim.render(i, frame, &truth);
        ASSERT_FALSE(truth.face_box_px.empty());
        ASSERT_TRUE(
            det->detect(frame.depth_m, frame.colour_bgr, sim.intrinsics(), ColourCamera::registeredTo(sim.intrinsics()))
                .isOk());
        const cv::Mat& mask = det->candidateMask();  // at candidate_level
        const int level = det->params().candidate_level;
        const cv::Point c = (truth.face_box_px.tl() + truth.face_box_px.br()) / 2;
        const int r = std::max(1, (truth.face_box_px.width >> level) / 8);
        const cv::Rect probe = cv::Rect((c.x >> level) - r, (c.y >> level) - r, 2 * r + 1, 2 * r + 1) &
                               cv::Rect(0, 0, mask.cols, mask.rows);
        EXPECT_GT(cv::countNonZero(mask(probe)), 0) << "frame " << i;
        // ... and the mask is selective: a small share of the image.
        EXPECT_LT(cv::countNonZero(mask), static_cast<int>(mask.total() / 10)) << "frame " << i;
    }
}
#endif

TEST(FaceDetector, RejectsBadInputWithAStatus) {
    StatusOr<FaceDetector> det = FaceDetector::create({});
    ASSERT_TRUE(det.isOk()) << det.status().toString();
    const Intrinsics k;
    const ColourCamera cam = ColourCamera::registeredTo(k);
    const cv::Mat colour(480, 640, CV_8UC3, cv::Scalar(90, 90, 90));
    EXPECT_FALSE(det->detect(cv::Mat(), colour, k, cam).isOk());
    EXPECT_FALSE(det->detect(cv::Mat(480, 640, CV_16U, cv::Scalar(800)), colour, k, cam).isOk());
    EXPECT_FALSE(det->detect(cv::Mat(100, 100, CV_32F, cv::Scalar(1.0f)), colour, k, cam).isOk());
    EXPECT_FALSE(det->detect(cv::Mat(480, 640, CV_32F, cv::Scalar(1.0f)), cv::Mat(), k, cam).isOk());
    // All-zero depth is valid input with no face in it.
    StatusOr<FaceDetections> none = det->detect(cv::Mat(480, 640, CV_32F, cv::Scalar(0.0f)), colour, k, cam);
    ASSERT_TRUE(none.isOk());
    EXPECT_TRUE(none->faces.empty());
    FaceDetectorParams bad;
    bad.face_width_min_m = 0.3f;  // above the maximum
    EXPECT_FALSE(FaceDetector::create(bad).isOk());
    bad = {};
    bad.cascade_path = "/nonexistent/cascade.xml";
    EXPECT_EQ(FaceDetector::create(bad).status().code(), StatusCode::kNotFound);
}

TEST(BiwiDetect, FaceBoxMapsOntoDepthHeadThroughTheExtrinsics) {
    FACESCAN_REQUIRE_DATA(dir, "biwi_subject01_5frames");
    StatusOr<FaceDetector> det = FaceDetector::create({});
    ASSERT_TRUE(det.isOk());
    const Intrinsics k = dd::biwiDepthIntrinsics(dir);
    RgbdFrame frame;
    ASSERT_TRUE(dd::loadBiwiFrame(dir, "frame_00000.png", frame));
    StatusOr<FaceDetections> found = det->detect(frame.depth_m, frame.colour_bgr, k, dd::biwiColourCamera());
    ASSERT_TRUE(found.isOk());
    ASSERT_EQ(found->faces.size(), 1u);
    const FaceDetection& face = found->faces.front();
    EXPECT_GE(dd::iou(face.box_colour_px, dd::biwiFaceBoxColour()), 0.5);
    EXPECT_NEAR(face.depth_m, 0.85f, 0.05f);  // the subject sits at 0.79-0.96 m
    // The depth head (valid pixels of rows 172-300) is centred at column ~351; the mapped face box must be too.
    double sum = 0;
    int n = 0;
    for (int v = 180; v < 290; ++v) {
        for (int u = 250; u < 450; ++u) {
            if (frame.depth_m.at<float>(v, u) > 0) sum += u, ++n;
        }
    }
    ASSERT_GT(n, 0);
    EXPECT_NEAR(face.box_depth_px.x + face.box_depth_px.width / 2.0, sum / n, 8.0);
}

}  // namespace
}  // namespace facescan::recon
