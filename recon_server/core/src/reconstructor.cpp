#include "recon/reconstructor.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>

#include "recon/timing.hpp"

namespace facescan::recon {
namespace {

constexpr size_t kTrajectoryReserve = 18000;  // 10 minutes at 30 frames/s before the vector ever grows

}  // namespace

ReconParams ReconParams::faceDefaults() { return ReconParams{}; }

ReconParams ReconParams::fast() {
    ReconParams p;
    // Fewer iterations and a looser convergence test: frame-to-model tracking at 30 Hz starts close to the answer.
    p.icp.iterations = {6, 5, 4, 4};
    p.icp.convergence_rel = 1e-3f;
    p.icp.convergence_step_m = 5e-5f;
    p.raycast.step_trunc_fraction = 1.0f;
    p.raycast.start_before_hint_m = 0.012f;
    p.raycast.search_after_hint_m = 0.02f;
    return p;
}

Status ReconParams::validate() const {
    RETURN_IF_ERROR(filter.validate());
    RETURN_IF_ERROR(icp.validate());
    RETURN_IF_ERROR(tsdf.validate());
    RETURN_IF_ERROR(raycast.validate());
    RETURN_IF_ERROR(mesh.validate());
    if (icp.levels > filter.levels) return invalidArgument("icp.levels must not exceed filter.levels");
    if (min_head_pixels < 1) return invalidArgument("min_head_pixels must be >= 1");
    if (roi_margin_px < 0) return invalidArgument("roi_margin_px must be >= 0");
    return Status::ok();
}

Reconstructor::Reconstructor(const Intrinsics& k, const ReconParams& p)
    : k_(k),
      params_(p),
      init_status_(k.valid() ? p.validate() : invalidArgument("camera intrinsics are not valid")),
      filter_(k.valid() ? k : Intrinsics{}, p.filter),
      icp_(p.icp),
      volume_(init_status_.isOk() ? p.tsdf : TsdfParams{}),
      raycaster_(p.raycast) {
    const Intrinsics kk = k.valid() ? k : Intrinsics{};
    frame_.allocate(kk, p.filter.levels);
    model_.allocate(kk, p.filter.levels);
    trajectory_.reserve(kTrajectoryReserve);
}

bool Reconstructor::checkInput(const RgbdFrame& frame, const cv::Mat& head_mask, FrameResult& result) const {
    const cv::Size size(k_.width_px, k_.height_px);
    const char* why = nullptr;
    if (!init_status_.isOk()) {
        why = "reconstructor parameters are invalid (see initStatus())";
    } else if (frame.depth_m.empty() || frame.depth_m.type() != CV_32FC1) {
        why = "depth must be CV_32FC1 metres";
    } else if (frame.depth_m.size() != size) {
        why = "depth size differs from the camera intrinsics";
    } else if (!frame.colour_bgr.empty() && (frame.colour_bgr.type() != CV_8UC3 || frame.colour_bgr.size() != size)) {
        why = "colour must be empty or CV_8UC3 of the depth's size";
    } else if (!head_mask.empty() && (head_mask.type() != CV_8UC1 || head_mask.size() != size)) {
        why = "head mask must be empty or CV_8UC1 of the depth's size";
    }
    if (why == nullptr) return true;
    result.tracking.status = TrackingStatus::kInvalidInput;
    result.tracking.T_world_camera = T_world_camera_;
    result.reason = why;
    return false;
}

FrameResult Reconstructor::processFrame(const RgbdFrame& frame, const cv::Mat& head_mask) {
    FrameResult result;
    if (!checkInput(frame, head_mask, result)) {
        result.consecutive_failures = consecutive_failures_;
        return result;
    }
    Stopwatch watch;
    auto reject = [&](TrackingStatus status, const char* why) {
        result.tracking.status = status;
        result.tracking.T_world_camera = T_world_camera_;
        result.reason = why;
        ++consecutive_failures_;
        result.consecutive_failures = consecutive_failures_;
        result.reacquiring = consecutive_failures_ >= params_.icp.max_failures_before_reacquire;
        return result;
    };

    // Noise reduction and point cloud (thesis 4.1.1-4.1.2).
    const int valid = filter_.filter(frame.depth_m, head_mask, frame_);
    result.ms.filter = watch.lapMs();
    if (valid < params_.min_head_pixels) return reject(TrackingStatus::kNoHead, "too few valid head pixels");

    if (!have_model_) {
        // The first frame defines the reference orientation (thesis 4.1): world = this camera.
        if (!volume_.placed() && !volume_.place(frame_.levels[0]))
            return reject(TrackingStatus::kNoHead, "no valid head point to place the volume");
        T_world_camera_ = Pose::Identity();
        result.tracking.status = TrackingStatus::kFirstFrame;
        result.tracking.inliers = valid;
    } else {
        // Registration against the ray-cast model (thesis 4.1.3, frame-to-model).
        const bool reacquiring = consecutive_failures_ >= params_.icp.max_failures_before_reacquire;
        // The prediction is the last pose, as in the thesis. A constant-velocity prediction was tried and made
        // tracking unstable on the synthetic head: it re-applies the error along the head's weakly constrained
        // (sliding) direction every frame, and the error grew twofold per frame.
        Pose guess = T_world_camera_;
        if (reacquiring || frames_integrated_ == 1) {
            // Eq. 4.11 for the first frame pair and for re-acquisition after a loss: align the centroids.
            guess = T_world_camera_;
            centroidAlignment(frame_.levels[0], model_.levels[0], guess);
        }
        Pose estimate = guess;
        // Motion limits are measured from the last good pose, not from the centroid-shifted start.
        result.tracking = icp_.align(frame_, model_, T_world_model_, T_world_camera_, estimate);
        result.ms.icp = watch.lapMs();
        if (!result.tracking.ok()) {
            const char* why = "registration failed";
            switch (result.tracking.status) {
                case TrackingStatus::kNotEnoughPoints: why = "too few correspondences with the model"; break;
                case TrackingStatus::kDiverged: why = "registration diverged (residual too large)"; break;
                case TrackingStatus::kLargeMotion: why = "motion larger than the limits"; break;
                default: break;
            }
            const TrackingStatus status = result.tracking.status;
            result = reject(status, why);
            result.ms.icp = watch.elapsedMs();
            return result;
        }
        T_world_camera_ = estimate;
    }

    // Volumetric integration (thesis 4.2.1) and ray casting for the next registration (4.2.2).
    {
        std::lock_guard<std::mutex> lock(volume_mutex_);
        volume_.integrate(frame_.levels[0], frame.colour_bgr, T_world_camera_);
    }
    result.ms.integrate = watch.lapMs();
    result.integrated = true;
    ++frames_integrated_;
    have_model_ = true;
    consecutive_failures_ = 0;
    trajectory_.emplace_back(frame.timestamp_ns, T_world_camera_);
    const cv::Rect& roi0 = frame_.levels[0].roi;
    const int m = params_.roi_margin_px;
    raycastModel(T_world_camera_, cv::Rect(roi0.x - m, roi0.y - m, roi0.width + 2 * m, roi0.height + 2 * m),
                 frame_.levels[0].depth_m);
    result.ms.raycast = watch.lapMs();
    result.tracking.T_world_camera = T_world_camera_;
    result.consecutive_failures = 0;
    return result;
}

void Reconstructor::raycastModel(const Pose& T_world_camera, const cv::Rect& roi, const cv::Mat& depth_hint_m) {
    raycaster_.cast(volume_.grid(), k_, T_world_camera, roi, depth_hint_m, model_.levels[0]);
    // The hint is only valid inside the frame's ROI; outside it the rays march the cube (see RaycastParams).
    for (int l = 1; l < model_.count; ++l) {
        downsampleVertexMap(model_.levels[l - 1].vertex, model_.levels[l - 1].roi, model_.levels[l].vertex,
                            model_.levels[l].roi);
        cv::Rect unused;
        downsampleNormalMap(model_.levels[l - 1].normal, model_.levels[l - 1].roi, model_.levels[l].normal, unused);
    }
    T_world_model_ = T_world_camera;
}

void Reconstructor::reset() {
    std::lock_guard<std::mutex> lock(volume_mutex_);
    volume_.reset();
    T_world_camera_ = T_world_model_ = Pose::Identity();
    have_model_ = false;
    frames_integrated_ = 0;
    consecutive_failures_ = 0;
    trajectory_.clear();
    for (int l = 0; l < model_.count; ++l) model_.levels[l].roi = cv::Rect();
}

void Reconstructor::copyVolume(TsdfSnapshot& snapshot) const {
    std::lock_guard<std::mutex> lock(volume_mutex_);
    volume_.grid().copyTo(snapshot);
}

Mesh Reconstructor::extractMesh(const MeshParams& p) const {
    TsdfSnapshot snapshot;
    copyVolume(snapshot);
    return ::facescan::recon::extractMesh(snapshot, p);
}

void Reconstructor::renderPreview(const Pose& T_world_camera, cv::Mat& shaded_bgr) const {
    std::lock_guard<std::mutex> lock(volume_mutex_);
    raycaster_.renderShaded(volume_.grid(), k_, T_world_camera, shaded_bgr);
}

void Reconstructor::captureState(uint64_t since_generation, size_t trajectory_from, ReconState& out) const {
    const TsdfParams& tp = params_.tsdf;
    out = ReconState{};
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
    out.model_roi = model_.levels[0].roi;
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
    T_world_camera_ = s.T_world_camera;
    trajectory_.assign(s.trajectory.begin(), s.trajectory.end());
    if (have_model_) {
        // The model the next frame registers against: cast again from where it was cast last, over the same
        // pixels, without the depth hint of a frame this reconstructor never saw (rays march the cube instead).
        const cv::Rect roi = s.model_roi.area() > 0 ? s.model_roi : cv::Rect(0, 0, k_.width_px, k_.height_px);
        raycastModel(s.T_world_model, roi, cv::Mat());
    }
    T_world_model_ = s.T_world_model;
    return Status::ok();
}

bool Reconstructor::predictedHeadBox(cv::Rect& box) const {
    if (!have_model_ || consecutive_failures_ >= params_.icp.max_failures_before_reacquire) return false;
    const SurfaceLevel& lv = model_.levels[0];
    int x0 = lv.k.width_px, y0 = lv.k.height_px, x1 = -1, y1 = -1;
    for (int v = lv.roi.y; v < lv.roi.y + lv.roi.height; ++v) {
        const auto* row = lv.vertex.ptr<cv::Vec3f>(v);
        for (int u = lv.roi.x; u < lv.roi.x + lv.roi.width; ++u) {
            if (std::isnan(row[u][0])) continue;
            x0 = std::min(x0, u);
            x1 = std::max(x1, u);
            y0 = std::min(y0, v);
            y1 = std::max(y1, v);
        }
    }
    if (x1 < 0) return false;
    box = cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1);
    return true;
}

std::string toTumLine(int64_t timestamp_ns, const Pose& T_world_camera) {
    const Eigen::Quaternionf q(T_world_camera.linear());
    const Eigen::Vector3f t = T_world_camera.translation();
    const long long sec = static_cast<long long>(timestamp_ns / 1000000000);
    const long long nsec = static_cast<long long>(timestamp_ns % 1000000000);
    char buf[192];
    std::snprintf(buf, sizeof(buf), "%lld.%09lld %.7f %.7f %.7f %.7f %.7f %.7f %.7f", sec, nsec < 0 ? -nsec : nsec,
                  t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
    return buf;
}

}  // namespace facescan::recon
