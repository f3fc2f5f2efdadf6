#include "recon/tsdf_volume.hpp"

#include <algorithm>
#include <cmath>

#include "recon/parallel.hpp"

namespace facescan::recon {

namespace {

// What the voxel loop of Algorithm 3 reads, as plain locals (see integrate()).
struct VoxelUpdate {
    float step_x[3], step_y[3], step_z[3];  // metres; one voxel along the grid's x, y, z, in the camera frame
    float fx, fy, cx, cy;                   // pixels; intrinsics (eq. 4.8)
    int u0, v0, u1, v1;                     // pixels; the frame's ROI, half-open
    float mu, inv_mu, max_w;                // metres, 1/metres, weight
    int width;                              // pixels per row of the frame (and of the maps below, continuous)
    const float* rw;                        // per pixel: range along the ray (metres), weight; 2 floats
    const uint8_t* colour;                  // BGR per pixel, or nullptr
};

// Eq. 4.22-4.26 for the 8^3 voxels of one block whose first voxel is at `corner_cam` (camera frame), one row of 8
// voxels along x at a time. The projection and the distance to the camera of a row's 8 voxels are computed first,
// branch-free, so the compiler does them 4 at a time (divps, sqrtps: the divider was the loop's bottleneck, 4 scalar
// divisions and square roots a voxel); then each voxel that projects onto a usable pixel is updated.
inline void integrateBlock(const VoxelUpdate& c, const Eigen::Vector3f& corner_cam, Voxel* block) {
    const VoxelUpdate up = c;  // locals: no reloads after the stores below
    float px[kBlockSide], py[kBlockSide], pz[kBlockSide], dist[kBlockSide];
    int pixel[kBlockSide];
    for (int iz = 0; iz < kBlockSide; ++iz) {
        for (int iy = 0; iy < kBlockSide; ++iy) {
            const float fz = static_cast<float>(iz), fy = static_cast<float>(iy);
            px[0] = corner_cam.x() + up.step_z[0] * fz + up.step_y[0] * fy;
            py[0] = corner_cam.y() + up.step_z[1] * fz + up.step_y[1] * fy;
            pz[0] = corner_cam.z() + up.step_z[2] * fz + up.step_y[2] * fy;
            for (int ix = 1; ix < kBlockSide; ++ix) {
                px[ix] = px[ix - 1] + up.step_x[0];
                py[ix] = py[ix - 1] + up.step_x[1];
                pz[ix] = pz[ix - 1] + up.step_x[2];
            }
            // Eq. 4.25-4.26: each voxel in the camera, projected to its nearest pixel (row-major index into the
            // frame, -1 outside the ROI or behind the camera), and its distance to the camera centre.
            for (int ix = 0; ix < kBlockSide; ++ix) {
                const float inv_z = 1.0f / pz[ix];
                const float fu = px[ix] * up.fx * inv_z + up.cx + 0.5f, fv = py[ix] * up.fy * inv_z + up.cy + 0.5f;
                // Clamped before the conversion (NaN to -1): far off the image or behind the camera stays outside.
                const int u = static_cast<int>(std::min(std::max(-1.0f, fu), 65536.0f));
                const int v = static_cast<int>(std::min(std::max(-1.0f, fv), 65536.0f));
                // Bitwise, not &&: no branch, so the loop vectorises.
                const bool inside = (pz[ix] > 0.0f) & (u >= up.u0) & (v >= up.v0) & (u < up.u1) & (v < up.v1);
                pixel[ix] = inside ? v * up.width + u : -1;
                dist[ix] = std::sqrt(px[ix] * px[ix] + py[ix] * py[ix] + pz[ix] * pz[ix]);
            }
            Voxel* vrow = block + iz * 64 + iy * 8;
            for (int ix = 0; ix < kBlockSide; ++ix) {
                if (pixel[ix] < 0) continue;
                const float* pix = up.rw + 2 * static_cast<size_t>(pixel[ix]);
                const float w = pix[1];
                if (!(w > 0.0f)) continue;
                // Eq. 4.24: distance to the surface along the ray minus the distance to the voxel.
                const float d = pix[0] - dist[ix];
                if (d < -up.mu) continue;                         // far behind the surface: zero weight (Algorithm 3)
                const float sdf = std::min(1.0f, d * up.inv_mu);  // truncated, in units of mu
                Voxel& vx = vrow[ix];
                const float w_sum = vx.weight + w;
                // Eq. 4.22 as a step towards the measurement, (W D + w sdf) / (W + w) = D + a (sdf - D) with
                // a = w / (W + w): one division for the distance and the colour.
                const float a = w / w_sum;
                vx.tsdf += a * (sdf - vx.tsdf);
                if (up.colour != nullptr && sdf < 1.0f) {
                    const uint8_t* col = up.colour + 3 * static_cast<size_t>(pixel[ix]);
                    vx.b = static_cast<uint8_t>(vx.b + a * (static_cast<float>(col[0]) - vx.b) + 0.5f);
                    vx.g = static_cast<uint8_t>(vx.g + a * (static_cast<float>(col[1]) - vx.g) + 0.5f);
                    vx.r = static_cast<uint8_t>(vx.r + a * (static_cast<float>(col[2]) - vx.r) + 0.5f);
                }
                vx.weight = std::min(w_sum, up.max_w);  // eq. 4.23, saturated
            }
        }
    }
}

}  // namespace

Status TsdfParams::validate() const {
    if (resolution_vox < kBlockSide || resolution_vox % kBlockSide != 0 || resolution_vox > 1024)
        return invalidArgument("tsdf resolution_vox must be a multiple of 8 in [8, 1024]");
    if (!(volume_size_m > 0.0f)) return invalidArgument("tsdf volume_size_m must be > 0");
    if (!(trunc_dist_m > voxelSizeM())) return invalidArgument("tsdf trunc_dist_m must exceed one voxel");
    if (!(max_weight >= 1.0f)) return invalidArgument("tsdf max_weight must be >= 1");
    if (!(weight_angle_sigma > 0.0f) || !(weight_depth_sigma_m > 0.0f))
        return invalidArgument("tsdf weight sigmas must be > 0");
    if (!(min_cos_angle >= 0.0f && min_cos_angle < 1.0f)) return invalidArgument("tsdf min_cos_angle in [0, 1)");
    if (!(edge_weight >= 0.0f && edge_weight <= 1.0f)) return invalidArgument("tsdf edge_weight in [0, 1]");
    if (edge_weight_frames < 0) return invalidArgument("tsdf edge_weight_frames must be >= 0");
    if (max_blocks < 1) return invalidArgument("tsdf max_blocks must be >= 1");
    if (!std::isfinite(centre_behind_surface_m)) return invalidArgument("tsdf centre_behind_surface_m not finite");
    return Status::ok();
}

bool VoxelBlockGrid::interpolate(const Eigen::Vector3f& p_vox, float& tsdf) const {
    return sample(p_vox, tsdf) == Cell::kOk;
}

bool VoxelBlockGrid::interpolateColour(const Eigen::Vector3f& p_vox, Eigen::Vector3f& bgr) const {
    const int x0 = static_cast<int>(std::floor(p_vox.x()));
    const int y0 = static_cast<int>(std::floor(p_vox.y()));
    const int z0 = static_cast<int>(std::floor(p_vox.z()));
    const float f[3] = {p_vox.x() - static_cast<float>(x0), p_vox.y() - static_cast<float>(y0),
                        p_vox.z() - static_cast<float>(z0)};
    Eigen::Vector3f sum = Eigen::Vector3f::Zero();
    float sum_w = 0.0f;
    for (int i = 0; i < 8; ++i) {
        const int dx = i & 1, dy = (i >> 1) & 1, dz = i >> 2;
        const Voxel* vx = voxel(x0 + dx, y0 + dy, z0 + dz);
        if (vx == nullptr || vx->weight <= 0.0f) continue;
        const float w = (dx ? f[0] : 1.0f - f[0]) * (dy ? f[1] : 1.0f - f[1]) * (dz ? f[2] : 1.0f - f[2]);
        sum += w * Eigen::Vector3f(vx->b, vx->g, vx->r);
        sum_w += w;
    }
    if (!(sum_w > 0.0f)) return false;
    bgr = sum / sum_w;
    return true;
}

void VoxelBlockGrid::copyTo(VoxelBlockGrid& dst) const {
    dst.resolution_vox = resolution_vox;
    dst.blocks_per_side = blocks_per_side;
    dst.voxel_size_m = voxel_size_m;
    dst.trunc_dist_m = trunc_dist_m;
    dst.origin_world = origin_world;
    dst.block_index.assign(block_index.begin(), block_index.end());
    // Room for as many blocks as the source has (address space: pages are only touched as blocks are written).
    // Copied with exactly the room it needed, a model that grows between two copies reallocated the whole copy,
    // and the kernel zeroed every page of it again: 1.6 % of a 4-session server's CPU, on the frame thread.
    if (dst.block_coords.capacity() < block_coords.capacity()) dst.block_coords.reserve(block_coords.capacity());
    if (dst.voxels.capacity() < voxels.capacity()) dst.voxels.reserve(voxels.capacity());
    dst.block_coords.assign(block_coords.begin(), block_coords.begin() + allocated_blocks);
    dst.voxels.assign(voxels.begin(), voxels.begin() + static_cast<ptrdiff_t>(allocated_blocks) * kBlockVoxels);
    dst.allocated_blocks = allocated_blocks;
}

TsdfVolume::TsdfVolume(const TsdfParams& p) : params_(p) {
    grid_.resolution_vox = p.resolution_vox;
    grid_.blocks_per_side = p.resolution_vox / kBlockSide;
    grid_.voxel_size_m = p.voxelSizeM();
    grid_.trunc_dist_m = p.trunc_dist_m;
    const size_t block_count =
        static_cast<size_t>(grid_.blocks_per_side) * grid_.blocks_per_side * grid_.blocks_per_side;
    grid_.block_index.assign(block_count, -1);
    // Reserved, not resized: pages are only touched as blocks come into use, and nothing reallocates later.
    grid_.block_coords.reserve(static_cast<size_t>(p.max_blocks));
    grid_.voxels.reserve(static_cast<size_t>(p.max_blocks) * kBlockVoxels);
    block_flag_.assign(block_count, 0);
    touched_.reserve(static_cast<size_t>(p.max_blocks));
    block_generation_.reserve(static_cast<size_t>(p.max_blocks));
}

void TsdfVolume::reset() {
    std::fill(grid_.block_index.begin(), grid_.block_index.end(), -1);
    grid_.block_coords.clear();
    grid_.voxels.clear();
    grid_.allocated_blocks = 0;
    block_generation_.clear();
    placed_ = false;
    reset_generation_ = ++generation_;
}

bool TsdfVolume::place(const SurfaceLevel& first) {
    Eigen::Vector3f centroid;
    if (validCentroid(first, centroid) == 0) return false;
    const Eigen::Vector3f centre = centroid + centroid.normalized() * params_.centre_behind_surface_m;
    // Voxel centres sit at origin + i * voxel_size, i = 0..N-1, symmetric about the centre.
    grid_.origin_world = centre - Eigen::Vector3f::Constant(0.5f * (params_.volume_size_m - grid_.voxel_size_m));
    placed_ = true;
    return true;
}

IntegrateStats TsdfVolume::integrate(const SurfaceLevel& frame, const cv::Mat& colour_bgr, const Pose& T_world_camera,
                                     int frames_fused) {
    IntegrateStats stats;
    const cv::Rect roi = frame.roi;
    if (roi.empty() || !placed_) return stats;
    const Intrinsics& k = frame.k;
    const float mu = params_.trunc_dist_m;
    const float inv_block_m = 1.0f / (grid_.voxel_size_m * kBlockSide);
    const int bps = grid_.blocks_per_side;

    // 1. Blocks within +-mu of the observed surface along each pixel's ray (every 2nd pixel: blocks are 12 mm,
    //    pixels ~1.2 mm apart at 0.7 m). Where they lie is found in parallel (the transforms were a tenth of the
    //    frame's serial CPU); the allocation is serial and in the same order on any core count, a few thousand
    //    lookups, most of them skipped because a neighbour named the same block.
    touched_.clear();
    const Eigen::Vector3f half_voxel = Eigen::Vector3f::Constant(0.5f * grid_.voxel_size_m);
    block_candidates_.create((frame.depth_m.rows + 1) / 2, (frame.depth_m.cols + 1) / 2, CV_32SC3);  // once
    // Candidate (r, c) is pixel (roi.x + 2 c, roi.y + 2 r).
    const int rows = (roi.height + 1) / 2, cols = (roi.width + 1) / 2;
    parallelFor(0, rows, [&](int r_lo, int r_hi) {
        for (int r = r_lo; r < r_hi; ++r) {
            const int v = roi.y + 2 * r;
            const float* z = frame.depth_m.ptr<float>(v);
            auto* out = block_candidates_.ptr<cv::Vec3i>(r);
            for (int c = 0; c < cols; ++c) {
                const int u = roi.x + 2 * c;
                out[c] = cv::Vec3i(-1, -1, -1);
                if (!(z[u] > 0.0f)) continue;
                const Eigen::Vector3f ray = k.ray(static_cast<float>(u), static_cast<float>(v));
                const float step = mu / ray.norm();  // depth change that moves mu along the ray
                for (int s = -1; s <= 1; ++s) {
                    const Eigen::Vector3f p_world = T_world_camera * (ray * (z[u] + static_cast<float>(s) * step));
                    const Eigen::Vector3f b = (p_world - grid_.origin_world + half_voxel) * inv_block_m;
                    const int bx = static_cast<int>(std::floor(b.x())), by = static_cast<int>(std::floor(b.y())),
                              bz = static_cast<int>(std::floor(b.z()));
                    if (bx < 0 || by < 0 || bz < 0 || bx >= bps || by >= bps || bz >= bps) continue;
                    out[c][s + 1] = static_cast<int>((static_cast<size_t>(bz) * bps + by) * bps + bx);
                }
            }
        }
    });
    for (int r = 0; r < rows; ++r) {
        const auto* cand = block_candidates_.ptr<cv::Vec3i>(r);
        for (int c = 0; c < cols; ++c) {
            for (int s = 0; s < 3; ++s) {
                const int bi = cand[c][s];
                if (bi < 0 || block_flag_[static_cast<size_t>(bi)]) continue;
                int32_t& slot = grid_.block_index[static_cast<size_t>(bi)];
                if (slot < 0) {
                    if (grid_.allocated_blocks >= params_.max_blocks) {
                        stats.pool_exhausted = true;
                        continue;
                    }
                    slot = grid_.allocated_blocks++;
                    const int bx = bi % bps, by = (bi / bps) % bps, bz = bi / (bps * bps);
                    grid_.block_coords.emplace_back(bx, by, bz);
                    grid_.voxels.resize(grid_.voxels.size() + kBlockVoxels);  // within the reserved capacity
                    block_generation_.push_back(0);
                    ++stats.blocks_allocated;
                }
                block_flag_[static_cast<size_t>(bi)] = 1;
                touched_.push_back(slot);
            }
        }
    }
    stats.blocks_touched = static_cast<int>(touched_.size());
    ++generation_;
    for (const int32_t slot : touched_) block_generation_[static_cast<size_t>(slot)] = generation_;

    // 2. Per pixel, once: the distance to the surface along the ray (z |K^-1 [u v 1]|, eq. 4.24) and the
    //    measurement's weight (Algorithm 3), 0 where there is no usable measurement (no depth, no normal around
    //    it, grazing).
    //    The voxel loop below then reads one interleaved pair per voxel (one cache line) instead of computing a
    //    norm and an exp each time.
    const float inv_angle_sigma = 1.0f / params_.weight_angle_sigma;
    const float inv_two_depth_var = 1.0f / (2.0f * params_.weight_depth_sigma_m * params_.weight_depth_sigma_m);
    const float min_cos = params_.min_cos_angle;
    const float edge_weight = frames_fused < params_.edge_weight_frames ? params_.edge_weight : 0.0f;
    pixel_range_weight_.create(frame.depth_m.size(), CV_32FC2);  // allocates on the first frame only
    parallelFor(roi.y, roi.y + roi.height, [&](int v_lo, int v_hi) {
        for (int v = v_lo; v < v_hi; ++v) {
            const float* z = frame.depth_m.ptr<float>(v);
            const auto* nrm = frame.normal.ptr<cv::Vec3f>(v);
            auto* rw = pixel_range_weight_.ptr<cv::Vec2f>(v);
            for (int u = roi.x; u < roi.x + roi.width; ++u) rw[u] = cv::Vec2f(0.0f, 0.0f);
            if (v == roi.y) continue;  // no pixel square above (see below)
            const auto* nrm_up = frame.normal.ptr<cv::Vec3f>(v - 1);
            for (int u = roi.x + 1; u < roi.x + roi.width; ++u) {
                // The normal of the angle term: the mean of eq. 4.10's normals of the four pixel squares that share
                // this pixel (its own, left, above, upper left), and no weight where one of them is missing (the
                // pixel is next to a depth edge). Eq. 4.10 alone spans the right and lower neighbours: its normal
                // lies half a pixel right of and below the measurement and is missing on one side of an edge only,
                // so the noisy, mixed depths along edges kept their full weight on the other side, and which side
                // that was turned with the camera: held upside down, the model came out 0.2 mm thicker.
                const cv::Vec3f &n00 = nrm[u], &n10 = nrm[u - 1], &n01 = nrm_up[u], &n11 = nrm_up[u - 1];
                if (!(z[u] > 0.0f) || std::isnan(n00[0])) continue;
                const bool edge = std::isnan(n10[0]) || std::isnan(n01[0]) || std::isnan(n11[0]);
                const cv::Vec3f n_sum = edge ? n00 : n00 + n10 + n01 + n11;  // all face the camera: no cancelling
                const Eigen::Vector3f ray = k.ray(static_cast<float>(u), static_cast<float>(v));
                const float ray_len = ray.norm();
                // Viewing angle between the normal and the ray towards the camera.
                const float cos_angle = -(n_sum[0] * ray.x() + n_sum[1] * ray.y() + n_sum[2] * ray.z()) /
                                        (ray_len * std::sqrt(n_sum.dot(n_sum)));
                if (cos_angle < min_cos) continue;
                rw[u] = cv::Vec2f(z[u] * ray_len,
                                  (edge ? edge_weight : 1.0f) * std::exp(-(1.0f - cos_angle) * inv_angle_sigma -
                                                                         z[u] * z[u] * inv_two_depth_var));
            }
        }
    });

    // 3. Algorithm 3 over the voxels of those blocks. Everything the voxel loop reads is copied into locals first:
    //    the voxel stores are floats, so through references the compiler had to reload the steps, the intrinsics
    //    and the map pointers after each one (a third of the loop's time).
    VoxelUpdate up;
    const Pose T_camera_world = T_world_camera.inverse();
    const Eigen::Matrix3f r_cw = T_camera_world.linear();
    const float vs = grid_.voxel_size_m;
    const Eigen::Vector3f step_x = r_cw.col(0) * vs, step_y = r_cw.col(1) * vs, step_z = r_cw.col(2) * vs;
    for (int a = 0; a < 3; ++a) up.step_x[a] = step_x[a], up.step_y[a] = step_y[a], up.step_z[a] = step_z[a];
    up.fx = k.fx_px, up.fy = k.fy_px, up.cx = k.cx_px, up.cy = k.cy_px;
    up.u0 = roi.x, up.v0 = roi.y, up.u1 = roi.x + roi.width, up.v1 = roi.y + roi.height;
    up.mu = mu;
    up.inv_mu = 1.0f / mu;
    up.max_w = params_.max_weight;
    up.width = frame.depth_m.cols;
    up.rw = pixel_range_weight_.ptr<float>(0);
    // A colour image that is a view into a larger one (not continuous) is copied once; the camera's own never is.
    const cv::Mat& colour = colour_bgr.empty() || colour_bgr.isContinuous() ? colour_bgr : colour_copy_;
    if (!colour_bgr.empty() && !colour_bgr.isContinuous()) colour_bgr.copyTo(colour_copy_);
    up.colour = colour.empty() ? nullptr : colour.ptr<uint8_t>(0);
    parallelFor(0, static_cast<int>(touched_.size()), [&](int t_lo, int t_hi) {
        for (int t = t_lo; t < t_hi; ++t) {
            const int slot = touched_[t];
            const Eigen::Vector3i& bc = grid_.block_coords[slot];
            const Eigen::Vector3f corner_cam = T_camera_world * grid_.toWorld((bc * kBlockSide).cast<float>());
            integrateBlock(up, corner_cam, &grid_.voxels[static_cast<size_t>(slot) * kBlockVoxels]);
        }
    });
    for (int32_t slot : touched_) {
        const Eigen::Vector3i& bc = grid_.block_coords[slot];
        block_flag_[(static_cast<size_t>(bc.z()) * bps + bc.y()) * bps + bc.x()] = 0;
    }
    return stats;
}

void TsdfVolume::copyBlocks(uint64_t since_generation, std::vector<Eigen::Vector3i>& coords,
                            std::vector<Voxel>& voxels) const {
    for (int slot = 0; slot < grid_.allocated_blocks; ++slot) {
        if (since_generation != 0 && block_generation_[static_cast<size_t>(slot)] <= since_generation) continue;
        coords.push_back(grid_.block_coords[static_cast<size_t>(slot)]);
        const auto first = grid_.voxels.begin() + static_cast<ptrdiff_t>(slot) * kBlockVoxels;
        voxels.insert(voxels.end(), first, first + kBlockVoxels);
    }
}

Status TsdfVolume::applyBlocks(const std::vector<Eigen::Vector3i>& coords, const std::vector<Voxel>& voxels) {
    if (voxels.size() != coords.size() * kBlockVoxels) return invalidArgument("block voxels do not match the blocks");
    const int bps = grid_.blocks_per_side;
    for (size_t i = 0; i < coords.size(); ++i) {
        const Eigen::Vector3i& c = coords[i];
        if (c.minCoeff() < 0 || c.maxCoeff() >= bps) return invalidArgument("block coordinates outside the cube");
        int32_t& slot = grid_.block_index[(static_cast<size_t>(c.z()) * bps + c.y()) * bps + c.x()];
        if (slot < 0) {
            if (grid_.allocated_blocks >= params_.max_blocks) {
                return resourceExhausted("the block pool (tsdf.max_blocks " + std::to_string(params_.max_blocks) +
                                         ") cannot hold the restored model");
            }
            slot = grid_.allocated_blocks++;
            grid_.block_coords.push_back(c);
            grid_.voxels.resize(grid_.voxels.size() + kBlockVoxels);
            block_generation_.push_back(0);
        }
        std::copy_n(voxels.begin() + static_cast<ptrdiff_t>(i) * kBlockVoxels, kBlockVoxels,
                    grid_.voxels.begin() + static_cast<ptrdiff_t>(slot) * kBlockVoxels);
        block_generation_[static_cast<size_t>(slot)] = generation_;
    }
    return Status::ok();
}

void TsdfVolume::setPlacement(bool placed, const Eigen::Vector3f& origin_world) {
    placed_ = placed;
    grid_.origin_world = origin_world;
}

}  // namespace facescan::recon
