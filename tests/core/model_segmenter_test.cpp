// The model segmenter's fast paths (growth from the seeds' frontier only, the mask and its figures in
// parallel stripes) against a plain statement of what it computes: seeds where the frame confirms the ray-cast
// model's prediction inside the head region, then Algorithm 1's depth-continuity growth from every seed within the
// predicted box widened by the band, inside the region.
#include "recon/model_segmenter.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <utility>
#include <vector>

#include "recon/face_pipeline.hpp"
#include "recon/reconstructor.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::recon {
namespace {

struct Reference {
    cv::Mat head;  // CV_8U, 1 on the head
    int pixels = 0;
    cv::Rect box;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
};

// The segmentation by its definition: every seed queued, every pixel of the grown box tried from each side.
Reference referenceSegmentation(const cv::Mat& depth_m, const Intrinsics& k, const HeadPrediction& prediction,
                                const ModelSegmenterParams& p, const HeadSegmenterParams& limits) {
    const SurfaceLevel& model = *prediction.model;
    const Pose T_camera_world = prediction.T_world_camera.inverse();
    const auto inRegion = [&](int u, int v, float z) {
        return prediction.region.contains(prediction.T_world_camera *
                                          k.backProject(static_cast<float>(u), static_cast<float>(v), z));
    };
    const auto inRange = [&](float z) { return z >= limits.min_depth_m && z <= limits.max_depth_m; };
    Reference r;
    r.head = cv::Mat::zeros(depth_m.size(), CV_8UC1);
    std::deque<cv::Point> queue;
    double z_sum = 0;
    int predicted = 0, u0 = depth_m.cols, v0 = depth_m.rows, u1 = -1, v1 = -1;
    // A model cast at a coarser level (ReconParams::model_level) predicts depth pixel (u, v) by its pixel
    // (u >> shift, v >> shift).
    const int shift = depth_m.cols == model.k.width_px ? 0 : 1;
    const cv::Rect roi =
        cv::Rect(model.roi.x << shift, model.roi.y << shift, model.roi.width << shift, model.roi.height << shift) &
        cv::Rect(0, 0, depth_m.cols, depth_m.rows);
    for (int v = roi.y; v < roi.br().y; ++v) {
        for (int u = roi.x; u < roi.br().x; ++u) {
            const cv::Vec3f vert = model.vertex.at<cv::Vec3f>(v >> shift, u >> shift);
            if (std::isnan(vert[0])) continue;
            const Eigen::Vector3f p_cam = T_camera_world * Eigen::Vector3f(vert[0], vert[1], vert[2]);
            ++predicted;
            z_sum += p_cam.z();
            u0 = std::min(u0, u), u1 = std::max(u1, u), v0 = std::min(v0, v), v1 = std::max(v1, v);
            const float z = depth_m.at<float>(v, u);
            if (!inRange(z) || std::fabs(z - p_cam.z()) > p.seed_margin_m || !inRegion(u, v, z)) continue;
            r.head.at<uint8_t>(v, u) = 1;
            queue.emplace_back(u, v);
        }
    }
    const int band_px = static_cast<int>(p.band_m * k.fx_px / static_cast<float>(z_sum / predicted));
    const cv::Rect box =
        cv::Rect(cv::Point(u0 - band_px, v0 - band_px), cv::Point(u1 + band_px + 1, v1 + band_px + 1)) &
        cv::Rect(0, 0, depth_m.cols, depth_m.rows);
    cv::Mat outside = cv::Mat::zeros(depth_m.size(), CV_8UC1);  // tried and outside the region
    while (!queue.empty()) {
        const cv::Point q = queue.front();
        queue.pop_front();
        const float z = depth_m.at<float>(q);
        for (const cv::Point n :
             {q + cv::Point(-1, 0), q + cv::Point(1, 0), q + cv::Point(0, -1), q + cv::Point(0, 1)}) {
            if (!box.contains(n) || r.head.at<uint8_t>(n) || outside.at<uint8_t>(n)) continue;
            const float nz = depth_m.at<float>(n);
            if (!inRange(nz) || std::fabs(nz - z) >= p.grow_jump_m) continue;
            if (!inRegion(n.x, n.y, nz)) {
                outside.at<uint8_t>(n) = 1;
                continue;
            }
            r.head.at<uint8_t>(n) = 1;
            queue.push_back(n);
        }
    }
    std::vector<cv::Point> head;
    cv::findNonZero(r.head, head);
    r.pixels = static_cast<int>(head.size());
    cv::Point lo(depth_m.cols, depth_m.rows), hi(-1, -1);
    for (const cv::Point& q : head) {
        lo = cv::Point(std::min(lo.x, q.x), std::min(lo.y, q.y));
        hi = cv::Point(std::max(hi.x, q.x), std::max(hi.y, q.y));
        r.centroid +=
            k.backProject(static_cast<float>(q.x), static_cast<float>(q.y), depth_m.at<float>(q)).cast<double>();
    }
    r.box = cv::Rect(lo, hi + cv::Point(1, 1));
    r.centroid /= r.pixels;
    return r;
}

// Over a tracked scenario (the chin's torso below the head: growth stops at the region, not at a depth edge), the
// segmentation of each next frame from the model is the reference's, pixel for pixel; with the model at full and
// at half resolution (a busy server's sessions).
TEST(ModelSegmenter, SegmentsAsThePlainFloodFillFromEverySeed) {
    for (const auto& [name, model_level] : {std::pair{"chin", 0}, std::pair{"wide", 0}, std::pair{"wide", 1}}) {
        synth::SequenceParams sp;
        ASSERT_TRUE(synth::applyScenario(name, sp).isOk());
        sp.frames = 40;
        const synth::KinectSimulator sim(synth::builtinHead(), sp);
        ReconParams params = ReconParams::faceDefaults();
        params.model_level = model_level;
        Reconstructor rec(sim.intrinsics(), params);
        const FacePipelineParams pipeline;
        ModelSegmenter segmenter(pipeline.model);
        HeadSegmentation out;
        RgbdFrame frame;
        synth::FrameTruth truth;
        int compared = 0;
        for (int i = 0; i < sp.frames; ++i) {
            sim.render(i, frame, &truth);
            HeadPrediction prediction;
            if (i > 0 && i % 4 == 0 && rec.predictHead(prediction)) {
                segmenter.segment(frame.depth_m, sim.intrinsics(), prediction, pipeline.segmenter, out);
                ASSERT_TRUE(out.found) << name << " level " << model_level << " frame " << i << ": " << out.reason;
                const Reference ref = referenceSegmentation(frame.depth_m, sim.intrinsics(), prediction, pipeline.model,
                                                            pipeline.segmenter);
                EXPECT_EQ(out.pixels, ref.pixels) << name << " level " << model_level << " frame " << i;
                EXPECT_EQ(cv::countNonZero(out.mask != ref.head * 255), 0)
                    << name << " level " << model_level << " frame " << i;
                EXPECT_EQ(cv::countNonZero((out.depth_m > 0) != (ref.head > 0)), 0)
                    << name << " level " << model_level << " frame " << i;
                EXPECT_EQ(out.head_box_px, ref.box) << name << " level " << model_level << " frame " << i;
                EXPECT_LT((out.centroid_m.cast<double>() - ref.centroid).norm(), 1e-6)
                    << name << " level " << model_level << " frame " << i;
                ++compared;
            }
            ASSERT_TRUE(
                rec.processFrame(frame, truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead)).integrated)
                << name << " level " << model_level << " frame " << i;
        }
        ASSERT_EQ(rec.modelLevel(), model_level);
        std::printf("%s, model level %d: %d segmentations compared with the reference\n", name, model_level, compared);
        EXPECT_EQ(compared, 9);
    }
}

}  // namespace
}  // namespace facescan::recon
