// The depth camera as the pipeline needs to know it: its working range, its kind and its depth noise. Every stage
// that used to assume a Kinect v1 derives its limits from this (recon/sensor_adapt.hpp). The wire's CameraInfo
// carries it; an older agent's CameraInfo, which lacks it, means a Kinect v1.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

// How a camera may be said to be held (a --roll flag, CameraInfo): how far the person appears turned clockwise in
// the image, 0 to 345 degrees in steps of kRollStepDeg, the steps in which the pipeline turns a frame upright
// (ImageRoll): a phone held in portrait is 90 or 270, upside down 180, and one at a slant the nearest step.
inline constexpr int kRollStepDeg = 15;
constexpr bool isRollStepDeg(int deg) { return deg >= 0 && deg < 360 && deg % kRollStepDeg == 0; }

// How the camera measures depth: it decides where its errors are (stereo: holes where texture or baseline fail,
// error growing with z^2; time of flight: flying pixels at silhouettes, multipath in concave parts).
enum class SensorFamily : uint8_t { kUnknown = 0, kStructuredLight = 1, kActiveStereo = 2, kTimeOfFlight = 3 };
const char* sensorFamilyName(SensorFamily family);  // "structured-light", "active-stereo", "time-of-flight", "unknown"
bool sensorFamilyFromName(const std::string& name, SensorFamily& out);

// Standard deviation of one depth measurement along the ray: sigma(z) = c0 + c1 z + c2 z^2 (metres, z in metres).
// All zero: not known.
struct DepthNoiseModel {
    float c0_m = 0.0f;      // metres
    float c1 = 0.0f;        // metres per metre
    float c2_per_m = 0.0f;  // metres per square metre
    bool known() const { return c0_m != 0.0f || c1 != 0.0f || c2_per_m != 0.0f; }
    float sigmaM(float z_m) const { return c0_m + z_m * (c1 + z_m * c2_per_m); }
    bool operator==(const DepthNoiseModel&) const = default;
};

struct SensorModel {
    std::string name = "kinect-v1";  // preset name, or the device's own name (OpenNI2), or "custom"
    SensorFamily family = SensorFamily::kStructuredLight;
    float min_depth_m = 0.4f;  // metres; nearer is not measured (reliably)
    float max_depth_m = 4.0f;  // metres; farther is ignored
    // Kinect v1: Nguyen, Izadi, Lovell, "Modeling Kinect sensor noise for improved 3D reconstruction and tracking"
    // (3DIMPVT 2012), axial noise sigma_z(z) = 0.0012 + 0.0019 (z - 0.4)^2 m, expanded into c0 + c1 z + c2 z^2.
    DepthNoiseModel noise{0.001504f, -0.00152f, 0.0019f};

    static SensorModel kinectV1() { return {}; }
    bool operator==(const SensorModel&) const = default;
    // A range that cannot be right (inverted, not positive, beyond 20 m) or a negative noise at the range's ends.
    Status validate() const;
};

// A named camera: its sensor model and its nominal depth stream (a device or a recording reports its own
// intrinsics, which take precedence; these are for when none are known, and for the synthetic renderer).
struct SensorPreset {
    const char* name;
    const char* description;
    SensorModel sensor;
    Intrinsics nominal_depth;
};
const std::vector<SensorPreset>& sensorPresets();
// NotFound naming the known presets when `name` is none of them.
StatusOr<SensorPreset> findSensorPreset(const std::string& name);
std::string sensorPresetNames();  // "kinect-v1, xtion, ..."

}  // namespace facescan::recon
