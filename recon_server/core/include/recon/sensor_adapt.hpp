// Every stage's camera-dependent limits from the camera it is given (recon/sensor.hpp): depth windows and the
// distance advice from the sensor's range, thresholds in pixels from the focal length and the resolution. The
// defaults of ReconParams, FacePipelineParams and AdviceParams were tuned on a Kinect v1 at 640x480
// (f = 575.8 px, 0.4-4 m); each value is scaled by the ratio of this camera's figure to the Kinect's, so a Kinect
// v1 gets exactly the defaults.
#pragma once

#include <string>

#include "recon/camera.hpp"
#include "recon/face_pipeline.hpp"
#include "recon/reconstructor.hpp"
#include "recon/scan_step.hpp"
#include "recon/sensor.hpp"

namespace facescan::recon {

// Adapts the three parameter sets, which start from their Kinect-tuned values, to `sensor` and `depth`; with a
// known depth noise lower than the Kinect's at the working distance, the volume gets finer voxels and a narrower
// truncation band too.
void adaptToSensor(const SensorModel& sensor, const Intrinsics& depth, ReconParams& recon, FacePipelineParams& face,
                   AdviceParams& advice);

// One line for the status: the camera, its working range, its noise at the working distance and the model's
// resolution, e.g. "truedepth (structured-light), 0.20-0.50 m; advised 0.25-0.50 m; depth noise 0.53 mm at
// 0.31 m; model 1.01 mm voxels, truncation 2.0 mm (finer than a Kinect's: less depth noise)".
std::string describeSensor(const SensorModel& sensor, const AdviceParams& advice, const TsdfParams& tsdf);

}  // namespace facescan::recon
