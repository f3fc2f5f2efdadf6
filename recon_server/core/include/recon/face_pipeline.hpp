// The per-frame head policy in front of the reconstructor (DESIGN.md s4): decide whether to detect, segment the
// head, and report it. Independent of the Reconstructor: the caller passes the head box that the tracked pose
// predicts (Reconstructor::predictedHeadBox), so detection runs only when tracking cannot seed the segmenter.
//
//   recon::FacePipeline pipeline = *recon::FacePipeline::create({}, depth_intrinsics, colour_camera);
//   cv::Rect box;
//   const bool tracked = reconstructor.predictedHeadBox(box);
//   recon::HeadObservation head = pipeline.process(frame, tracked ? &box : nullptr);
//   if (head.found) integrate(head.depth_m) ... else log(head.reason);
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>

#include "recon/camera.hpp"
#include "recon/face_detector.hpp"
#include "recon/frame.hpp"
#include "recon/head_finder.hpp"
#include "recon/head_segmenter.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

struct FacePipelineParams {
    FaceDetectorParams detector;
    HeadSegmenterParams segmenter;
    HeadFinderParams finder;
    bool depth_only_fallback = true;  // find the head by depth when there is no colour or the cascade misses
    // Re-detect at least this often even while tracking, to notice a second, nearer person (frames; 0 = never).
    int redetect_every_frames = 0;

    Status validate() const;
};

struct HeadObservation {
    bool found = false;
    cv::Mat mask;         // CV_8UC1, 255 on the head (depth pixel grid)
    cv::Mat depth_m;      // the frame's depth with everything outside the head set to 0 (metres)
    cv::Rect face_box;    // the face (detected) or head (tracked / depth-only) box in depth pixels
    std::string reason;   // why nothing was found: empty when found
    int other_faces = 0;  // further faces detected and ignored (the nearest one is scanned)
    float detect_ms = 0;  // detection (cascade or depth-only finder) time, 0 when it did not run
    float segment_ms = 0;
    bool detection_ran = false;
    bool depth_only = false;                               // found without colour (depth-only finder)
    Eigen::Vector3f centroid_m = Eigen::Vector3f::Zero();  // head centroid, depth camera frame (metres)
    Eigen::Vector3f extent_m = Eigen::Vector3f::Zero();    // head width, height, depth (metres)
};

class FacePipeline {
 public:
    static StatusOr<FacePipeline> create(const FacePipelineParams& params, const Intrinsics& depth,
                                         const ColourCamera& colour);

    // predicted_head_box: the head box (depth pixels) from the tracked pose, or nullptr when not tracking.
    HeadObservation process(const RgbdFrame& frame, const cv::Rect* predicted_head_box = nullptr);
    // Forget the tracking state (new scan).
    void reset() { frames_since_detection_ = 0; }

 private:
    FacePipeline(const FacePipelineParams& params, const Intrinsics& depth, const ColourCamera& colour,
                 FaceDetector detector)
        : params_(params),
          depth_(depth),
          colour_(colour),
          detector_(std::move(detector)),
          segmenter_(params.segmenter),
          finder_(params.finder, params.segmenter) {}

    FacePipelineParams params_;
    Intrinsics depth_;
    ColourCamera colour_;
    FaceDetector detector_;
    HeadSegmenter segmenter_;
    HeadFinder finder_;
    HeadSegmentation segmentation_;
    int frames_since_detection_ = 0;
};

}  // namespace facescan::recon
