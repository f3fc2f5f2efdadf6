// Surface extraction by ray casting (thesis section 4.2.2, eq. 4.27-4.30): rays step through D(x) until it changes
// sign, the crossing is interpolated (eq. 4.28-4.29) and the normal is the gradient of D (eq. 4.30). Used for the
// model the next frame is registered against, and for a shaded preview image.
#pragma once

#include <opencv2/core.hpp>

#include "recon/camera.hpp"
#include "recon/depth_filter.hpp"
#include "recon/status.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

struct RaycastParams {
    float step_trunc_fraction = 0.8f;   // ratio; ray step as a share of mu (thesis: smaller than mu, or it may
                                        // miss the zero crossing)
    float start_before_hint_m = 0.01f;  // metres; with a depth hint (the frame just integrated at the pose just
                                        // estimated: the model is within noise of it), rays start this far in
                                        // front of it...
    float search_after_hint_m = 0.03f;  // metres; ...and give up this far behind it
    int hint_search_px = 4;             // pixels; a ROI pixel without a hint borrows the nearest one of its row
                                        // within this distance (covers the silhouette's motion to the next
                                        // frame and dropouts)...
    float hint_widen_m = 0.015f;        // metres; ...with the search window widened by this on both sides.
                                        // 12 px and 0.03 m marched 61 % of the samples for rays that mostly
                                        // missed; 4 px and 0.015 m: ray cast -25 %, same accuracy and tracking
                                        // in every synthetic scenario and on 7-Scenes.
    bool march_without_hint = false;    // rays with no hint even then march the whole cube (empty blocks are
                                        // skipped half a block at a time); false = no surface there. Without
                                        // any hint image (empty depth_hint_m) rays always march the whole cube.
    Status validate() const;
};

class Raycaster {
 public:
    explicit Raycaster(const RaycastParams& p) : params_(p) {}

    // Casts the pixels of `roi` from T_world_camera. depth_hint_m (CV_32F, may be empty) is where the surface is
    // expected per pixel (the frame just integrated). Writes world-frame vertex and normal maps into out.vertex /
    // out.normal (preallocated, camera size; NaN = no surface) and sets out.roi and out.k. No allocation.
    void cast(const VoxelBlockGrid& grid, const Intrinsics& k, const Pose& T_world_camera, const cv::Rect& roi,
              const cv::Mat& depth_hint_m, SurfaceLevel& out) const;

    // A Lambert-shaded grey image of the model seen from T_world_camera (light at the camera), tinted by the voxel
    // colours when they exist; background black. Allocates shaded_bgr (CV_8UC3, camera size) when needed.
    void renderShaded(const VoxelBlockGrid& grid, const Intrinsics& k, const Pose& T_world_camera,
                      cv::Mat& shaded_bgr) const;

    const RaycastParams& params() const { return params_; }

 private:
    RaycastParams params_;
};

}  // namespace facescan::recon
