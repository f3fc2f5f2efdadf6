// Internal: the depth noise models (Kinect v1: Nguyen, Izadi, Lovell 2012, docs/design.md s6; the other sensors:
// kinect_simulator.hpp's NoiseParams factories) and the random numbers
// it needs (counter-based seeding so any frame or row can be generated independently and deterministically).
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>

#include "recon/camera.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::synth::detail {

// SplitMix64: the seed mixer; a different stream per (seed, frame, row).
inline uint64_t mix64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

// xorshift64* generator with a table-based standard normal (inverse CDF at 4096 nodes, linearly interpolated;
// tails beyond 3.5 sigma are clipped, immaterial for sensor noise) so ~300k pixels cost a few ms.
class FastRng {
 public:
    explicit FastRng(uint64_t seed) : s_(mix64(seed) | 1) {}
    uint64_t next() {
        s_ ^= s_ >> 12;
        s_ ^= s_ << 25;
        s_ ^= s_ >> 27;
        return s_ * 0x2545F4914F6CDD1Dull;
    }
    float uniform() { return static_cast<float>(next() >> 40) * (1.0f / 16777216.0f); }  // [0, 1)
    float normal();

 private:
    uint64_t s_;
};

// Axial standard deviation (metres) at depth z (metres) and incidence angle theta (radians): Nguyen et al.
// sigma_z = a + b (z - z0)^2 + c / sqrt(z) * theta^2 / (pi/2 - theta)^2.
float axialSigmaM(const NoiseParams& p, float z_m, float theta_rad);

// Turns the ideal depth into a measurement of the sensor p describes. Every principle: lateral jitter, axial noise
// (axialSigmaM), incidence and range limits, dropouts. Structured light: projector shadows and disparity
// quantisation. Active stereo: the second imager's shadow and holes where matching fails (stereoMatchable).
// Time of flight: flying pixels and multipath (timeOfFlightDepth), depth quantisation. `cos_incidence` (CV_32F)
// is |n . view| of the ideal surface per pixel, `colour_bgr` the rendered colour (the stereo texture). `seed`
// selects the frame's random stream. Rows are processed in parallel.
void applyDepthNoise(const NoiseParams& p, const recon::Intrinsics& k, const cv::Mat& depth_true_m,
                     const cv::Mat& cos_incidence, const cv::Mat& colour_bgr, uint64_t seed, cv::Mat& depth_m);

// The shadow mask alone (CV_8U, 255 = the projector's light, or the second stereo imager, cannot reach that pixel's
// surface): baseline_m to the +x side of the camera.
void projectorShadow(const NoiseParams& p, const recon::Intrinsics& k, const cv::Mat& depth_true_m, cv::Mat& shadow);

// Active stereo: CV_8U, 255 where the matcher finds texture (the projected pattern or the surface's own).
void stereoMatchable(const NoiseParams& p, const cv::Mat& depth_true_m, const cv::Mat& cos_incidence,
                     const cv::Mat& colour_bgr, cv::Mat& matchable);

// Time of flight: the depth each pixel's phase says before random noise: flying pixels (flying: CV_8U, 255 where
// the pixel mixes two surfaces) and the multipath bias in concavities. Deterministic in `seed`.
void timeOfFlightDepth(const NoiseParams& p, const cv::Mat& depth_true_m, uint64_t seed, cv::Mat& depth_m,
                       cv::Mat& flying);

}  // namespace facescan::synth::detail
