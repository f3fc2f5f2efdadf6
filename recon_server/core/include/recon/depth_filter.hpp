// Noise reduction and the depth pyramid (thesis section 4.1.1, eq. 4.4-4.6), and the vertex and normal maps that
// registration and integration consume (thesis eq. 4.9-4.10). Everything works on a region of interest (the head)
// of full-size, preallocated images so that the frame loop does not allocate.
#pragma once

#include <array>
#include <opencv2/core.hpp>
#include <vector>

#include "recon/camera.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

inline constexpr int kMaxPyramidLevels = 4;

struct FilterParams {
    float sigma_space_px = 1.0f;       // pixels; spatial closeness sigma of eq. 4.5 (Meyer: 1 px)
    float sigma_depth_m = 0.05f;       // metres; depth similarity sigma of eq. 4.6 (Meyer: 50 mm)
    int radius_px = 2;                 // pixels; window half-size (2 => 5x5, covers 2 sigma_space)
    int levels = 3;                    // count; pyramid levels (level 0 = full resolution)
    float pyramid_max_step_m = 0.03f;  // metres; 2x2 children further than this from the first valid one are
                                       // left out of the coarser pixel, so edges do not blend foreground/background
    float min_depth_m = 0.3f;          // metres; measurements nearer than this are treated as invalid
    float max_depth_m = 3.0f;          // metres; and further than this
    Status validate() const;
};

// One level of a frame's point cloud: vertices and normals (CV_32FC3, NaN = invalid) in the camera frame.
struct SurfaceLevel {
    Intrinsics k;     // intrinsics of this level
    cv::Mat depth_m;  // CV_32F, metres, 0 = invalid
    cv::Mat vertex;   // CV_32FC3, camera frame metres, NaN x = invalid (thesis eq. 4.9)
    cv::Mat normal;   // CV_32FC3, unit normals facing the camera, NaN x = invalid (thesis eq. 4.10)
    cv::Rect roi;     // where valid pixels may be; outside it everything is invalid
    // CV_32F: the model's accumulated weight W (eq. 4.24) where each pixel's ray met the surface (set where the
    // vertex is valid, undefined elsewhere). Only on the ray cast model's finest level, and only when registration
    // weighs its pairs by it (IcpParams::confident_model_weight); empty elsewhere.
    cv::Mat weight;
};

// The filtered, masked frame at every pyramid level; all images are allocated once by allocate().
struct SurfacePyramid {
    std::array<SurfaceLevel, kMaxPyramidLevels> levels;
    int count = 0;
    void allocate(const Intrinsics& k, int level_count);
};

// Filters a masked depth image and builds the pyramid with vertex/normal maps. Preallocates all buffers for one
// camera; filter() does no allocation.
class DepthFilter {
 public:
    DepthFilter(const Intrinsics& k, const FilterParams& p);

    // depth_m: CV_32F metres (0 or NaN = invalid) of the camera's size; mask: CV_8U nonzero = keep, or empty (keep
    // all). mask_box: where the mask may be nonzero (a segmenter's HeadSegmentation::written_px); pixels outside it
    // are not kept and not read, so the first pass sweeps the head's box instead of the whole frame. Empty: the
    // whole frame. Returns the number of valid level-0 pixels after filtering (0 when none). Sizes must match the
    // camera (the caller checks; see Reconstructor). normals_from_level: the normal maps of the finer levels are
    // not computed (they keep the last frame's: computeNormals when one is needed after all); 0 = every level.
    int filter(const cv::Mat& depth_m, const cv::Mat& mask, SurfacePyramid& out, const cv::Rect& mask_box = {},
               int normals_from_level = 0);
    // The normal map of one level (eq. 4.10) from its vertex map, as filter() makes it.
    void computeNormals(SurfaceLevel& level) const;

    const FilterParams& params() const { return params_; }

 private:
    Intrinsics k_;
    FilterParams params_;
    cv::Mat masked_;                   // CV_32F, the input after masking and range checks
    std::vector<float> space_weight_;  // exp(-(du^2 + dv^2) / 2 sigma_c^2) over the window, row-major (eq. 4.5)
    static constexpr size_t kRangeSteps = 512;
    // exp(-dz^2 / 2 sigma_s^2) indexed by |dz| / range_step_m_ up to 3 sigma, then 0 (eq. 4.6)
    std::array<float, kRangeSteps + 1> range_lut_{};
    float range_step_m_ = 0.0f;
};

// The mean of a level's valid vertices inside its ROI (in the level's frame) and how many there are; returns 0
// and leaves `centroid` unchanged when there is none.
int validCentroid(const SurfaceLevel& level, Eigen::Vector3f& centroid);

// Thesis eq. 4.9 over an ROI: vertex map of a depth image (NaN where depth is 0).
void computeVertexMap(const Intrinsics& k, const cv::Mat& depth_m, const cv::Rect& roi, cv::Mat& vertex);
// Thesis eq. 4.10: n = (v[i+1,j] - v[i,j]) x (v[i,j+1] - v[i,j]), normalised and oriented toward the camera;
// NaN where a neighbour is missing or the neighbours are more than max_step_m apart (a depth edge).
void computeNormalMap(const cv::Mat& vertex, const cv::Rect& roi, float max_step_m, cv::Mat& normal);
// Half-resolution copy of a vertex or normal map (mean of valid 2x2 children; normals renormalised). Used for the
// coarse levels of the ray-cast model. dst must be preallocated to src.size()/2.
void downsampleVertexMap(const cv::Mat& src, const cv::Rect& src_roi, cv::Mat& dst, cv::Rect& dst_roi);
void downsampleNormalMap(const cv::Mat& src, const cv::Rect& src_roi, cv::Mat& dst, cv::Rect& dst_roi);

}  // namespace facescan::recon
