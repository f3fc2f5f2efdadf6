#include "recon/frame.hpp"

#include <cmath>

namespace facescan::recon {

const cv::Mat& frameColour(const RgbdFrame& frame, const cv::Rect& roi_px) {
    static const cv::Mat kNone;
    if (!frame.colour_bgr.empty() || frame.colour_on_demand == nullptr) return frame.colour_bgr;
    const cv::Mat& colour = frame.colour_on_demand->colour(roi_px);
    // A source's colour of another shape is none, as Reconstructor::checkInput refuses such a colour_bgr.
    return colour.type() == CV_8UC3 && colour.size() == frame.depth_m.size() ? colour : kNone;
}

void depthRawToMetres(const cv::Mat& raw_u16, float metres_per_unit, cv::Mat& depth_m) {
    CV_Assert(raw_u16.type() == CV_16UC1);
    raw_u16.convertTo(depth_m, CV_32F, metres_per_unit);
}

void depthMetresToRaw(const cv::Mat& depth_m, float metres_per_unit, cv::Mat& raw_u16) {
    CV_Assert(depth_m.type() == CV_32FC1 && metres_per_unit > 0);
    raw_u16.create(depth_m.size(), CV_16UC1);
    const float inv = 1.0f / metres_per_unit;
    for (int v = 0; v < depth_m.rows; ++v) {
        const float* src = depth_m.ptr<float>(v);
        auto* dst = raw_u16.ptr<uint16_t>(v);
        for (int u = 0; u < depth_m.cols; ++u) {
            const float raw = src[u] * inv;
            dst[u] = (std::isfinite(raw) && raw > 0.5f && raw < 65535.5f) ? static_cast<uint16_t>(raw + 0.5f) : 0;
        }
    }
}

}  // namespace facescan::recon
