// The volumetric model (thesis section 4.2.1): a truncated signed distance function D(x) and weight W(x) on a cube
// of voxels (eq. 4.22-4.26, Algorithm 3), with a running-average colour per voxel. Storage is sparse: the cube is
// cut into 8^3-voxel blocks, and only blocks that a frame's head surface touches (within the truncation band) are
// allocated, from a pool reserved up front, and integrated. The whole 256^3 grid is never visited.
#pragma once

#include <Eigen/Core>
#include <algorithm>
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
    float weight_angle_sigma = 0.5f;    // dimensionless; in units of (1 - cos theta)
    float weight_depth_sigma_m = 1.5f;  // metres
    float min_cos_angle = 0.2f;         // cos; grazing measurements (> ~78 deg) are not integrated
    // A measurement next to a depth edge (one of the four pixel squares around it has no eq. 4.10 normal) gets this
    // share of its weight while the model has fused fewer than edge_weight_frames frames, and none after: the
    // mixed, noisy depths there thicken the model (the near-range camera's wide turn: 0.168 mm with them to the
    // end, 0.142 mm without), but a model of a few frames needs its rim to align the next frames after a gap.
    float edge_weight = 0.05f;              // dimensionless, in [0, 1]
    int edge_weight_frames = 8;             // fused frames (count)
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
    // The 8 corners of one trilinear cell, corner i at (x0 + (i & 1), y0 + ((i >> 1) & 1), z0 + (i >> 2)):
    // kUnallocated when the block holding (x0, y0, z0) is not allocated (empty space: ray casting skips ahead),
    // kUnobserved when another corner lies outside the cube, in an unallocated block or has zero weight.
    // Inline (below): the ray caster's inner loop calls them ~200k times a frame.
    enum class Cell { kOk, kUnobserved, kUnallocated };
    Cell fetchCell(int x0, int y0, int z0, float corners[8]) const;
    // D at p_vox from its trilinear cell; returns what fetchCell returned for that cell.
    Cell sample(const Eigen::Vector3f& p_vox, float& tsdf) const;
    // Same, with the running-average colour (BGR, 0..255) interpolated as well.
    bool interpolateColour(const Eigen::Vector3f& p_vox, Eigen::Vector3f& bgr) const;
    // Gradient of D by central differences of trilinear samples one voxel apart (thesis eq. 4.30); false where
    // any of those six samples' cells is unobserved. Inline (below) like sample(): the ray caster takes one per
    // pixel, marching cubes one per vertex.
    bool gradient(const Eigen::Vector3f& p_vox, Eigen::Vector3f& grad) const;
    // What gradient() reads: the trilinear cell of a point and the 24 voxels beyond its faces, reduced to the
    // cell's corners and the central differences at them. The ray caster interpolates D at its first estimate of
    // a crossing from it (what sample() gives there) and, when the refined crossing stays in the cell, the
    // gradient too: one gather instead of a cell and then the 32 voxels again.
    struct CrossCell {
        int x0 = 0, y0 = 0, z0 = 0;   // voxel coordinates; the cell's lower corner
        float corner[8];              // D at the cell's corners (corner i as in fetchCell)
        float corner_weight[8];       // W at the cell's corners (eq. 4.24's accumulated weight)
        float diff[3][8];             // D(c + e_a) - D(c - e_a) at each corner c, per axis a
        bool cell_observed = false;   // the 8 corners allocated and observed: sample() returns kOk in the cell
        bool cross_observed = false;  // all 32 allocated and observed: gradient() succeeds in the cell
        bool contains(const Eigen::Vector3f& p_vox) const {
            return static_cast<int>(p_vox.x()) == x0 && static_cast<int>(p_vox.y()) == y0 &&
                   static_cast<int>(p_vox.z()) == z0 && p_vox.x() >= 0.0f && p_vox.y() >= 0.0f && p_vox.z() >= 0.0f;
        }
        float tsdfAt(const Eigen::Vector3f& p_vox) const;                // = sample() at a point of the cell
        Eigen::Vector3f gradientAt(const Eigen::Vector3f& p_vox) const;  // = gradient() at a point of the cell
        float weightAt(const Eigen::Vector3f& p_vox) const;              // W, trilinear, at a point of the cell
        // A point's fractions within the cell, as sample() takes them.
        Eigen::Vector3f fractions(const Eigen::Vector3f& p_vox) const {
            return {p_vox.x() - static_cast<float>(x0), p_vox.y() - static_cast<float>(y0),
                    p_vox.z() - static_cast<float>(z0)};
        }
    };
    // False where p_vox lies outside [1, N - 3] on some axis (NaN included); gradient() is false there as well.
    bool gatherCross(const Eigen::Vector3f& p_vox, CrossCell& out) const;
    // Copies only the allocated blocks (and the index) into `dst`, reusing its capacity; `dst` gets room for as
    // many blocks as this grid has room for, so a model that grows does not move the copy's buffers.
    void copyTo(VoxelBlockGrid& dst) const;
};
using TsdfSnapshot = VoxelBlockGrid;

