// The pinhole camera model: the ONE place projection and back-projection live (thesis eq. 4.7-4.9).
// Every module (renderer, filter, ICP, integration, raycast, detector) uses these helpers.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace facescan::recon {

// A rigid transform; T_a_b maps points in frame b to frame a (thesis eq. 4.1).
using Pose = Eigen::Isometry3f;

struct Intrinsics {
    int width_px = 640;
    int height_px = 480;
    float fx_px = 575.8f;  // Kinect v1 depth camera
    float fy_px = 575.8f;
    float cx_px = 319.5f;
    float cy_px = 239.5f;

    static Intrinsics kinectV1() { return {}; }

    bool valid() const {
        return width_px > 0 && height_px > 0 && fx_px > 0 && fy_px > 0 && std::isfinite(cx_px) && std::isfinite(cy_px);
    }
    bool operator==(const Intrinsics&) const = default;

    // Thesis eq. 4.8: pixel of a camera-frame point (z > 0). Sub-pixel; the pixel centre of column u is u.
    Eigen::Vector2f project(const Eigen::Vector3f& p_camera) const {
        const float inv_z = 1.0f / p_camera.z();
        return {p_camera.x() * fx_px * inv_z + cx_px, p_camera.y() * fy_px * inv_z + cy_px};
    }
    // The pixel whose centre is nearest to the sub-pixel position px (std::lround's result), false when that is off
    // the image (NaN included). Without lround, a libm call: per-point loops use this.
    bool nearestPixel(const Eigen::Vector2f& px, int& u_px, int& v_px) const {
        const float fu = px.x() + 0.5f, fv = px.y() + 0.5f;
        if (!(fu >= 0.0f && fv >= 0.0f && fu < static_cast<float>(width_px) && fv < static_cast<float>(height_px)))
            return false;
        u_px = static_cast<int>(fu);
        v_px = static_cast<int>(fv);
        return true;
    }
    // Thesis eq. 4.9: camera-frame point of pixel (u, v) at depth z (metres).
    Eigen::Vector3f backProject(float u_px, float v_px, float z_m) const {
        return {(u_px - cx_px) * z_m / fx_px, (v_px - cy_px) * z_m / fy_px, z_m};
    }
    // Unit-z ray through pixel (u, v): K^-1 [u v 1]^T (thesis eq. 4.24, 4.27).
    Eigen::Vector3f ray(float u_px, float v_px) const { return backProject(u_px, v_px, 1.0f); }
    bool contains(int u_px, int v_px) const { return u_px >= 0 && v_px >= 0 && u_px < width_px && v_px < height_px; }

    // The same camera at 1/2^level resolution (image pyramids).
    Intrinsics scaled(int level) const {
        const float s = 1.0f / static_cast<float>(1 << level);
        Intrinsics k;
        k.width_px = width_px >> level;
        k.height_px = height_px >> level;
        k.fx_px = fx_px * s;
        k.fy_px = fy_px * s;
        // Pixel centres: coordinate u at level 0 maps to (u + 0.5) * s - 0.5 at the coarser level.
        k.cx_px = (cx_px + 0.5f) * s - 0.5f;
        k.cy_px = (cy_px + 0.5f) * s - 0.5f;
        return k;
    }
};

// The pyramid level (Intrinsics::scaled) at which an image width_px wide is no wider than coarse_width_px, at most
// max_level: how many levels coarser than the frame a model cast at a lower resolution is.
inline int pyramidLevelOfWidth(int width_px, int coarse_width_px, int max_level) {
    int level = 0;
    while (level < max_level && (width_px >> level) > coarse_width_px) ++level;
    return level;
}

}  // namespace facescan::recon
