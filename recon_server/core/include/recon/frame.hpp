// What one frame is inside the core: depth in metres (0 = invalid), optional colour registered to depth.
// Raw sensor units are converted at the boundary (agent/server), never here.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>

#include "recon/camera.hpp"

namespace facescan::recon {

// Colour decoded only where and when a stage reads it (the server's JPEG payloads): a frame that is only tracked,
// its head found from the model, never pays for its colour, and integration decodes only the head's region.
class ColourSource {
 public:
    virtual ~ColourSource() = default;
    // The colour image (CV_8UC3, registered to depth, of its size), right at least inside roi_px; empty when it
    // cannot be had (a corrupt payload: the source keeps why), and the stage goes on as for a frame without one.
    virtual const cv::Mat& colour(const cv::Rect& roi_px) = 0;
};

struct RgbdFrame {
    cv::Mat depth_m;     // CV_32FC1, metres, 0 where the sensor has no measurement
    cv::Mat colour_bgr;  // CV_8UC3 registered to depth, or empty
    int64_t timestamp_ns = 0;
    // When colour_bgr is empty: decodes the colour on demand (not owned; valid while the frame is processed).
    ColourSource* colour_on_demand = nullptr;
};

// The frame's colour, right at least inside roi_px: colour_bgr when set, else colour_on_demand's when it is CV_8UC3
// of the depth's size; empty: none.
const cv::Mat& frameColour(const RgbdFrame& frame, const cv::Rect& roi_px);

// Raw sensor depth (CV_16UC1) to metres: raw * metres_per_unit (Kinect/OpenNI: 0.001; TUM PNGs: 1/5000).
void depthRawToMetres(const cv::Mat& raw_u16, float metres_per_unit, cv::Mat& depth_m);
// Metres back to raw units, rounding to nearest; 0 stays 0, out-of-range clamps to 0 (invalid).
void depthMetresToRaw(const cv::Mat& depth_m, float metres_per_unit, cv::Mat& raw_u16);

}  // namespace facescan::recon
