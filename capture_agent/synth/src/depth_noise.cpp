// The depth noise models applied to an ideal depth image: the Kinect v1's of docs/design.md s6 (Nguyen, Izadi,
// Lovell 2012) and, in the same form, those of the other synthetic sensors (stereo_tof_noise.cpp adds their own
// failure modes).
#include "depth_noise.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>

namespace facescan::synth::detail {
namespace {

constexpr int kTableBits = 12;
constexpr int kTableSize = 1 << kTableBits;

// Standard normal quantiles at (i + 0.5) / N, by bisection on erfc (once, at start-up).
const std::array<float, kTableSize + 1>& normalTable() {
    static const std::array<float, kTableSize + 1> table = [] {
        std::array<float, kTableSize + 1> t{};
        for (int i = 0; i < kTableSize; ++i) {
            const double p = (i + 0.5) / kTableSize;
            double lo = -8, hi = 8;
            for (int it = 0; it < 60; ++it) {
                const double mid = 0.5 * (lo + hi);
                (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
            }
            t[i] = static_cast<float>(0.5 * (lo + hi));
        }
        t[kTableSize] = t[kTableSize - 1];
        return t;
    }();
    return table;
}

}  // namespace

float FastRng::normal() {
    const auto& t = normalTable();
    const uint64_t r = next();
    const int i = static_cast<int>(r >> (64 - kTableBits));
    const float f = static_cast<float>((r >> 20) & 0xFFFFF) * (1.0f / 1048576.0f);
    // Between nodes i and i+1 the quantile is nearly linear; the last node has no successor and stays flat.
    return t[i] + f * (t[i + 1] - t[i]);
}

float axialSigmaM(const NoiseParams& p, float z_m, float theta_rad) {
    constexpr float kHalfPi = 1.57079632679f;
    const float dz = z_m - p.axial_z0_m;
    const float angle = theta_rad * theta_rad / ((kHalfPi - theta_rad) * (kHalfPi - theta_rad));
    return p.axial_a_m + p.axial_b_per_m * dz * dz + p.angle_coeff_m / std::sqrt(z_m) * angle;
}

void projectorShadow(const NoiseParams& p, const recon::Intrinsics& k, const cv::Mat& depth_true_m, cv::Mat& shadow) {
    shadow.create(depth_true_m.size(), CV_8U);
    shadow.setTo(0);
    if (!p.shadow) return;
    const float fb = k.fx_px * p.baseline_m;
    cv::parallel_for_(cv::Range(0, depth_true_m.rows), [&](const cv::Range& rows) {
        for (int v = rows.start; v < rows.end; ++v) {
            const float* z = depth_true_m.ptr<float>(v);
            uint8_t* s = shadow.ptr<uint8_t>(v);
            // The projector (or the second imager) sits at +x of the camera, so its epipolar lines are the image rows
            // and a surface point at column u lights up projector column u - f b / z. Scanning right to left, a point
            // whose projector column is right of one already seen (nearer to the projector's view) is occluded from the
            // projector: the classic shadow band left of every foreground edge.
            float min_up = std::numeric_limits<float>::max();
            for (int u = depth_true_m.cols - 1; u >= 0; --u) {
                if (!(z[u] > 0)) continue;
                const float up = static_cast<float>(u) - fb / z[u];
                if (up > min_up + 0.5f) {
                    s[u] = 255;
                } else {
                    min_up = std::min(min_up, up);
                }
            }
        }
    });
}

void applyDepthNoise(const NoiseParams& p, const recon::Intrinsics& k, const cv::Mat& depth_true_m,
                     const cv::Mat& cos_incidence, const cv::Mat& colour_bgr, uint64_t seed, cv::Mat& depth_m) {
    cv::Mat shadow;
    projectorShadow(p, k, depth_true_m, shadow);
    // What each pixel sees before the random noise: the ideal depth, or a time-of-flight camera's phase depth.
    const bool tof = p.principle == DepthPrinciple::kTimeOfFlight;
    cv::Mat tof_depth, flying, matchable;
    if (tof) timeOfFlightDepth(p, depth_true_m, mix64(seed ^ 0x70F70Full), tof_depth, flying);
    const cv::Mat& source = tof ? tof_depth : depth_true_m;
    if (p.principle == DepthPrinciple::kActiveStereo) {
        stereoMatchable(p, depth_true_m, cos_incidence, colour_bgr, matchable);
        shadow.setTo(255, matchable == 0);
    }
    depth_m.create(depth_true_m.size(), CV_32F);
    const float fb = k.fx_px * p.baseline_m;
    const float max_theta = p.max_incidence_deg * static_cast<float>(M_PI / 180.0);
    const int w = depth_true_m.cols, h = depth_true_m.rows;
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
        for (int v = rows.start; v < rows.end; ++v) {
            FastRng rng(mix64(seed) ^ static_cast<uint64_t>(v) * 0xD6E8FEB86659FD93ull);
            float* out = depth_m.ptr<float>(v);
            for (int u = 0; u < w; ++u) {
                // Lateral noise: the sample comes from a jittered pixel (sigma in pixels, rounded to a pixel).
                const int su =
                    std::clamp(u + static_cast<int>(std::lround(p.lateral_sigma_px * rng.normal())), 0, w - 1);
                const int sv =
                    std::clamp(v + static_cast<int>(std::lround(p.lateral_sigma_px * rng.normal())), 0, h - 1);
                const float z_true = source.at<float>(sv, su);
                const float n_axial = rng.normal();
                const float dropout = rng.uniform();
                out[u] = 0;
                if (!(z_true > 0) || shadow.at<uint8_t>(sv, su)) continue;
                // A flying pixel's return comes from two surfaces, whatever the incidence on either.
                const bool mixed = tof && flying.at<uint8_t>(sv, su) != 0;
                const float theta = mixed ? 0.0f : std::acos(std::clamp(cos_incidence.at<float>(sv, su), 0.0f, 1.0f));
                if (theta > max_theta || dropout < p.dropout_rate) continue;
                float z = z_true + axialSigmaM(p, z_true, theta) * n_axial;
                // Disparity quantisation: the sensor measures d = f b / z in steps (1/8 pixel on the Kinect v1).
                if (p.disparity_step_px > 0 && z > 0) {
                    const float d = std::round(fb / z / p.disparity_step_px) * p.disparity_step_px;
                    z = d > 0 ? fb / d : 0.0f;
                }
                if (p.depth_step_m > 0) z = std::round(z / p.depth_step_m) * p.depth_step_m;
                if (z < p.min_range_m || z > p.max_range_m) continue;
                out[u] = z;
            }
        }
    });
}

}  // namespace facescan::synth::detail
