// The per-frame head policy in front of the reconstructor (docs/design.md s4): decide whether to detect, segment the
// head, and report it. Independent of the Reconstructor: the caller passes what the tracked model predicts
// (Reconstructor::predictHead), so while tracking the head is segmented from the model's prediction
// (ModelSegmenter) and detection with the width criterion runs only to start a scan, when the
// prediction is not confirmed, and every redetect_every_frames as a check.
//
//   recon::FacePipeline pipeline = *recon::FacePipeline::create({}, depth_intrinsics, colour_camera);
//   recon::HeadPrediction prediction;
//   const bool tracked = reconstructor.predictHead(prediction);
//   recon::HeadObservation head = tracked ? pipeline.process(frame, prediction) : pipeline.process(frame);
//   if (head.found) reconstructor.processFrame(frame, head.mask, head.mask_box) ... else reconstructor.noHead(...);
// (recon/scan_step.hpp does exactly this, with the advice for the person being scanned.)
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>

#include "recon/camera.hpp"
#include "recon/face_detector.hpp"
#include "recon/frame.hpp"
#include "recon/head_finder.hpp"
#include "recon/head_segmenter.hpp"
#include "recon/model_segmenter.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

struct FacePipelineParams {
    FaceDetectorParams detector;
    HeadSegmenterParams segmenter;
    HeadFinderParams finder;
    ModelSegmenterParams model;       // segmentation from the tracked model's prediction
    bool depth_only_fallback = true;  // find the head by depth when there is no colour or the cascade misses
    // Re-detect at least this often even while tracking, to notice a second, nearer person (frames; 0 = never).
    int redetect_every_frames = 0;

    Status validate() const;
};

struct HeadObservation {
    bool found = false;
    cv::Mat mask;         // CV_8UC1, 255 on the head (depth pixel grid)
    cv::Mat depth_m;      // the frame's depth with everything outside the head set to 0 (metres)
    cv::Rect mask_box;    // mask and depth_m are 0 outside this box (for Reconstructor::processFrame)
    cv::Rect face_box;    // the face (detected) or head (tracked / depth-only) box in depth pixels
    std::string reason;   // why nothing was found: empty when found
    int other_faces = 0;  // further faces detected and ignored (the nearest one is scanned)
    float detect_ms = 0;  // detection (cascade or depth-only finder) time, 0 when it did not run
    float segment_ms = 0;
    bool detection_ran = false;
    bool depth_only = false;                               // found without colour (depth-only finder)
    bool from_model = false;                               // segmented from the tracked model's prediction
    Eigen::Vector3f centroid_m = Eigen::Vector3f::Zero();  // head centroid, depth camera frame (metres)
    Eigen::Vector3f extent_m = Eigen::Vector3f::Zero();    // head width, height, depth (metres)
};

class FacePipeline {
 public:
    static StatusOr<FacePipeline> create(const FacePipelineParams& params, const Intrinsics& depth,
                                         const ColourCamera& colour);

    // predicted_head_box: the head box (depth pixels) from the tracked pose, or nullptr when not tracking.
    HeadObservation process(const RgbdFrame& frame, const cv::Rect* predicted_head_box = nullptr);
    // While tracking: the head from the model's prediction; when the frame does not confirm it (the head left,
    // turned away or is hidden, or the result is not head-sized), detection and the width criterion as above.
    HeadObservation process(const RgbdFrame& frame, const HeadPrediction& prediction);
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
    ModelSegmenter model_segmenter_{params_.model};
    HeadSegmentation segmentation_;
    HeadSegmentation model_segmentation_;  // separate buffers: ModelSegmenter clears only what it wrote
    int frames_since_detection_ = 0;
};

}  // namespace facescan::recon
