// One depth image as a mesh: the single-raw-frame baseline that fusion must beat (facescan-bench accuracy).
#pragma once

#include <opencv2/core.hpp>

#include "recon/camera.hpp"
#include "recon/mesh.hpp"

namespace facescan::eval {

// Back-projects every valid pixel (depth > 0 and mask != 0 where a CV_8U mask is given) with the camera's
// back-projection (thesis eq. 4.9) and joins 2x2 pixel neighbourhoods into triangles whose edges are all
// shorter than max_edge_m (no bridges across depth edges). Points in the camera frame, metres.
recon::Mesh meshFromDepth(const cv::Mat& depth_m, const recon::Intrinsics& k, const cv::Mat& mask = cv::Mat(),
                          float max_edge_m = 0.01f);

}  // namespace facescan::eval