// Trilinear interpolation (thesis section 4.2.2) of the 8 corner values c (corner i at (i & 1, (i >> 1) & 1,
// i >> 2)) at fractions fx, fy, fz in [0, 1).
[[gnu::always_inline]] inline float trilinear(const float c[8], float fx, float fy, float fz) {
    const float c00 = c[0] + fx * (c[1] - c[0]), c10 = c[2] + fx * (c[3] - c[2]);
    const float c01 = c[4] + fx * (c[5] - c[4]), c11 = c[6] + fx * (c[7] - c[6]);
    const float c0 = c00 + fy * (c10 - c00), c1 = c01 + fy * (c11 - c01);
    return c0 + fz * (c1 - c0);
}

// A block of never-observed voxels (weight 0) that gradient() reads in place of an unallocated block, so that its
// gather needs no test per voxel: the zero weight alone rejects the gradient, as an unallocated block would.
inline constexpr Voxel kUnobservedBlock[kBlockVoxels]{};

[[gnu::always_inline]] inline VoxelBlockGrid::Cell VoxelBlockGrid::fetchCell(int x0, int y0, int z0, float c[8]) const {
    const unsigned n = static_cast<unsigned>(resolution_vox);
    if (static_cast<unsigned>(x0) >= n || static_cast<unsigned>(y0) >= n || static_cast<unsigned>(z0) >= n)
        return Cell::kUnallocated;
    const size_t bps = static_cast<size_t>(blocks_per_side);
    const int bx = x0 >> 3, by = y0 >> 3, bz = z0 >> 3;
    const int b = block_index[(bz * bps + by) * bps + bx];
    if (b < 0) return Cell::kUnallocated;
    const int lx = x0 & 7, ly = y0 & 7, lz = z0 & 7;
    if (lx < 7 && ly < 7 && lz < 7) {
        // All 8 corners lie in one block (343 of 512 cells): one index lookup instead of eight.
        const Voxel* p = &voxels[static_cast<size_t>(b) * kBlockVoxels + (lz * 64 + ly * 8 + lx)];
        const float w = std::min(std::min(std::min(p[0].weight, p[1].weight), std::min(p[8].weight, p[9].weight)),
                                 std::min(std::min(p[64].weight, p[65].weight), std::min(p[72].weight, p[73].weight)));
        if (!(w > 0.0f)) return Cell::kUnobserved;
        c[0] = p[0].tsdf, c[1] = p[1].tsdf, c[2] = p[8].tsdf, c[3] = p[9].tsdf;
        c[4] = p[64].tsdf, c[5] = p[65].tsdf, c[6] = p[72].tsdf, c[7] = p[73].tsdf;
        return Cell::kOk;
    }
    // The cell straddles 2, 4 or 8 blocks: the upper corner's side of each axis that crosses into the next block
    // (a 3-bit "crossing" code) names the block; each distinct block is looked up once. Within a block, a step to
    // the upper corner along an axis that crosses wraps to local coordinate 0.
    if (static_cast<unsigned>(x0 + 1) >= n || static_cast<unsigned>(y0 + 1) >= n || static_cast<unsigned>(z0 + 1) >= n)
        return Cell::kUnobserved;
    const int cross = (lx == 7 ? 1 : 0) | (ly == 7 ? 2 : 0) | (lz == 7 ? 4 : 0);
    const Voxel* block_of[8];
    block_of[0] = &voxels[static_cast<size_t>(b) * kBlockVoxels];
#pragma GCC unroll 8
    for (int k = 1; k < 8; ++k) {
        if ((k & cross) != k) continue;
        const int bk = block_index[((bz + (k >> 2)) * bps + by + ((k >> 1) & 1)) * bps + bx + (k & 1)];
        if (bk < 0) return Cell::kUnobserved;
        block_of[k] = &voxels[static_cast<size_t>(bk) * kBlockVoxels];
    }
    const int base = lz * 64 + ly * 8 + lx;
    const int step_x = lx == 7 ? -7 : 1, step_y = ly == 7 ? -56 : 8, step_z = lz == 7 ? -448 : 64;
    float w = 1.0f;
#pragma GCC unroll 8
    for (int i = 0; i < 8; ++i) {
        const Voxel& v = block_of[i & cross][base + (i & 1) * step_x + ((i >> 1) & 1) * step_y + (i >> 2) * step_z];
        w = std::min(w, v.weight);
        c[i] = v.tsdf;
    }
    return w > 0.0f ? Cell::kOk : Cell::kUnobserved;
}

