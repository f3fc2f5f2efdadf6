// The Reconstructor's state as plain data (recon_state.hpp): what a standby server or a restarted one needs to
// continue a scan. Kept apart from the frame path in reconstructor.cpp.
#include "recon/reconstructor.hpp"

namespace facescan::recon {

void Reconstructor::captureState(uint64_t since_generation, size_t trajectory_from, ReconState& out) const {
    const TsdfParams& tp = params_.tsdf;
    // Everything is reset but the buffers' capacity: the server captures each live session once a second, and
    // copying megabytes of voxels into fresh pages cost the frame thread as much again in page faults.
    std::vector<Eigen::Vector3i> coords = std::move(out.blocks.coords);
    std::vector<Voxel> voxels = std::move(out.blocks.voxels);
    std::vector<std::pair<int64_t, Pose>> trajectory = std::move(out.trajectory);
    coords.clear();
    voxels.clear();
    trajectory.clear();
    out = ReconState{};
    out.blocks.coords = std::move(coords);
    out.blocks.voxels = std::move(voxels);
    out.trajectory = std::move(trajectory);
    out.resolution_vox = tp.resolution_vox;
    out.volume_size_m = tp.volume_size_m;
    out.trunc_dist_m = tp.trunc_dist_m;
    out.placed = volume_.placed();
    out.origin_world = volume_.grid().origin_world;
    // A delta across a reset (or from a trajectory longer than ours) would be meaningless: send everything.
    out.full = since_generation == 0 || since_generation < volume_.resetGeneration() ||
               since_generation > volume_.generation() || trajectory_from > trajectory_.size();
    out.generation = volume_.generation();
    out.since_generation = out.full ? 0 : since_generation;
    out.total_blocks = volume_.grid().allocated_blocks;
    {
        std::lock_guard<std::mutex> lock(volume_mutex_);  // cheap here: the frame thread is the only writer
        volume_.copyBlocks(out.since_generation, out.blocks.coords, out.blocks.voxels);
    }
    out.have_model = have_model_;
    out.frames_integrated = frames_integrated_;
    out.consecutive_failures = consecutive_failures_;
    out.T_world_camera = T_world_camera_;
    out.T_world_model = T_world_model_;
    out.model_roi = model_cast_roi_;
    out.region = region_;
    out.visible_ref_px = visible_ref_px_;
    out.verify_next = verify_next_;
    out.trajectory_begin = out.full ? 0 : trajectory_from;
    out.trajectory.assign(trajectory_.begin() + static_cast<ptrdiff_t>(out.trajectory_begin), trajectory_.end());
}

Status Reconstructor::restoreState(const ReconState& s) {
    RETURN_IF_ERROR(init_status_);
    if (!s.full) return invalidArgument("only a full state can be restored");
    RETURN_IF_ERROR(s.validate());
    const TsdfParams& tp = params_.tsdf;
    if (s.resolution_vox != tp.resolution_vox || s.volume_size_m != tp.volume_size_m ||
        s.trunc_dist_m != tp.trunc_dist_m) {
        return invalidArgument("the saved model was made with another volume (" + std::to_string(s.resolution_vox) +
                               " voxels over " + std::to_string(s.volume_size_m) + " m; this server uses " +
                               std::to_string(tp.resolution_vox) + " over " + std::to_string(tp.volume_size_m) +
                               " m): run every server with the same tsdf settings");
    }
    reset();
    {
        std::lock_guard<std::mutex> lock(volume_mutex_);
        RETURN_IF_ERROR(volume_.applyBlocks(s.blocks.coords, s.blocks.voxels));
        volume_.setPlacement(s.placed, s.origin_world);
        volume_.setGeneration(s.generation);
    }
    have_model_ = s.have_model;
    frames_integrated_ = s.frames_integrated;
    consecutive_failures_ = s.consecutive_failures;
    region_ = s.region;
    visible_ref_px_ = s.visible_ref_px;
    verify_next_ = s.verify_next;
    trajectory_.assign(s.trajectory.begin(), s.trajectory.end());
    if (have_model_) {
        // The model the next frame registers against: cast again from where it was cast last, over the same
        // pixels, without the depth hint of a frame this reconstructor never saw (rays march the cube instead).
        const cv::Rect roi = s.model_roi.area() > 0 ? s.model_roi : cv::Rect(0, 0, k_.width_px, k_.height_px);
        T_world_camera_ = s.T_world_model;
        raycastModel(roi, cv::Mat());
    }
    T_world_camera_ = s.T_world_camera;
    T_world_model_ = s.T_world_model;
    return Status::ok();
}

}  // namespace facescan::recon
