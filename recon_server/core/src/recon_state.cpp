#include "recon/recon_state.hpp"

#include <cmath>
#include <unordered_map>

namespace facescan::recon {
namespace {

constexpr int kMaxResolutionVox = 1024;  // TsdfParams::validate's limit

bool finitePose(const Pose& T) { return T.matrix().allFinite(); }

// Block coordinates as one integer key (blocks_per_side <= 128 at the largest resolution).
int64_t blockKey(const Eigen::Vector3i& c) {
    return (static_cast<int64_t>(c.z()) << 40) | (int64_t{c.y()} << 20) | c.x();
}

}  // namespace

Status ReconState::validate() const {
    if (resolution_vox < kBlockSide || resolution_vox % kBlockSide != 0 || resolution_vox > kMaxResolutionVox) {
        return invalidArgument("state: volume resolution " + std::to_string(resolution_vox) + " is not valid");
    }
    if (!(volume_size_m > 0 && volume_size_m < 100) || !(trunc_dist_m > 0 && trunc_dist_m < volume_size_m)) {
        return invalidArgument("state: volume size or truncation distance is not valid");
    }
    if (!origin_world.allFinite()) return invalidArgument("state: volume origin is not finite");
    if (!finitePose(T_world_camera) || !finitePose(T_world_model)) return invalidArgument("state: pose not finite");
    if (!region.centre_world.allFinite() || !region.down_world.allFinite() || !std::isfinite(region.radius_m) ||
        !std::isfinite(region.below_centre_m) || !std::isfinite(region.centre_behind_m) ||
        !(visible_ref_px >= 0 && visible_ref_px < 1e8f)) {
        return invalidArgument("state: head region or visibility not finite");
    }
    if (frames_integrated < 0 || consecutive_failures < 0 || total_blocks < 0) {
        return invalidArgument("state: negative counter");
    }
    if (blocks.voxels.size() != blocks.coords.size() * kBlockVoxels) {
        return invalidArgument("state: " + std::to_string(blocks.voxels.size()) + " voxels for " +
                               std::to_string(blocks.coords.size()) + " blocks");
    }
    if (full && static_cast<size_t>(total_blocks) != blocks.count()) {
        return invalidArgument("state: a full state with " + std::to_string(blocks.count()) + " of " +
                               std::to_string(total_blocks) + " blocks");
    }
    if (full && (trajectory_begin != 0 || since_generation != 0))
        return invalidArgument("state: full state with a base");
    // A delta's trajectory_begin is not bounded by frames_integrated: the trajectory holds every tracked frame,
    // fused or not (ReconParams::fuse_every). mergeState checks that it joins its base.
    if (!full && since_generation > generation) return invalidArgument("state: delta bounds are not consistent");
    const int bps = resolution_vox / kBlockSide;
    std::vector<uint8_t> seen(static_cast<size_t>(bps) * bps * bps, 0);
    for (const Eigen::Vector3i& c : blocks.coords) {
        if (c.minCoeff() < 0 || c.maxCoeff() >= bps) return invalidArgument("state: block outside the cube");
        uint8_t& s = seen[(static_cast<size_t>(c.z()) * bps + c.y()) * bps + c.x()];
        if (s) return invalidArgument("state: a block appears twice");
        s = 1;
    }
    for (const Voxel& v : blocks.voxels) {
        if (!(v.tsdf >= -1.0f && v.tsdf <= 1.0f) || !(v.weight >= 0.0f && v.weight < 1e6f)) {
            return invalidArgument("state: a voxel holds an impossible value");
        }
    }
    for (const auto& [t_ns, T] : trajectory) {
        if (!finitePose(T)) return invalidArgument("state: a trajectory pose is not finite");
    }
    return Status::ok();
}

Status mergeState(ReconState& base, const ReconState& delta) {
    if (delta.full) {
        RETURN_IF_ERROR(delta.validate());
        base = delta;
        return Status::ok();
    }
    if (!base.full) return invalidArgument("merge: the base is not a full state");
    if (delta.resolution_vox != base.resolution_vox || delta.volume_size_m != base.volume_size_m ||
        delta.trunc_dist_m != base.trunc_dist_m) {
        return invalidArgument("merge: the delta belongs to another volume");
    }
    if (delta.since_generation != base.generation) {
        return invalidArgument("merge: the delta continues generation " + std::to_string(delta.since_generation) +
                               ", the base is at " + std::to_string(base.generation));
    }
    if (delta.trajectory_begin != base.trajectorySize()) {
        return invalidArgument("merge: the trajectory does not join (" + std::to_string(delta.trajectory_begin) +
                               " after " + std::to_string(base.trajectorySize()) + " entries)");
    }
    RETURN_IF_ERROR(delta.validate());
    std::unordered_map<int64_t, size_t> index;
    index.reserve(base.blocks.count() + delta.blocks.count());
    for (size_t i = 0; i < base.blocks.count(); ++i) index.emplace(blockKey(base.blocks.coords[i]), i);
    size_t added = 0;
    for (const Eigen::Vector3i& c : delta.blocks.coords) added += index.count(blockKey(c)) ? 0 : 1;
    if (base.blocks.count() + added != static_cast<size_t>(delta.total_blocks)) {
        return invalidArgument("merge: the delta leaves " + std::to_string(base.blocks.count() + added) +
                               " blocks, the owner has " + std::to_string(delta.total_blocks));
    }
    for (size_t i = 0; i < delta.blocks.count(); ++i) {
        const auto src = delta.blocks.voxels.begin() + static_cast<ptrdiff_t>(i) * kBlockVoxels;
        const auto [it, inserted] = index.emplace(blockKey(delta.blocks.coords[i]), base.blocks.count());
        if (inserted) {
            base.blocks.coords.push_back(delta.blocks.coords[i]);
            base.blocks.voxels.insert(base.blocks.voxels.end(), src, src + kBlockVoxels);
        } else {
            std::copy_n(src, kBlockVoxels,
                        base.blocks.voxels.begin() + static_cast<ptrdiff_t>(it->second) * kBlockVoxels);
        }
    }
    base.placed = delta.placed;
    base.origin_world = delta.origin_world;
    base.generation = delta.generation;
    base.total_blocks = delta.total_blocks;
    base.have_model = delta.have_model;
    base.frames_integrated = delta.frames_integrated;
    base.consecutive_failures = delta.consecutive_failures;
    base.T_world_camera = delta.T_world_camera;
    base.T_world_model = delta.T_world_model;
    base.model_roi = delta.model_roi;
    base.region = delta.region;
    base.visible_ref_px = delta.visible_ref_px;
    base.verify_next = delta.verify_next;
    base.trajectory.insert(base.trajectory.end(), delta.trajectory.begin(), delta.trajectory.end());
    return Status::ok();
}

}  // namespace facescan::recon
