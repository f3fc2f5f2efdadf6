// One frame of a scan as facescan-server runs it, and what to tell the person being scanned: the
// model's prediction seeds the head segmentation (detection when there is none), the head goes to the
// reconstructor, and a frame without a head counts as one (Reconstructor::noHead), so a loss is noticed, and the
// next head is verified before anything is fused. Shared by the server's session worker and facescan-bench.
//
//   recon::ScanStep step;
//   recon::scanFrame(pipeline, reconstructor, frame, step);
//   status.detail = step.advice;   // "face lost: hold still", "move closer", ...
#pragma once

#include "recon/face_pipeline.hpp"
#include "recon/reconstructor.hpp"

namespace facescan::recon {

struct AdviceParams {
    // A Kinect v1's (it measures from 0.4 m); adaptToSensor (recon/sensor_adapt.hpp) scales them to the camera.
    float far_m = 1.0f;        // metres; a head further away is asked to come closer (noise grows with z^2)
    float near_m = 0.5f;       // metres; nearer is asked to move back
    float turned_deg = 50.0f;  // degrees from the scan's first (frontal) view: asked to turn back
    Status validate() const;
};

struct ScanStep {
    HeadObservation head;
    FrameResult frame;
    bool tracked_before = false;  // the model predicted the head for this frame (it was tracked)
    const char* advice = "";      // what the person should do now (static text); empty while all is well
};

// Runs one frame; `out` is overwritten (its buffers are reused where they can be).
void scanFrame(FacePipeline& pipeline, Reconstructor& reconstructor, const RgbdFrame& frame, ScanStep& out,
               const AdviceParams& advice = {});

// The advice for a frame's outcome (scanFrame calls it): "move closer", "move back", "turn back toward the
// camera", "face lost: hold still", "face lost: turn back toward the camera", "face lost: come back in front of
// the camera", "face the camera" (no scan yet), or "" when the scan is going well.
const char* adviceFor(const ScanStep& step, const Reconstructor& reconstructor, const AdviceParams& p = {});

// Degrees between the scan's first view and the pose T_world_camera (how far the head is turned from it).
float degreesFromFirstView(const Pose& T_world_camera);

}  // namespace facescan::recon
