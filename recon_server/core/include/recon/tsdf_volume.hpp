// The volumetric model (thesis section 4.2.1): a truncated signed distance function D(x) and weight W(x) on a cube
// of voxels (eq. 4.22-4.26, Algorithm 3), with a running-average colour per voxel. Storage is sparse: the cube is
// cut into 8^3-voxel blocks, and only blocks that a frame's head surface touches (within the truncation band) are
// allocated, from a pool reserved up front, and integrated. The whole 256^3 grid is never visited.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "recon/camera.hpp"
#include "recon/depth_filter.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

inline constexpr int kBlockSide = 8;                                       // voxels per block edge
inline constexpr int kBlockVoxels = kBlockSide * kBlockSide * kBlockSide;  // 512

struct TsdfParams {
    int resolution_vox = 256;      // voxels per cube edge (a multiple of 8)
    float volume_size_m = 0.386f;  // metres; cube edge (Meyer: 0.386 m => 1.51 mm voxels)
    float trunc_dist_m = 0.005f;   // metres; mu of Algorithm 3 (Meyer: 5 mm)
    float max_weight = 256.0f;     // W(x) saturates here (Meyer: 256), so the model keeps adapting
    // Weight of a measurement (Algorithm 3): exp(-(1 - cos theta) / angle_sigma) * exp(-Z^2 / (2 depth_sigma^2)),
    // theta = angle between the surface normal and the viewing ray, Z = measured depth.
    float weight_angle_sigma = 0.5f;        // dimensionless; in units of (1 - cos theta)
    float weight_depth_sigma_m = 1.5f;      // metres
    float min_cos_angle = 0.2f;             // cos; grazing measurements (> ~78 deg) are not integrated
    int max_blocks = 8192;                  // count; block pool reserved up front (8192 x 512 voxels x 12 B = 48 MB)
    float centre_behind_surface_m = 0.07f;  // metres; the cube's centre is placed this far behind the centroid of
                                            // the first frame's head points, along the view ray (a head's depth)
    Status validate() const;
    float voxelSizeM() const { return volume_size_m / static_cast<float>(resolution_vox); }
};

// One voxel: normalised TSDF in [-1, 1] (units of trunc_dist_m), accumulated weight, running-average colour.
struct Voxel {
    float tsdf = 1.0f;
    float weight = 0.0f;
    uint8_t b = 0, g = 0, r = 0, pad = 0;
};
static_assert(sizeof(Voxel) == 12);

// The sparse voxel grid as plain data: what the integrator writes and the ray caster and marching cubes read.
// A snapshot for another thread is a copy of this (only the allocated blocks are copied).
struct VoxelBlockGrid {
    int resolution_vox = 0;                                  // voxels per edge
    int blocks_per_side = 0;                                 // resolution_vox / 8
    float voxel_size_m = 0.0f;                               // metres
    float trunc_dist_m = 0.0f;                               // metres
    Eigen::Vector3f origin_world = Eigen::Vector3f::Zero();  // metres; world position of voxel (0,0,0)'s centre
    std::vector<int32_t> block_index;                        // blocks_per_side^3 entries; -1 = not allocated
    std::vector<Eigen::Vector3i> block_coords;               // block coordinates of each allocated block, pool order
    std::vector<Voxel> voxels;                               // pool: block i owns voxels [i*512, (i+1)*512), x fastest
    int allocated_blocks = 0;                                // count; blocks in use (a prefix of the pool)

