// The failure modes of the synthetic active stereo and time-of-flight cameras (kinect_simulator.hpp's
// NoiseParams::activeStereo and NoiseParams::timeOfFlight, with their sources); depth_noise.cpp adds the random
// noise that all sensors share.
#include <algorithm>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "depth_noise.hpp"

namespace facescan::synth::detail {

void stereoMatchable(const NoiseParams& p, const cv::Mat& depth_true_m, const cv::Mat& cos_incidence,
                     const cv::Mat& colour_bgr, cv::Mat& matchable) {
    // The surface's own texture: the grey level's standard deviation over the matcher's window.
    cv::Mat grey, grey_f, mean, mean_sq;
    cv::cvtColor(colour_bgr, grey, cv::COLOR_BGR2GRAY);
    grey.convertTo(grey_f, CV_32F);
    const cv::Size window(p.texture_window_px, p.texture_window_px);
    cv::boxFilter(grey_f, mean, CV_32F, window);
    cv::boxFilter(grey_f.mul(grey_f), mean_sq, CV_32F, window);
    const float min_var = p.texture_min_grey * p.texture_min_grey;
    const float range_sq = p.pattern_range_m * p.pattern_range_m;
    matchable.create(depth_true_m.size(), CV_8U);
    cv::parallel_for_(cv::Range(0, depth_true_m.rows), [&](const cv::Range& rows) {
        for (int v = rows.start; v < rows.end; ++v) {
            const float* z = depth_true_m.ptr<float>(v);
            const float* c = cos_incidence.ptr<float>(v);
            const float* m = mean.ptr<float>(v);
            const float* m2 = mean_sq.ptr<float>(v);
            uint8_t* out = matchable.ptr<uint8_t>(v);
            for (int u = 0; u < depth_true_m.cols; ++u) {
                // The pattern's irradiance falls with z^2 and its brightness on the surface with the incidence
                // cosine: matched while z^2 / cos stays within the reach on a frontal surface squared.
                const bool pattern = c[u] > 0 && z[u] * z[u] <= range_sq * c[u];
                const bool texture = m2[u] - m[u] * m[u] >= min_var;
                out[u] = pattern || texture ? 255 : 0;
            }
        }
    });
}

void timeOfFlightDepth(const NoiseParams& p, const cv::Mat& depth_true_m, uint64_t seed, cv::Mat& depth_m,
                       cv::Mat& flying) {
    const int w = depth_true_m.cols, h = depth_true_m.rows;
    const cv::Mat valid = depth_true_m > 0;
    constexpr float kNone = 1e6f;
    // Nearest and farthest surface in each pixel's footprint and its neighbours (3 x 3), ignoring pixels without a
    // return.
    cv::Mat filled = depth_true_m.clone(), z_lo, z_hi;
    filled.setTo(kNone, ~valid);
    const cv::Mat k3 = cv::Mat::ones(3, 3, CV_8U);
    cv::erode(filled, z_lo, k3);
    cv::dilate(depth_true_m, z_hi, k3);
    // The multipath window: mean surface and depth spread around each pixel.
    cv::Mat sum, count, win_lo, win_hi;
    const bool multipath = p.multipath_gain > 0 && p.multipath_max_m > 0;
    if (multipath) {
        const cv::Size window(p.multipath_window_px, p.multipath_window_px);
        cv::Mat valid_f;
        valid.convertTo(valid_f, CV_32F, 1.0 / 255.0);
        cv::boxFilter(depth_true_m, sum, CV_32F, window, cv::Point(-1, -1), false);
        cv::boxFilter(valid_f, count, CV_32F, window, cv::Point(-1, -1), false);
        const cv::Mat kw = cv::Mat::ones(window, CV_8U);
        cv::erode(filled, win_lo, kw);
        cv::dilate(depth_true_m, win_hi, kw);
    }
    depth_m.create(depth_true_m.size(), CV_32F);
    flying.create(depth_true_m.size(), CV_8U);
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
        for (int v = rows.start; v < rows.end; ++v) {
            FastRng rng(seed ^ static_cast<uint64_t>(v) * 0x9FB21C651E98DF25ull);
            const float* z = depth_true_m.ptr<float>(v);
            float* out = depth_m.ptr<float>(v);
            uint8_t* fly = flying.ptr<uint8_t>(v);
            for (int u = 0; u < w; ++u) {
                const float pick = rng.uniform(), share = rng.uniform();
                fly[u] = 0;
                out[u] = z[u];
                const float lo = z_lo.at<float>(v, u), hi = z_hi.at<float>(v, u);
                // Flying pixel: the footprint straddles two surfaces and the phase of the mixed return lies
                // between them (a share of each, uniformly distributed).
                if (lo < kNone && hi - lo > p.flying_jump_m && pick < p.flying_pixel_rate) {
                    out[u] = share * lo + (1.0f - share) * hi;
                    fly[u] = 255;
                    continue;
                }
                if (!multipath || !(z[u] > 0)) continue;
                if (win_hi.at<float>(v, u) - win_lo.at<float>(v, u) > p.flying_jump_m) continue;
                const float behind = z[u] - sum.at<float>(v, u) / count.at<float>(v, u);
                if (behind > 0) out[u] = z[u] + std::min(p.multipath_gain * behind, p.multipath_max_m);
            }
        }
    });
}

}  // namespace facescan::synth::detail