[[gnu::always_inline]] inline VoxelBlockGrid::Cell VoxelBlockGrid::sample(const Eigen::Vector3f& p_vox,
                                                                          float& tsdf) const {
    // Truncation, not floor: a negative coordinate is outside the cube either way (rejected here), and this keeps
    // the hot loop free of a libm call on targets without SSE4.1.
    if (!(p_vox.x() >= 0.0f && p_vox.y() >= 0.0f && p_vox.z() >= 0.0f)) return Cell::kUnallocated;
    const int x0 = static_cast<int>(p_vox.x());
    const int y0 = static_cast<int>(p_vox.y());
    const int z0 = static_cast<int>(p_vox.z());
    float c[8];
    const Cell cell = fetchCell(x0, y0, z0, c);
    if (cell != Cell::kOk) return cell;
    const float fx = p_vox.x() - static_cast<float>(x0);
    const float fy = p_vox.y() - static_cast<float>(y0);
    const float fz = p_vox.z() - static_cast<float>(z0);
    tsdf = trilinear(c, fx, fy, fz);
    return Cell::kOk;
}

[[gnu::always_inline]] inline bool VoxelBlockGrid::gatherCross(const Eigen::Vector3f& p_vox, CrossCell& out) const {
    // Central differences of trilinear samples one voxel apart along each axis (eq. 4.30). The derivative of the
    // trilinear cell alone would cost one cell instead of six, but measured twice the angular error on a sphere
    // (4.3 against 2.1 degrees mean, p99 12.8 against 6.0) and, through ICP's point-to-plane terms, +0.002 mm mean
    // error and +10 % ATE on the synthetic head. So the same central differences, computed cheaper: the samples at
    // p -+ e_a lie in the cells at (x0, y0, z0) -+ e_a with the same fractions fx, fy, fz, so their difference is
    // the trilinear interpolation of the voxel-grid differences D(c + e_a) - D(c - e_a) at the 8 corners c of
    // p's cell. Those read 32 voxels (p's cell and the 24 beyond its faces: a cross) instead of the six cells'
    // 48, in at most 8 block lookups, and interpolate 3 times instead of 6. Valid exactly where all six cells
    // were: every one of the 32 voxels inside the cube, allocated and observed.
    if (!(p_vox.x() >= 1.0f && p_vox.y() >= 1.0f && p_vox.z() >= 1.0f)) return false;
    const int c0[3] = {static_cast<int>(p_vox.x()), static_cast<int>(p_vox.y()), static_cast<int>(p_vox.z())};
    if (c0[0] + 2 >= resolution_vox || c0[1] + 2 >= resolution_vox || c0[2] + 2 >= resolution_vox) return false;
    // Per axis, the 4 coordinates c0 - 1 .. c0 + 2 span at most two blocks: which of the two each lies in (bit)
    // and its offset inside the block (off, scaled by the axis' stride in the block).
    constexpr int kStride[3] = {1, kBlockSide, kBlockSide * kBlockSide};
    int bit[3][4], off[3][4], block_lo[3];
    int cross = 0;  // bit a set: axis a spans two blocks
#pragma GCC unroll 3
    for (int a = 0; a < 3; ++a) {
        block_lo[a] = (c0[a] - 1) >> 3;
#pragma GCC unroll 4
        for (int i = 0; i < 4; ++i) {
            bit[a][i] = ((c0[a] - 1 + i) >> 3) - block_lo[a];
            off[a][i] = ((c0[a] - 1 + i) & (kBlockSide - 1)) * kStride[a];
        }
        cross |= bit[a][3] << a;
    }
    const size_t bps = static_cast<size_t>(blocks_per_side);
    const Voxel* block_of[8];
#pragma GCC unroll 8
    for (int k = 0; k < 8; ++k) {
        if ((k & cross) != k) continue;
        const int b =
            block_index[((block_lo[2] + (k >> 2)) * bps + block_lo[1] + ((k >> 1) & 1)) * bps + block_lo[0] + (k & 1)];
        block_of[k] = b < 0 ? kUnobservedBlock : &voxels[static_cast<size_t>(b) * kBlockVoxels];
    }
    // The corners, the differences at them and the least weights of the cell and of all 32 voxels, given where
    // voxel (c0 - 1 + i, c0 - 1 + j, c0 - 1 + l), i, j, l in 0..3, lies.
    const auto gather = [&out](auto at) {
        float w_cell = 1.0f, w_cross = 1.0f;
#pragma GCC unroll 8
        for (int corner = 0; corner < 8; ++corner) {
            const int i = 1 + (corner & 1), j = 1 + ((corner >> 1) & 1), l = 1 + (corner >> 2);
            const Voxel& c = at(i, j, l);
            const Voxel &x_lo = at(i - 1, j, l), &x_hi = at(i + 1, j, l);
            const Voxel &y_lo = at(i, j - 1, l), &y_hi = at(i, j + 1, l);
            const Voxel &z_lo = at(i, j, l - 1), &z_hi = at(i, j, l + 1);
            w_cell = std::min(w_cell, c.weight);
            w_cross = std::min(
                w_cross, std::min(std::min(x_lo.weight, x_hi.weight),
                                  std::min(std::min(y_lo.weight, y_hi.weight), std::min(z_lo.weight, z_hi.weight))));
            out.corner[corner] = c.tsdf;
            out.corner_weight[corner] = c.weight;
            out.diff[0][corner] = x_hi.tsdf - x_lo.tsdf;
            out.diff[1][corner] = y_hi.tsdf - y_lo.tsdf;
            out.diff[2][corner] = z_hi.tsdf - z_lo.tsdf;
        }
        out.cell_observed = w_cell > 0.0f;
        out.cross_observed = std::min(w_cell, w_cross) > 0.0f;
    };
    if (cross == 0) {
        // All 32 in one block (a quarter of the calls): constant offsets from one pointer.
        const Voxel* p = block_of[0] + off[0][0] + off[1][0] + off[2][0];
        gather([p](int i, int j, int l) -> const Voxel& { return p[i + kBlockSide * (j + kBlockSide * l)]; });
    } else {
        gather([&](int i, int j, int l) -> const Voxel& {
            return block_of[bit[0][i] | (bit[1][j] << 1) | (bit[2][l] << 2)][off[0][i] + off[1][j] + off[2][l]];
        });
    }
    out.x0 = c0[0], out.y0 = c0[1], out.z0 = c0[2];
    return true;
}