    // Voxel at integer coordinates, or nullptr outside the cube or in an unallocated block.
    const Voxel* voxel(int x, int y, int z) const {
        if (static_cast<unsigned>(x) >= static_cast<unsigned>(resolution_vox) ||
            static_cast<unsigned>(y) >= static_cast<unsigned>(resolution_vox) ||
            static_cast<unsigned>(z) >= static_cast<unsigned>(resolution_vox))
            return nullptr;
        const int b =
            block_index[(static_cast<size_t>(z >> 3) * blocks_per_side + (y >> 3)) * blocks_per_side + (x >> 3)];
        if (b < 0) return nullptr;
        return &voxels[static_cast<size_t>(b) * kBlockVoxels + ((z & 7) * 64 + (y & 7) * 8 + (x & 7))];
    }
    // Continuous voxel coordinates of a world point (voxel centres at integers).
    Eigen::Vector3f toVoxel(const Eigen::Vector3f& p_world) const { return (p_world - origin_world) / voxel_size_m; }
    Eigen::Vector3f toWorld(const Eigen::Vector3f& p_vox) const { return origin_world + p_vox * voxel_size_m; }
    // Trilinear interpolation of D(x) (thesis section 4.2.2) in voxel coordinates; false where any of the 8
    // neighbours is unallocated or has zero weight.
    bool interpolate(const Eigen::Vector3f& p_vox, float& tsdf) const;
    // Same, with the running-average colour (BGR, 0..255) interpolated as well.
    bool interpolateColour(const Eigen::Vector3f& p_vox, Eigen::Vector3f& bgr) const;
    // Gradient of D by central differences of trilinear samples (thesis eq. 4.30); false where unavailable.
    bool gradient(const Eigen::Vector3f& p_vox, Eigen::Vector3f& grad) const;
    // Copies only the allocated blocks (and the index) into `dst`, reusing its capacity.
    void copyTo(VoxelBlockGrid& dst) const;
};
using TsdfSnapshot = VoxelBlockGrid;

struct IntegrateStats {
    int blocks_touched = 0;       // count; blocks integrated this frame
    int blocks_allocated = 0;     // count; of which new this frame
    bool pool_exhausted = false;  // some surface could not be stored (TsdfParams::max_blocks too small)
};

class TsdfVolume {
 public:
    explicit TsdfVolume(const TsdfParams& p);  // reserves the block pool and per-frame lists up front

    // Clears every voxel; the cube is placed again at the next place().
    void reset();
    // Places the cube around the head of the first frame: centred centre_behind_surface_m behind the centroid of
    // `first` (camera frame = world frame). False when the frame has no valid point.
    bool place(const SurfaceLevel& first);
    bool placed() const { return placed_; }

    // Algorithm 3 over the blocks that the frame's valid pixels touch within +-mu: allocates missing blocks, then
    // updates each of their voxels with eq. 4.22-4.26. `frame` is level 0 of the filtered pyramid (depth, normals,
    // roi, intrinsics); colour_bgr is CV_8UC3 of the same size or empty.
    IntegrateStats integrate(const SurfaceLevel& frame, const cv::Mat& colour_bgr, const Pose& T_world_camera);

    const VoxelBlockGrid& grid() const { return grid_; }
    const TsdfParams& params() const { return params_; }

    // Replication (recon_state.hpp). Every integrate() advances the generation and stamps the blocks it touched;
    // reset() starts over (a capture across a reset must be full: resetGeneration() tells when it happened).
    uint64_t generation() const { return generation_; }
    uint64_t resetGeneration() const { return reset_generation_; }
    // Appends the allocated blocks touched after `since_generation` (all of them for 0) to `out`.
    void copyBlocks(uint64_t since_generation, std::vector<Eigen::Vector3i>& coords, std::vector<Voxel>& voxels) const;
    // Writes blocks (allocating missing ones) and, for a full restore, places the cube at origin_world.
    // ResourceExhausted when the pool cannot hold them; InvalidArgument for coordinates outside the cube.
    Status applyBlocks(const std::vector<Eigen::Vector3i>& coords, const std::vector<Voxel>& voxels);
    void setPlacement(bool placed, const Eigen::Vector3f& origin_world);
    // After a restore: later captures count from here.
    void setGeneration(uint64_t generation) { generation_ = reset_generation_ = generation; }

 private:
    TsdfParams params_;
    VoxelBlockGrid grid_;
    bool placed_ = false;
    uint64_t generation_ = 0;                 // integrations so far (monotonic across resets)
    uint64_t reset_generation_ = 0;           // generation_ at the last reset
    std::vector<uint64_t> block_generation_;  // per pool slot: the generation that last touched it
    std::vector<uint8_t> block_flag_;         // per block: touched this frame
    std::vector<int32_t> touched_;            // pool indices of the blocks touched this frame
    cv::Mat pixel_range_m_;                   // CV_32F, metres: distance to the measured surface along each pixel's ray
    cv::Mat pixel_weight_;                    // CV_32F: Algorithm 3 weight of each pixel's measurement, 0 = unusable
};

}  // namespace facescan::recon
