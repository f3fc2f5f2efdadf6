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
#include <array>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/face_detector.hpp"
#include "recon/frame.hpp"
#include "recon/head_finder.hpp"
#include "recon/head_segmenter.hpp"
#include "recon/image_roll.hpp"
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
    // The camera's roll about its optical axis (degrees): how far the person appears turned clockwise in the image
    // (a phone held in portrait: 90 or 270; upside down: 180). Detection and the head/torso split run on the
    // frame turned upright. kRollAuto finds it from the frames: the cascade tries the other quarter turns when it
    // misses at the current one (at once while the roll is unknown, else after roll_recheck_misses misses in a
    // row), the depth-only finder takes the direction in which the body leaves the image as "down" (a tilt
    // between quarter turns too, which the cascade then tries first), and while tracking the model's own down
    // axis, seen through the pose, gives each frame's roll (a turning camera), in steps of ImageRoll::kStepDeg.
    static constexpr int kRollAuto = -1;
    int roll_deg = kRollAuto;      // kRollAuto, or 0 .. 345 in steps of kRollStepDeg (degrees)
    int roll_recheck_misses = 10;  // detection frames (count)

    Status validate() const;
};

// "auto" or "0" .. "345" in steps of kRollStepDeg (a --roll flag or config value) to FacePipelineParams::roll_deg.
StatusOr<int> parseRoll(const std::string& text);

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
    Eigen::Vector3f extent_m = Eigen::Vector3f::Zero();    // head width, height, depth (metres), as the person stands
    int roll_deg = 0;  // the camera's roll the head was found at (ImageRoll degrees: 0 .. 345, steps of 15)
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
    // Forget the tracking state (new scan). The roll found so far is kept: the camera is held the same way.
    void reset() { frames_since_detection_ = 0; }
    // The roll in use now (found or fixed).
    ImageRoll roll() const { return roll_; }

 private:
    FacePipeline(const FacePipelineParams& params, const Intrinsics& depth, const ColourCamera& colour,
                 FaceDetector detector)
        : params_(params),
          depth_(depth),
          colour_(colour),
          detector_(std::move(detector)),
          segmenter_(params.segmenter),
          finder_(params.finder, params.segmenter),
          roll_(ImageRoll::fromDegrees(params.roll_deg == FacePipelineParams::kRollAuto ? 0 : params.roll_deg)),
          roll_known_(params.roll_deg != FacePipelineParams::kRollAuto) {}

    // The frame turned upright for one roll, made on first use in a frame.
    struct UprightFrame {
        ImageRoll roll;
        bool have_depth = false, have_colour = false;
        cv::Mat depth_m, colour;
        Intrinsics k;
        ColourCamera colour_camera;
    };
    const UprightFrame& upright(ImageRoll roll, const cv::Mat& depth, const cv::Mat* colour);
    // The segmenter / cascade / finder at `roll`; results in this camera's pixels and frame.
    void segmentAt(ImageRoll roll, const cv::Mat& depth, const cv::Rect& seed_box_px, HeadSegmentation& out,
                   const cv::Rect* seed_box_upright = nullptr);
    StatusOr<FaceDetections> detectAt(ImageRoll roll, const cv::Mat& depth, const cv::Mat& colour);
    void findAt(ImageRoll roll, const cv::Mat& depth, HeadSegmentation& out);
    // An upright segmentation turned back into this camera's pixels.
    // `depth` is this camera's frame.
    void turnBack(ImageRoll roll, const HeadSegmentation& up, const cv::Mat& depth, HeadSegmentation& out);

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
    ImageRoll roll_;                                       // the roll in use
    bool roll_known_ = false;                              // fixed, or confirmed by a detection or the tracked model
    int misses_at_roll_ = 0;                               // detection frames in a row without a face at roll_
    std::array<UprightFrame, ImageRoll::kSteps> upright_;  // per roll; reused between frames
    HeadSegmentation upright_segmentation_;
    cv::Mat tilt_depth_, tilt_diff_;                // turnBack's scratch at a tilt
    std::vector<cv::Rect> detected_upright_boxes_;  // detectAt's faces in the upright frame's depth pixels
};

}  // namespace facescan::recon
