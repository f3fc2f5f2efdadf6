// Re-acquisition after a loss: the head is back in view, but at a pose that frame-to-model ICP from the
// last good pose cannot reach (it turned while out of view, or turned too fast). Hypotheses rotate the camera about
// the head's vertical and horizontal axes from the last good pose, each re-centred on the head (thesis eq. 4.11's
// centroid alignment, between the frame's head centre and the head region's). For each, the model is ray-cast
// from that view at a coarse level and ICP (thesis 4.1.3) runs against it; the best few are refined at a finer
// level and verified (model_agreement.hpp: inlier share, residual, free space). The best verified fit wins; a fit
// that fails verification is never returned, so nothing is fused at a wrong pose.
// Cost: bounded by the hypothesis count (21 by default) and runs only on frames after a loss.
#pragma once

#include <vector>

#include "recon/camera.hpp"
#include "recon/depth_filter.hpp"
#include "recon/icp.hpp"
#include "recon/model_agreement.hpp"
#include "recon/model_segmenter.hpp"
#include "recon/raycaster.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

struct ReacquireParams {
    bool enabled = true;
    float yaw_step_deg = 12.0f;    // degrees between yaw hypotheses about the head's vertical axis
    int yaw_steps = 3;             // count; hypotheses at 0, +-1, ... +-yaw_steps steps (+-36 deg by default)
    float pitch_step_deg = 15.0f;  // degrees between pitch hypotheses (nodding)
    int pitch_steps = 1;           // count; 0, +-1, ... steps
    int refine_candidates = 3;     // count; best coarse fits refined and verified
    int min_points = 200;          // count; frame points at the coarse level needed to try at all
    // The hypothesis casts look for the model this far in front of / behind each measured depth (metres).
    float window_before_m = 0.10f;
    float window_after_m = 0.05f;
    // Verification (at pyramid level 1): a measured point within agree_m of the model surface is an inlier; one
    // more than conflict_m behind the model surface contradicts the model's free space.
    float agree_m = 0.005f;     // metres
    float conflict_m = 0.015f;  // metres
    // Measured on the synthetic head at 0.7 m: right fits 0.75-0.95 inliers at 0.6-0.8 mm; fits 16-36 deg off on
    // a half-hidden head 0.6 inliers at 2.1 mm.
    float min_agree_share = 0.65f;     // ratio of measured points that must be inliers
    float max_conflict_share = 0.05f;  // ratio of associated points allowed to contradict free space
    float max_rmse_m = 0.0015f;        // metres; RMS distance of the inliers
    // A fit after skipped frames (acceptsNewView): the frame may show surface the model has not seen yet (a model of
    // one frame covered 60 % of a frame 9.6 deg later), so the inlier share counts over the points the model has a
    // surface for, of which there must be at least this share of the measured points.
    float min_covered_share = 0.5f;  // ratio
    Status validate() const;
};

struct ReacquireResult {
    bool found = false;
    Pose T_world_camera = Pose::Identity();  // the verified pose when found
    PoseCheck check;                         // verification of the winner, or of the best rejected candidate
    int hypotheses = 0;                      // count; tried this frame
    int refined = 0;                         // count; refined and verified
    const char* why = "";                    // static text when not found
};

class Reacquirer {
 public:
    // k: level-0 intrinsics of the frames; icp: the tracker's ICP parameters (the refine stage inherits its
    // convergence settings).
    Reacquirer(const Intrinsics& k, const ReacquireParams& p, const IcpParams& icp);

    // Searches for the pose of `frame` (the filtered, segmented frame pyramid, camera frame) against the model in
    // `grid`, starting from last_good (T_world_camera of the last integrated frame). No allocation after the
    // first call.
    ReacquireResult search(const VoxelBlockGrid& grid, const SurfacePyramid& frame, const Pose& last_good,
                           const HeadRegion& region);

    // Verifies one pose: casts the model from it at level 1 around the frame's depth and checks agreement.
    PoseCheck verify(const VoxelBlockGrid& grid, const SurfacePyramid& frame, const Pose& T_world_camera);
    bool accepts(const PoseCheck& check) const;
    // The same thresholds for a tracked fit that moved further than one frame allows because frames were skipped:
    // agreement over the points the model covers (min_covered_share of them at least), as the model may not have
    // seen all the frame shows yet.
    bool acceptsNewView(const PoseCheck& check) const;

    const ReacquireParams& params() const { return params_; }

 private:
    struct Candidate {
        Pose pose;
        float score = 0;
    };
    void castLevel(const VoxelBlockGrid& grid, const SurfaceLevel& frame_level, const Pose& T_world_camera,
                   SurfaceLevel& out) const;

    ReacquireParams params_;
    Raycaster wide_;                        // casts with a search window around each measured depth
    Icp coarse_icp_;                        // one level, wide gates
    Icp refine_icp_;                        // two levels (1 and 2 of the frame), tighter gates
    SurfacePyramid cast_;                   // model casts at levels 0-2 (levels 1 and 2 used)
    SurfacePyramid src_view_, model_view_;  // sub-pyramids sharing the frame's and cast_'s images (no copies)
    std::vector<Candidate> candidates_;
};

}  // namespace facescan::recon
