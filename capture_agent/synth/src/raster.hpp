// Internal: the software z-buffer rasteriser of the synthetic Kinect (perspective-correct barycentrics).
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "recon/camera.hpp"

namespace facescan::synth::detail {

// What the rasteriser leaves per pixel: the nearest triangle and where on it the pixel's ray hits.
struct GBuffer {
    cv::Mat depth_m;  // CV_32F camera-frame z of the hit, 0 = no hit
    cv::Mat tri;      // CV_32S triangle index, -1 = no hit
    cv::Mat bary;     // CV_32FC2 perspective-correct barycentrics (b1, b2) of corners 1 and 2 (b0 = 1 - b1 - b2)
};

// Rasterises `triangles` over camera-frame `points_camera` into `g` (allocated here, 640x480 per `k`).
// Triangles with a corner nearer than `near_m` are skipped (nothing in the scene comes that close).
// Rows are split in bands rendered in parallel (cv::parallel_for_); each band owns its rows, so no locks.
void rasterise(const std::vector<Eigen::Vector3f>& points_camera, const std::vector<Eigen::Vector3i>& triangles,
               const recon::Intrinsics& k, GBuffer& g, float near_m = 0.05f);

}  // namespace facescan::synth::detail
