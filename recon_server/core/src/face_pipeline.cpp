#include "recon/face_pipeline.hpp"

#include <chrono>
#include <cmath>

namespace facescan::recon {
namespace {

using Clock = std::chrono::steady_clock;
float msSince(Clock::time_point t0) { return std::chrono::duration<float, std::milli>(Clock::now() - t0).count(); }

// The observation of a segmentation (masks shared, not copied).
void adopt(const HeadSegmentation& seg, HeadObservation& obs) {
    obs.found = seg.found;
    obs.mask = seg.mask;
    obs.depth_m = seg.depth_m;
    obs.mask_box = seg.written_px;
    obs.centroid_m = seg.centroid_m;
    obs.extent_m = seg.extent_m;
    if (!seg.found) obs.reason = seg.reason;
}

}  // namespace

Status FacePipelineParams::validate() const {
    RETURN_IF_ERROR(detector.validate());
    RETURN_IF_ERROR(segmenter.validate());
    RETURN_IF_ERROR(finder.validate());
    RETURN_IF_ERROR(model.validate());
    if (redetect_every_frames < 0) return invalidArgument("redetect_every_frames must be >= 0");
    return Status::ok();
}

StatusOr<FacePipeline> FacePipeline::create(const FacePipelineParams& params, const Intrinsics& depth,
                                            const ColourCamera& colour) {
    RETURN_IF_ERROR(params.validate());
    if (!depth.valid()) return invalidArgument("invalid depth intrinsics");
    if (!colour.registered && !colour.intrinsics.valid()) return invalidArgument("invalid colour intrinsics");
    ASSIGN_OR_RETURN(FaceDetector detector, FaceDetector::create(params.detector));
    return FacePipeline(params, depth, colour, std::move(detector));
}

HeadObservation FacePipeline::process(const RgbdFrame& frame, const cv::Rect* predicted_head_box) {
    HeadObservation obs;
    const cv::Mat& depth = frame.depth_m;
    if (depth.empty()) return obs.reason = "depth image is empty", obs;
    if (depth.type() != CV_32FC1) return obs.reason = "depth must be CV_32FC1 metres", obs;
    if (depth.cols != depth_.width_px || depth.rows != depth_.height_px) {
        return obs.reason = "depth size differs from the camera's intrinsics", obs;
    }

    // 1. Tracking: the predicted head box seeds the segmenter; no detection.
    const bool redetect_due =
        params_.redetect_every_frames > 0 && frames_since_detection_ >= params_.redetect_every_frames;
    if (predicted_head_box && !redetect_due) {
        const auto t0 = Clock::now();
        segmenter_.segment(depth, depth_, *predicted_head_box, segmentation_);
        obs.segment_ms = msSince(t0);
        ++frames_since_detection_;
        if (segmentation_.found) {
            adopt(segmentation_, obs);
            obs.face_box = segmentation_.head_box_px;
            return obs;
        }
        // The prediction no longer holds a head: fall through to detection.
    }

    // 2. Detection with colour: the nearest accepted face is scanned, the others counted.
    obs.detection_ran = true;
    frames_since_detection_ = 0;
    std::string detect_reason = "no colour image";
    const auto t_colour = Clock::now();
    const cv::Mat& colour = frameColour(frame, cv::Rect(0, 0, depth.cols, depth.rows));  // decoded now, if on demand
    obs.detect_ms += msSince(t_colour);
    if (!colour.empty()) {
        const auto t0 = Clock::now();
        StatusOr<FaceDetections> faces = detector_.detect(depth, colour, depth_, colour_);
        obs.detect_ms += msSince(t0);
        if (!faces.isOk()) {
            detect_reason = faces.status().message();
        } else if (faces->faces.empty()) {
            detect_reason = "no face found by the cascade";
        } else {
            const FaceDetection& face = faces->faces.front();
            obs.other_faces = static_cast<int>(faces->faces.size()) - 1;
            obs.face_box = face.box_depth_px;
            const auto t1 = Clock::now();
            segmenter_.segment(depth, depth_, face.box_depth_px, segmentation_);
            obs.segment_ms += msSince(t1);
            adopt(segmentation_, obs);
            if (obs.found) return obs;
            detect_reason = "face found but " + segmentation_.reason;
        }
    }

    // 3. Depth only: the nearest head-sized blob.
    if (params_.depth_only_fallback) {
        const auto t0 = Clock::now();
        finder_.find(depth, depth_, segmentation_);
        obs.detect_ms += msSince(t0);
        if (segmentation_.found) {
            adopt(segmentation_, obs);
            obs.depth_only = true;
            obs.face_box = segmentation_.head_box_px;
            obs.reason.clear();
            return obs;
        }
        obs.found = false;
        obs.mask = segmentation_.mask;
        obs.depth_m = segmentation_.depth_m;
        obs.reason = detect_reason + "; depth-only: " + segmentation_.reason;
        return obs;
    }
    obs.found = false;
    obs.reason = detect_reason;
    return obs;
}

HeadObservation FacePipeline::process(const RgbdFrame& frame, const HeadPrediction& prediction) {
    const bool redetect_due =
        params_.redetect_every_frames > 0 && frames_since_detection_ >= params_.redetect_every_frames;
    if (redetect_due || prediction.model == nullptr) return process(frame, nullptr);
    const auto t0 = Clock::now();
    model_segmenter_.segment(frame.depth_m, depth_, prediction, params_.segmenter, model_segmentation_);
    const float ms = msSince(t0);
    if (!model_segmentation_.found) {
        // Not confirmed: find the head afresh (detection, width criterion, depth-only finder).
        HeadObservation obs = process(frame, nullptr);
        obs.segment_ms += ms;
        return obs;
    }
    ++frames_since_detection_;
    HeadObservation obs;
    adopt(model_segmentation_, obs);
    obs.from_model = true;
    obs.segment_ms = ms;
    obs.face_box = model_segmentation_.head_box_px;
    return obs;
}

}  // namespace facescan::recon
