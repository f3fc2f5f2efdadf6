// The reconstructor's state as plain data, for replication to a standby server and for resuming after a restart:
// the volume's blocks (all of them, or those changed since an earlier capture), the poses, the
// trajectory and the counters. The core only copies memory here; encoding, compression, DDS and files are the
// service's and the wire layer's business (wire/replica_codec.hpp).
//
//   recon::ReconState delta;
//   reconstructor.captureState(last.generation, last.trajectory_size, delta);   // on the frame thread
//   recon::mergeState(standby_copy, delta);                                      // on the standby
//   fresh_reconstructor.restoreState(standby_copy);                               // at takeover
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <utility>
#include <vector>

#include "recon/camera.hpp"
#include "recon/model_segmenter.hpp"
#include "recon/status.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

// Blocks of a TsdfVolume: coords[i] owns voxels [i*512, (i+1)*512), x fastest (VoxelBlockGrid's layout).
struct TsdfBlocks {
    std::vector<Eigen::Vector3i> coords;  // block coordinates, 0..blocks_per_side-1
    std::vector<Voxel> voxels;
    size_t count() const { return coords.size(); }
};

struct ReconState {
    // The volume's geometry: a state only applies to a reconstructor with the same (checked by restoreState).
    int resolution_vox = 0;
    float volume_size_m = 0;
    float trunc_dist_m = 0;
    bool placed = false;  // the cube has been placed (origin_world is meaningful)
    Eigen::Vector3f origin_world = Eigen::Vector3f::Zero();

    // Which part this is. A full state holds every allocated block and the whole trajectory; a delta holds the
    // blocks integrated after `since_generation` and the trajectory entries from `trajectory_begin` on.
    bool full = true;
    uint64_t generation = 0;        // the volume's integration counter at capture: the next delta's `since`
    uint64_t since_generation = 0;  // deltas: changes after this generation
    int total_blocks = 0;           // count; allocated blocks in the model at capture (the delta's may be fewer)
    TsdfBlocks blocks;

    // Tracking.
    bool have_model = false;
    int frames_integrated = 0;
    int consecutive_failures = 0;
    Pose T_world_camera = Pose::Identity();
    Pose T_world_model = Pose::Identity();  // where the model was last ray cast from
    cv::Rect model_roi;                     // the last ray cast's pixels (restore casts them again)
    HeadRegion region;                      // where the head can be, fixed at the first frame
    float visible_ref_px = 0;               // running mean of the head's pixels over fused frames
    bool verify_next = false;               // the next fit must be verified before it is fused

    // Trajectory entries [trajectory_begin, trajectory_begin + trajectory.size()): timestamp (ns) and pose.
    size_t trajectory_begin = 0;
    std::vector<std::pair<int64_t, Pose>> trajectory;
    size_t trajectorySize() const { return trajectory_begin + trajectory.size(); }

    // Sizes and values make sense (finite poses and voxels, coordinates inside the cube, no duplicate block).
    // Every state decoded from the network or a file passes this before it is used.
    Status validate() const;
};

// Applies `delta` onto `base` (a full state): replaces or adds its blocks, takes its poses, counters and
// trajectory tail. Fails (and leaves base unchanged) when delta is not the continuation of base: another volume,
// a generation gap, a reset in between, or a trajectory that does not join.
Status mergeState(ReconState& base, const ReconState& delta);

}  // namespace facescan::recon
