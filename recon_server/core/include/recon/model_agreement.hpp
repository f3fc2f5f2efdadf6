// How well a frame agrees with the model at a pose. Both tests pair each measured point with the model
// surface seen along the same ray of the model's camera, the projective association of thesis Algorithm 2:
//  - checkPose verifies a fit before anything is fused after a loss: the share of measured points on the model
//    surface (inliers), their residual, and the share that lies behind a model surface, where the camera would
//    have to see through the model (free space disagreeing);
//  - rejectOccludingDepth is robust integration: a measurement more than the truncation band in front of a
//    confident model surface (a hand passing in front of the face) is removed from the frame before integration,
//    so it leaves no trace in the volume. Measurements behind the model are kept: a surface that comes into view
//    from behind a silhouette is new, not wrong.
#pragma once

#include "recon/camera.hpp"
#include "recon/depth_filter.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

struct PoseCheck {
    int measured = 0;     // count; valid measured points
    int associated = 0;   // count; of which the model has a surface at the associated pixel
    int agreeing = 0;     // count; within agree_m of that surface (inliers)
    int conflicting = 0;  // count; further than conflict_m behind it along the model camera's ray
    float rmse_m = 0.0f;  // metres; RMS distance of the agreeing points to the model surface
    float agreeShare() const { return measured > 0 ? static_cast<float>(agreeing) / measured : 0.0f; }
    float conflictShare() const { return associated > 0 ? static_cast<float>(conflicting) / associated : 0.0f; }
};

// source_camera: a frame level (camera-frame vertices); model_world: a ray-cast model level (world-frame vertices)
// rendered from T_world_model at the same resolution. T_world_camera: the pose under test.
PoseCheck checkPose(const SurfaceLevel& source_camera, const SurfaceLevel& model_world, const Pose& T_world_model,
                    const Pose& T_world_camera, float agree_m, float conflict_m);

// Invalidates (depth 0, vertex and normal NaN) the pixels of `frame`'s level 0 (camera frame) whose point at
// T_world_camera lies more than band_m in front of the model surface (model_world from T_world_model) where the
// volume's weight at that surface is at least min_weight, and the coarser levels' pixels that cover them. Returns
// the number of level-0 pixels removed. When hint_m is given (CV_32F, frame size), the model's depth is written
// there for each removed pixel, so the next ray cast still finds the surface behind the occluder (and the next
// frame is compared with it). level > 0: the same test over that level's pixels instead of level 0's (and the
// coarser levels'; the finer ones are left as they are, and hint_m must be null): for a frame registered on the
// coarser levels only (ReconParams::unfused_finest_level), a quarter of the pixels. No allocation.
int rejectOccludingDepth(SurfacePyramid& frame, const SurfaceLevel& model_world, const Pose& T_world_model,
                         const Pose& T_world_camera, const VoxelBlockGrid& grid, float band_m, float min_weight,
                         cv::Mat* hint_m = nullptr, int level = 0);

}  // namespace facescan::recon
