#include "recon/sensor.hpp"

#include <cmath>

namespace facescan::recon {

const char* sensorFamilyName(SensorFamily family) {
    switch (family) {
        case SensorFamily::kStructuredLight: return "structured-light";
        case SensorFamily::kActiveStereo: return "active-stereo";
        case SensorFamily::kTimeOfFlight: return "time-of-flight";
        case SensorFamily::kUnknown: break;
    }
    return "unknown";
}

bool sensorFamilyFromName(const std::string& name, SensorFamily& out) {
    for (const SensorFamily f : {SensorFamily::kUnknown, SensorFamily::kStructuredLight, SensorFamily::kActiveStereo,
                                 SensorFamily::kTimeOfFlight}) {
        if (name == sensorFamilyName(f)) {
            out = f;
            return true;
        }
    }
    return false;
}

Status SensorModel::validate() const {
    if (!(std::isfinite(min_depth_m) && std::isfinite(max_depth_m) && min_depth_m > 0.0f && max_depth_m <= 20.0f)) {
        return invalidArgument("sensor depth range " + std::to_string(min_depth_m) + ".." +
                               std::to_string(max_depth_m) + " m is not usable: give 0 < min < max <= 20 metres");
    }
    if (!(max_depth_m > min_depth_m)) {
        return invalidArgument("sensor depth range is inverted (min " + std::to_string(min_depth_m) + " m, max " +
                               std::to_string(max_depth_m) + " m): give the nearer distance first, e.g. 0.2:0.5");
    }
    if (noise.known() && !(std::isfinite(noise.c0_m) && std::isfinite(noise.c1) && std::isfinite(noise.c2_per_m) &&
                           noise.sigmaM(min_depth_m) > 0.0f && noise.sigmaM(max_depth_m) > 0.0f)) {
        return invalidArgument("sensor depth noise model gives no positive sigma over its range: check c0, c1, c2");
    }
    return Status::ok();
}

namespace {

Intrinsics depthStream(int width_px, int height_px, float f_px) {
    Intrinsics k;
    k.width_px = width_px;
    k.height_px = height_px;
    k.fx_px = k.fy_px = f_px;
    k.cx_px = (static_cast<float>(width_px) - 1.0f) / 2.0f;
    k.cy_px = (static_cast<float>(height_px) - 1.0f) / 2.0f;
    return k;
}

SensorModel model(const char* name, SensorFamily family, float min_m, float max_m, DepthNoiseModel noise) {
    SensorModel s;
    s.name = name;
    s.family = family;
    s.min_depth_m = min_m;
    s.max_depth_m = max_m;
    s.noise = noise;
    return s;
}

}  // namespace

const std::vector<SensorPreset>& sensorPresets() {
    // Ranges are the makers' specified operating ranges; focal lengths follow from the specified fields of view
    // (f = width / (2 tan(hfov / 2))). Noise only where a published model exists; otherwise unknown (all zero).
    static const std::vector<SensorPreset> presets = {
        {"kinect-v1", "Microsoft Kinect v1 (PrimeSense PS1080 structured light), 640x480", SensorModel::kinectV1(),
         Intrinsics::kinectV1()},
        // Same PS1080 chip and projector as the Kinect v1, so the same noise model; ASUS specifies 0.8-3.5 m.
        {"xtion", "ASUS Xtion / PrimeSense Carmine (PS1080 structured light), 640x480",
         model("xtion", SensorFamily::kStructuredLight, 0.8f, 3.5f, SensorModel::kinectV1().noise),
         depthStream(640, 480, 570.3f)},
        // Orbbec specifies 0.6-8 m for the Astra (0.4-2 m for the Astra S) and a 60 deg horizontal field of view.
        {"astra", "Orbbec Astra (structured light, OpenNI2), 640x480",
         model("astra", SensorFamily::kStructuredLight, 0.6f, 8.0f, {}), depthStream(640, 480, 554.3f)},
        // Intel's RMS error of active stereo (Grunnet-Jepsen et al., "Tuning depth cameras for best performance",
        // Intel RealSense white paper, 2019): sigma = z^2 * subpixel / (f * baseline), with subpixel 0.08, baseline
        // 55 mm and f = 665.6 px at 848x480 (65 deg horizontal field of view): 2.19 mm/m^2 * z^2.
        {"realsense-d415", "Intel RealSense D415 (active stereo), 848x480",
         model("realsense-d415", SensorFamily::kActiveStereo, 0.3f, 3.0f, {0.0f, 0.0f, 0.08f / (665.6f * 0.055f)}),
         depthStream(848, 480, 665.6f)},
        // NFOV unbinned mode; Microsoft specifies 0.5-3.86 m. Its random error is specified only as a bound
        // (std <= 17 mm), not a model, so the noise stays unknown.
        {"azure-kinect", "Microsoft Azure Kinect / Orbbec Femto (time of flight, NFOV unbinned), 640x576",
         model("azure-kinect", SensorFamily::kTimeOfFlight, 0.5f, 3.86f, {}), depthStream(640, 576, 504.0f)},
        // A phone's front depth camera at arm's length: 0.2-0.5 m. Its noise has no published model we use here;
        // a recording carries the phone's own intrinsics.
        {"truedepth", "Apple TrueDepth front camera (structured light, near range), 320x240",
         model("truedepth", SensorFamily::kStructuredLight, 0.2f, 0.5f, {}), depthStream(320, 240, 217.5f)},
    };
    return presets;
}

std::string sensorPresetNames() {
    std::string names;
    for (const SensorPreset& p : sensorPresets()) names += (names.empty() ? "" : ", ") + std::string(p.name);
    return names;
}

StatusOr<SensorPreset> findSensorPreset(const std::string& name) {
    for (const SensorPreset& p : sensorPresets()) {
        if (name == p.name) return p;
    }
    return notFound("unknown sensor '" + name + "': use one of " + sensorPresetNames() +
                    " (and --depth-range MIN:MAX for a camera that is none of them)");
}

}  // namespace facescan::recon
