#include "recon/scan_step.hpp"

#include <algorithm>
#include <cmath>

namespace facescan::recon {

Status AdviceParams::validate() const {
    if (!(near_m > 0.0f && far_m > near_m)) return invalidArgument("advice needs 0 < near_m < far_m");
    if (!(turned_deg > 0.0f && turned_deg < 180.0f)) return invalidArgument("advice turned_deg must be in (0, 180)");
    return Status::ok();
}

float degreesFromFirstView(const Pose& T_world_camera) {
    const float c = std::clamp((T_world_camera.linear().trace() - 1.0f) * 0.5f, -1.0f, 1.0f);
    return std::acos(c) * static_cast<float>(180.0 / M_PI);
}

void scanFrame(FacePipeline& pipeline, Reconstructor& reconstructor, const RgbdFrame& frame, ScanStep& out,
               const AdviceParams& advice) {
    HeadPrediction prediction;
    out.tracked_before = reconstructor.predictHead(prediction);
    out.head = out.tracked_before ? pipeline.process(frame, prediction) : pipeline.process(frame);
    if (out.head.found) {
        // A scan that starts now takes the person's down from the roll the head was found at.
        reconstructor.setPersonDown(ImageRoll::fromDegrees(out.head.roll_deg).downCamera());
        out.frame = reconstructor.processFrame(frame, out.head.mask, out.head.mask_box);
    } else {
        out.frame = reconstructor.noHead("no head found in the frame");
    }
    out.frame.ms.detect = out.head.detect_ms;
    out.frame.ms.segment = out.head.segment_ms;
    out.advice = adviceFor(out, reconstructor, advice);
}

const char* adviceFor(const ScanStep& step, const Reconstructor& reconstructor, const AdviceParams& p) {
    const bool scanning = reconstructor.framesIntegrated() > 0;
    const bool turned = scanning && degreesFromFirstView(reconstructor.lastPose()) > p.turned_deg;
    if (!step.head.found) {
        if (step.head.reason.find("too close") != std::string::npos) return "too close: move back";
        if (!scanning) return "face the camera";
        return turned ? "face lost: turn back toward the camera" : "face lost: come back in front of the camera";
    }
    const float z = step.head.centroid_m.z();
    if (!step.frame.tracked) {  // a frame tracked but not fused (fuse_every) is no loss
        if (!scanning) return z > p.far_m ? "move closer" : "face the camera";
        return turned ? "face lost: turn back toward the camera" : "face lost: hold still";
    }
    if (z > p.far_m) return "move closer";
    if (z < p.near_m) return "move back";
    if (turned) return "turn back toward the camera";
    return "";
}

}  // namespace facescan::recon
