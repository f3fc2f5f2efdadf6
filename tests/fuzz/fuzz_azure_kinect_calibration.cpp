// libFuzzer target: the Azure Kinect calibration.json of .mkv recordings (parseAzureKinectCalibration), read for
// the depth and colour modes a recording can hold. Whatever it accepts must be usable: finite pinholes of the
// mode's size with positive focal lengths, eight distortion coefficients, and a finite rigid depth-to-colour
// transform.
#include <cmath>
#include <string>

#include "capture/recording_sources.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan::capture;
    const std::string json(reinterpret_cast<const char*>(data), size);
    struct Mode {
        int dw, dh, cw, ch;
    };
    // The input's length picks the modes, so every input is read in two of them.
    static constexpr Mode kModes[] = {{640, 576, 1280, 720},    {320, 288, 0, 0},   {512, 512, 2048, 1536},
                                      {1024, 1024, 3840, 2160}, {640, 576, 17, 17}, {100, 100, 0, 0}};
    for (const Mode& m : {kModes[size % 6], kModes[(size / 6) % 6]}) {
        const auto parsed = parseAzureKinectCalibration(json, m.dw, m.dh, m.cw, m.ch);
        if (!parsed.isOk()) {
            if (parsed.status().message().empty()) __builtin_trap();
            continue;
        }
        const auto check = [](const AzureKinectCamera& cam, int w, int h) {
            const auto& k = cam.intrinsics;
            if (k.width_px != w || k.height_px != h) __builtin_trap();
            if (!std::isfinite(k.fx_px) || !std::isfinite(k.fy_px) || !std::isfinite(k.cx_px) ||
                !std::isfinite(k.cy_px) || !(k.fx_px > 0.0f) || !(k.fy_px > 0.0f))
                __builtin_trap();
            if (cam.distortion.size() != 8) __builtin_trap();
        };
        check(parsed->depth, m.dw, m.dh);
        if (m.cw > 0) check(parsed->colour, m.cw, m.ch);
        if (!parsed->T_colour_depth.matrix().allFinite()) __builtin_trap();
    }
    return 0;
}