[[gnu::always_inline]] inline float VoxelBlockGrid::CrossCell::tsdfAt(const Eigen::Vector3f& p_vox) const {
    const Eigen::Vector3f f = fractions(p_vox);
    return trilinear(corner, f.x(), f.y(), f.z());
}

[[gnu::always_inline]] inline Eigen::Vector3f VoxelBlockGrid::CrossCell::gradientAt(
    const Eigen::Vector3f& p_vox) const {
    const Eigen::Vector3f f = fractions(p_vox);
    return Eigen::Vector3f(trilinear(diff[0], f.x(), f.y(), f.z()), trilinear(diff[1], f.x(), f.y(), f.z()),
                           trilinear(diff[2], f.x(), f.y(), f.z()));
}

[[gnu::always_inline]] inline float VoxelBlockGrid::CrossCell::weightAt(const Eigen::Vector3f& p_vox) const {
    const Eigen::Vector3f f = fractions(p_vox);
    return trilinear(corner_weight, f.x(), f.y(), f.z());
}

inline bool VoxelBlockGrid::gradient(const Eigen::Vector3f& p_vox, Eigen::Vector3f& grad) const {
    CrossCell x;
    if (!gatherCross(p_vox, x) || !x.cross_observed) return false;
    grad = x.gradientAt(p_vox);
    return true;
}

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
    // frames_fused: how many frames the model holds already (TsdfParams::edge_weight_frames).
    IntegrateStats integrate(const SurfaceLevel& frame, const cv::Mat& colour_bgr, const Pose& T_world_camera,
                             int frames_fused = 0);

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
    cv::Mat block_candidates_;    // CV_32SC3 per 2x2 pixels: the blocks at -mu, 0, +mu along its ray (-1: none)
    cv::Mat pixel_range_weight_;  // CV_32FC2 per pixel: distance (metres) to the measured surface along its ray,
                                  // and the Algorithm 3 weight of its measurement (0 = unusable)
    cv::Mat colour_copy_;         // a non-continuous colour image, made continuous (never for a camera's own)
};

}  // namespace facescan::recon
