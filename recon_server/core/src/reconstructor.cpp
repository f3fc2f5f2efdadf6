#include "recon/reconstructor.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "recon/timing.hpp"

namespace facescan::recon {
namespace {

constexpr size_t kTrajectoryReserve = 18000;  // 10 minutes at 30 frames/s before the vector ever grows
// Visibility: the head's valid pixels at pyramid level 2 (a sixteenth of the pixels, plenty for a share) against
// their running mean over fused frames (rate per fused frame), which drifts slowly towards the count while the
// head is hidden (rate per unfused frame).
constexpr int kVisibilityLevel = 2;
// A frame less than this many source periods after the last tracked one is the next frame (none skipped between).
constexpr float kNextFrameScale = 1.5f;
constexpr float kVisibleRefRate = 0.05f, kVisibleRefDecay = 0.02f;

// The ray caster's parameters for a model cast model_level levels coarser than the frame: a ray without a hint
// borrows one from as far in frame pixels as at full resolution, not 2^level times further.
RaycastParams modelRaycastParams(const RaycastParams& p, int model_level) {
    RaycastParams r = p;
    if (model_level > 0 && model_level < 8 && r.hint_search_px > 0) {
        r.hint_search_px = std::max(1, (r.hint_search_px + (1 << model_level) - 1) >> model_level);
    }
    return r;
}

// Valid vertices of a level inside its ROI.
int countValid(const SurfaceLevel& lv) {
    Eigen::Vector3f unused;
    return validCentroid(lv, unused);
}

}  // namespace

Reconstructor::Reconstructor(const Intrinsics& k, const ReconParams& p)
    : k_(k),
      params_(p),
      init_status_(k.valid() ? p.validate() : invalidArgument("camera intrinsics are not valid")),
      filter_(k.valid() ? k : Intrinsics{}, p.filter),
      icp_(p.icp),
      volume_(init_status_.isOk() ? p.tsdf : TsdfParams{}),
      raycaster_(p.raycast),
      reacquirer_(k.valid() ? k : Intrinsics{}, p.reacquire, p.icp) {
    const Intrinsics kk = k.valid() ? k : Intrinsics{};
    frame_.allocate(kk, p.filter.levels);
    model_level_ = next_model_level_ = init_status_.isOk() ? p.model_level : 0;
    cast_every_ = init_status_.isOk() ? p.model_cast_every : 1;
    fuse_every_ = init_status_.isOk() ? p.fuse_every : 1;
    model_.allocate(kk.scaled(model_level_), std::max(1, p.filter.levels - model_level_));
    allocateModelWeight();
    raycaster_ = Raycaster(modelRaycastParams(params_.raycast, model_level_));
    hint_m_.create(kk.height_px, kk.width_px, CV_32FC1);
    hint_m_.setTo(0.0f);
    // Full size: holds the hint of a model at any level (rows and columns from 0).
    hint_model_m_.create(kk.height_px, kk.width_px, CV_32FC1);
    hint_model_m_.setTo(0.0f);
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

FrameResult Reconstructor::processFrame(const RgbdFrame& frame, const cv::Mat& head_mask, const cv::Rect& mask_box) {
    // Figure 1.1 of the thesis for one frame: noise reduction and point cloud, surface alignment against the
    // ray-cast model, volumetric integration, ray casting. Each robustness policy is a named step below.
    FrameResult result;
    if (!checkInput(frame, head_mask, result)) {
        result.consecutive_failures = consecutive_failures_;
        return result;
    }
    Stopwatch watch;
    const FramePlan plan = planFrame(frame.timestamp_ns);

    // Noise reduction and point-cloud generation (thesis 4.1.1-4.1.2), on the levels registration will read.
    const int valid = filter_.filter(frame.depth_m, head_mask, frame_, mask_box, plan.coarse_level);
    result.ms.filter = watch.lapMs();
    if (valid < params_.min_head_pixels) {
        return rejectFrame(result, TrackingStatus::kNoHead, "too few valid head pixels");
    }
    restartOneFrameModelIfLost(result);

    bool fuse = true;
    if (!have_model_) {
        // The first frame defines the reference orientation (thesis 4.1): world = this camera.
        if (!startModel(valid, result)) {
            return rejectFrame(result, TrackingStatus::kNoHead, "no valid head point to place the volume");
        }
    } else if (!trackFrame(plan, valid, watch, result, fuse)) {
        return result;  // held or rejected: result says which and why
    }
    recordPose(frame.timestamp_ns, result);
    if (!fuse) return result;  // tracked only: the model and its last cast stay as they are

    // Volumetric integration (thesis 4.2.1), then ray casting for the next registration (4.2.2).
    integrateFrame(frame, result);
    result.ms.integrate = watch.lapMs();
    castModelIfDue(result);
    result.ms.raycast = watch.lapMs();
    return result;
}

Reconstructor::FramePlan Reconstructor::planFrame(int64_t timestamp_ns) const {
    FramePlan plan;
    // A frame after a rejected or held one is fused whatever fuse_every says: the model catches up at once.
    plan.after_gap = consecutive_failures_ > 0 || verify_next_;
    plan.motion_scale = motionScale(timestamp_ns);
    // Economy (departs from 4.1.3, which registers every frame on every level): a frame that will not be fused may
    // be registered on the coarser levels alone (unfused_finest_level). That is known before registration, since
    // fusion only depends on the count (a verified fit, which is always fused, only follows skipped frames or a
    // failed fit, and such frames take the full path). Only the next frame: less than half a period late (a
    // camera's clock jitters; one skipped frame makes it two periods).
    const bool fuse_due = frames_integrated_ < 2 || plan.after_gap || frames_since_fuse_ + 1 >= fuse_every_;
    const bool next_frame = plan.motion_scale < kNextFrameScale;
    plan.coarse_level = have_model_ && !fuse_due && next_frame ? params_.unfused_finest_level : 0;
    return plan;
}

FrameResult Reconstructor::rejectFrame(FrameResult& result, TrackingStatus status, const char* why) {
    // Thesis 4.1: frames that cannot be aligned are discarded; after max_failures_before_reacquire of them in a
    // row the caller re-detects the head and registration searches for it.
    result.tracking.status = status;
    result.tracking.T_world_camera = T_world_camera_;
    result.reason = why;
    ++consecutive_failures_;
    result.consecutive_failures = consecutive_failures_;
    result.reacquiring = consecutive_failures_ >= params_.icp.max_failures_before_reacquire;
    return result;
}

void Reconstructor::restartOneFrameModelIfLost(FrameResult& result) {
    // A model of one fused frame that lost the head for good starts over from this frame: re-acquisition cannot
    // verify a fit against one view once the head has turned away from it (most of what the frame shows is new),
    // so such a session would stay lost; one frame of model is all that is given up.
    if (have_model_ && frames_integrated_ == 1 && consecutive_failures_ >= params_.icp.max_failures_before_reacquire) {
        reset();
        result.restarted = true;
    }
}

bool Reconstructor::startModel(int valid_px, FrameResult& result) {
    if (!volume_.placed() && !volume_.place(frame_.levels[0])) return false;
    HeadRegion::fromFirstFrame(frame_.levels[0], params_.head_region, region_, person_down_camera_);
    visible_ref_px_ = static_cast<float>(countValid(frame_.levels[std::min(kVisibilityLevel, frame_.count - 1)]));
    T_world_camera_ = Pose::Identity();
    result.tracking.status = TrackingStatus::kFirstFrame;
    result.tracking.inliers = valid_px;
    return true;
}

bool Reconstructor::trackFrame(const FramePlan& plan, int valid_px, Stopwatch& watch, FrameResult& result, bool& fuse) {
    // Robust integration, part 1 (departs from 4.2.1, which fuses every measurement): whatever lies well in front
    // of the confident model at the predicted pose (further than any head motion between frames could put it: a
    // hand in front of the face) is an occluder; it leaves the frame before registration, so it cannot pull the
    // fit either. A frame registered on the coarser levels only is tested there (its finer levels are not read).
    if (params_.robust_integration) prefilterOccluders(plan.coarse_level, result);
    // Held frames (departs from 4.1.3): a head mostly hidden (a hand across the face, a head half out of view)
    // leaves too little surface to pin down all six degrees of freedom: a fit may slide along the visible part, and
    // so may a search. Such a frame is neither registered nor fused; the last good pose stays the next frame's
    // start, and the next fit is verified before it is fused (after a real loss, the head back in view is searched
    // for whatever part of it shows).
    const int visible = countValid(frame_.levels[std::min(kVisibilityLevel, frame_.count - 1)]);
    const bool long_loss = consecutive_failures_ >= params_.icp.max_failures_before_reacquire;
    if (!long_loss && headMostlyHidden(visible)) {
        result.ms.icp = watch.lapMs();
        result.tracking.status = TrackingStatus::kNotEnoughPoints;
        result.tracking.T_world_camera = T_world_camera_;
        result.reason = "head mostly hidden: held, not fused";
        result.consecutive_failures = consecutive_failures_;
        return false;
    }
    Pose estimate = T_world_camera_;
    const bool registered = plan.coarse_level > 0 && registerCoarse(plan.coarse_level, result, estimate);
    if (!registered && !registerFrame(valid_px, plan.motion_scale, result, estimate)) {
        rejectFrame(result, result.tracking.status, whyNotRegistered(result.tracking.status));
        result.ms.icp = watch.elapsedMs();
        return false;
    }
    // After a real loss the verified re-acquisition starts the visibility count afresh (the head may be nearer
    // or further than before).
    if (result.reacquired && long_loss) visible_ref_px_ = static_cast<float>(visible);
    visible_ref_px_ += kVisibleRefRate * (static_cast<float>(visible) - visible_ref_px_);
    verify_next_ = false;
    T_world_camera_ = estimate;
    // ReconParams::fuse_every: one tracked frame in N is fused; always the first two, any after a gap (a
    // re-acquisition only follows one) and any fit verified because frames were skipped.
    fuse = frames_integrated_ < 2 || plan.after_gap || result.verified || ++frames_since_fuse_ >= fuse_every_;
    // Robust integration, part 2: at the fitted pose, what lies in front of the confident model by more than the
    // truncation band (a hand near the face) is left out of this frame's fusion. The next cast looks for the model
    // behind such pixels (their hint is the model's depth), so the comparison holds for as long as the occluder
    // stays.
    if (params_.robust_integration && fuse) {
        const float band = params_.occluder_band_m > 0.0f ? params_.occluder_band_m : params_.tsdf.trunc_dist_m;
        result.occluding_pixels += rejectOccludingDepth(frame_, model_.levels[0], T_world_model_, T_world_camera_,
                                                        volume_.grid(), band, params_.confident_weight, &hint_m_);
    }
    result.ms.icp = watch.lapMs();
    return true;
}

bool Reconstructor::registerCoarse(int coarse_level, FrameResult& result, Pose& estimate) {
    // Within one frame's motion limits: a fit that moved further takes the full path, which verifies it.
    result.tracking = icp_.align(frame_, model_, T_world_model_, T_world_camera_, estimate, 1.0f, coarse_level);
    if (result.tracking.ok()) {
        result.finest_level = coarse_level;
        return true;
    }
    // The full path after all, with the finer levels it needs.
    estimate = T_world_camera_;
    if (params_.robust_integration) prefilterOccluders(0, result);
    for (int l = 0; l < coarse_level; ++l) filter_.computeNormals(frame_.levels[l]);
    return false;
}

const char* Reconstructor::whyNotRegistered(TrackingStatus status) {
    switch (status) {
        case TrackingStatus::kNotEnoughPoints: return "too few correspondences with the model";
        case TrackingStatus::kDiverged: return "registration diverged (residual too large)";
        case TrackingStatus::kLargeMotion: return "motion larger than the limits";
        case TrackingStatus::kUnverified: return "lost: no fit of the head passed verification";
        default: return "registration failed";
    }
}

void Reconstructor::recordPose(int64_t timestamp_ns, FrameResult& result) {
    result.tracked = true;
    consecutive_failures_ = 0;
    trajectory_.emplace_back(timestamp_ns, T_world_camera_);
    result.tracking.T_world_camera = T_world_camera_;
    result.consecutive_failures = 0;
}

void Reconstructor::integrateFrame(const RgbdFrame& frame, FrameResult& result) {
    frames_since_fuse_ = 0;
    {
        // Integration reads colour only inside the surface's ROI, so a colour source decodes just that (its time
        // counts as fusion's).
        const cv::Mat& colour = frameColour(frame, frame_.levels[0].roi);
        std::lock_guard<std::mutex> lock(volume_mutex_);
        volume_.integrate(frame_.levels[0], colour, T_world_camera_, frames_integrated_);
    }
    result.integrated = true;
    ++frames_integrated_;
    have_model_ = true;
}

void Reconstructor::castModelIfDue(FrameResult& result) {
    // Economy (departs from 4.2.2, which casts after every frame): the next frame registers against the last cast
    // while it is recent enough (model_cast_every); the first frames, a re-acquisition (its cast was from the
    // search's pose) and a new model level always cast.
    const bool cast = ++frames_since_cast_ >= cast_every_ || frames_integrated_ <= 2 || result.reacquired ||
                      next_model_level_ != model_level_;
    if (cast) {
        frames_since_cast_ = 0;
        const cv::Rect& roi0 = frame_.levels[0].roi;
        const int m = params_.roi_margin_px;
        raycastModel(cv::Rect(roi0.x - m, roi0.y - m, roi0.width + 2 * m, roi0.height + 2 * m),
                     result.occluding_pixels > 0 ? hint_m_ : frame_.levels[0].depth_m);
    }
    result.model_cast = cast;
}

void Reconstructor::prefilterOccluders(int level, FrameResult& result) {
    cv::Mat* hint = nullptr;  // only a frame that may be fused casts the model after (level 0)
    if (level == 0) {
        const cv::Rect& roi = frame_.levels[0].roi;
        frame_.levels[0].depth_m(roi).copyTo(hint_m_(roi));
        hint = &hint_m_;
    }
    result.occluding_pixels =  // the first count of the frame (or, on the full path after all, the one that holds)
        rejectOccludingDepth(frame_, model_.levels[0], T_world_model_, T_world_camera_, volume_.grid(),
                             params_.occluder_prefilter_m, params_.confident_weight, hint, level);
}

bool Reconstructor::headMostlyHidden(int visible) {
    const float needed = verify_next_ ? params_.resume_visible_share : params_.min_visible_share;
    if (static_cast<float>(visible) >= needed * visible_ref_px_) return false;
    // The reference drifts slowly towards what is seen, so a head that stays small (it moved away while hidden)
    // is fused again after a while, once a fit of it is verified.
    visible_ref_px_ += kVisibleRefDecay * (static_cast<float>(visible) - visible_ref_px_);
    verify_next_ = params_.reacquire.enabled;
    return true;
}

float Reconstructor::motionScale(int64_t timestamp_ns) const {
    if (params_.source_fps <= 0.0f || trajectory_.empty()) return 1.0f;
    const double periods = static_cast<double>(timestamp_ns - trajectory_.back().first) * 1e-9 * params_.source_fps;
    return std::clamp(static_cast<float>(periods), 1.0f, params_.max_motion_scale);
}

bool Reconstructor::beyondFrameLimits(const Pose& estimate) const {
    const Pose delta = T_world_camera_.inverse() * estimate;
    const float rotation_deg = Eigen::AngleAxisf(delta.linear()).angle() * static_cast<float>(180.0 / M_PI);
    return delta.translation().norm() > params_.icp.max_translation_m || rotation_deg > params_.icp.max_rotation_deg;
}

bool Reconstructor::registerFrame(int valid, float motion_scale, FrameResult& result, Pose& estimate) {
    // Registration against the ray-cast model (thesis 4.1.3, frame-to-model). The prediction is the last pose, as
    // in the thesis. A constant-velocity prediction was tried and made tracking unstable on the synthetic head: it
    // re-applies the error along the head's weakly constrained (sliding) direction every frame, and the error grew
    // twofold per frame.
    const bool reacquiring = consecutive_failures_ >= params_.icp.max_failures_before_reacquire;
    const bool first_pair = frames_integrated_ == 1;
    if (reacquiring || first_pair) {
        // Eq. 4.11 for the first frame pair and for re-acquisition after a loss: align the centroids.
        centroidAlignment(frame_.levels[0], model_.levels[0], estimate);
    }
    // Motion limits are measured from the last good pose, not from the centroid-shifted start.
    result.tracking = icp_.align(frame_, model_, T_world_model_, T_world_camera_, estimate, motion_scale);
    if (first_pair && !reacquiring && !result.tracking.ok()) {
        // The centroids of the first pair can belong to two different cuts of the head: the first frame's mask
        // comes from detection and segmentation, this one's from the model's prediction, and a region a centimetre
        // taller moves its centroid by more than the head moved between the frames (seen on the near stereo
        // camera, where the fit from the shifted start then found no pairs). The fit from the last pose, as every
        // later frame starts, before the frame counts as lost.
        estimate = T_world_camera_;
        result.tracking = icp_.align(frame_, model_, T_world_model_, T_world_camera_, estimate, motion_scale);
    }
    if (!params_.reacquire.enabled) return result.tracking.ok();
    if (consecutive_failures_ > 0 || verify_next_) {
        // After a loss (or hidden frames) nothing is fused before a fit is verified: the plain fit, else the best
        // verified hypothesis.
        const bool icp_ok = result.tracking.ok();
        if (reacquire(icp_ok, estimate, valid, result)) {
            estimate = T_world_camera_;
            return true;
        }
        if (icp_ok || result.hypotheses > 0) result.tracking.status = TrackingStatus::kUnverified;
        return false;
    }
    if (result.tracking.ok()) {
        // Frames were skipped (motion_scale > 1) and the fit moved further than one frame allows: fused only once
        // verified, so wider limits never fuse a wrong fit. The right one passes even against a single fused
        // frame (TracksAFrameElevenFramesAfterTheOnlyFusedOne).
        if (motion_scale <= 1.0f || !beyondFrameLimits(estimate)) return true;
        result.verified = true;
        result.check = reacquirer_.verify(volume_.grid(), frame_, estimate);
        if (reacquirer_.acceptsNewView(result.check)) return true;
        result.tracking.status = TrackingStatus::kUnverified;
    }
    // The first failed frame: the head may have turned fast. One search, bounded like any other.
    const TrackingStatus failed = result.tracking.status;
    if (reacquire(false, estimate, valid, result)) {
        estimate = T_world_camera_;
        return true;
    }
    result.tracking.status = failed;
    return false;
}

bool Reconstructor::reacquire(bool icp_ok, const Pose& icp_estimate, int valid_px, FrameResult& result) {
    Stopwatch watch;
    // The plain fit from the last good pose first: its own inlier share must pass too (a fit that converged on
    // part of the head only, sliding over the rest, can look consistent along each ray).
    const bool icp_converged = icp_ok && static_cast<float>(result.tracking.inliers) >=
                                             params_.reacquire.min_agree_share * static_cast<float>(valid_px);
    if (icp_converged) {
        result.verified = true;
        result.check = reacquirer_.verify(volume_.grid(), frame_, icp_estimate);
        if (reacquirer_.accepts(result.check)) {
            T_world_camera_ = icp_estimate;
            result.reacquire_ms = watch.elapsedMs();
            return true;
        }
    }
    // Lost for good and told to search less often (setSearchEvery: the server is behind): the frames between
    // searches try the plain fit only, so a lost session does not take the cores from the others.
    if (consecutive_failures_ >= params_.icp.max_failures_before_reacquire && ++frames_since_search_ < search_every_) {
        result.search_deferred = true;
        result.reacquire_ms = watch.elapsedMs();
        return false;
    }
    frames_since_search_ = 0;
    const ReacquireResult found = reacquirer_.search(volume_.grid(), frame_, T_world_camera_, region_);
    result.hypotheses = found.hypotheses;
    if (found.refined > 0) {
        result.verified = true;
        result.check = found.check;
    }
    if (!found.found) {
        result.reacquire_ms = watch.elapsedMs();
        return false;
    }
    // The model as seen from the verified pose, then the tracker's own ICP against it for the last millimetre;
    // robust integration compares against this cast.
    T_world_camera_ = found.T_world_camera;
    const cv::Rect& roi0 = frame_.levels[0].roi;
    const int m = params_.roi_margin_px;
    raycastModel(cv::Rect(roi0.x - m, roi0.y - m, roi0.width + 2 * m, roi0.height + 2 * m), frame_.levels[0].depth_m);
    Pose polished = found.T_world_camera;
    const TrackingResult r = icp_.align(frame_, model_, T_world_model_, found.T_world_camera, polished);
    if (r.ok()) {
        T_world_camera_ = polished;
        result.tracking = r;
    } else {
        result.tracking.status = TrackingStatus::kTracked;
        result.tracking.T_world_camera = found.T_world_camera;
    }
    result.reacquired = true;
    result.reacquire_ms = watch.elapsedMs();
    return true;
}

PoseCheck Reconstructor::verifyPose(const Pose& T_world_camera) {
    return reacquirer_.verify(volume_.grid(), frame_, T_world_camera);
}

FrameResult Reconstructor::noHead(const char* why) {
    FrameResult result;
    result.tracking.status = TrackingStatus::kNoHead;
    result.tracking.T_world_camera = T_world_camera_;
    result.reason = why;
    if (init_status_.isOk() && have_model_) ++consecutive_failures_;
    result.consecutive_failures = consecutive_failures_;
    result.reacquiring = consecutive_failures_ >= params_.icp.max_failures_before_reacquire;
    return result;
}

bool Reconstructor::predictHead(HeadPrediction& out) const {
    if (!have_model_ || !region_.valid || consecutive_failures_ > params_.predict_max_failures) return false;
    if (model_.levels[0].roi.empty()) return false;
    out.model = &model_.levels[0];
    out.T_world_camera = T_world_model_;
    out.region = region_;
    const int s = model_level_;
    const cv::Rect& r = model_.levels[0].roi;
    out.box = cv::Rect(r.x << s, r.y << s, r.width << s, r.height << s) & cv::Rect(0, 0, k_.width_px, k_.height_px);
    return true;
}

void Reconstructor::raycastModel(const cv::Rect& roi, const cv::Mat& depth_hint_m) {
    model_cast_roi_ = roi & cv::Rect(0, 0, k_.width_px, k_.height_px);
    if (next_model_level_ != model_level_) {
        model_level_ = next_model_level_;
        model_.allocate(k_.scaled(model_level_), std::max(1, params_.filter.levels - model_level_));
        allocateModelWeight();
        raycaster_ = Raycaster(modelRaycastParams(params_.raycast, model_level_));
    }
    const int s = model_level_;
    if (s == 0) {
        raycaster_.cast(volume_.grid(), k_, T_world_camera_, model_cast_roi_, depth_hint_m, model_.levels[0]);
    } else {
        // The model's pixel (u, v) is the frame's 2^s x 2^s block from (u << s, v << s); its hint is the block's
        // first measured pixel (row-major), 0 when none is.
        const SurfaceLevel& lv = model_.levels[0];
        const int x0 = model_cast_roi_.x >> s, y0 = model_cast_roi_.y >> s;
        const cv::Rect roi_model =
            cv::Rect(cv::Point(x0, y0), cv::Point((model_cast_roi_.br().x + (1 << s) - 1) >> s,
                                                  (model_cast_roi_.br().y + (1 << s) - 1) >> s)) &
            cv::Rect(0, 0, lv.k.width_px, lv.k.height_px);
        cv::Mat hint;
        if (!depth_hint_m.empty()) {
            const int n = 1 << s;
            for (int v = roi_model.y; v < roi_model.br().y; ++v) {
                float* dst = hint_model_m_.ptr<float>(v);
                for (int u = roi_model.x; u < roi_model.br().x; ++u) {
                    float z = 0.0f;
                    for (int dv = 0; dv < n && !(z > 0.0f); ++dv) {
                        const int fv = (v << s) + dv;
                        if (fv >= depth_hint_m.rows) break;
                        const float* row = depth_hint_m.ptr<float>(fv);
                        for (int du = 0; du < n && !(z > 0.0f); ++du) {
                            const int fu = (u << s) + du;
                            if (fu < depth_hint_m.cols && row[fu] > 0.0f) z = row[fu];
                        }
                    }
                    dst[u] = z;
                }
            }
            hint = hint_model_m_;
        }
        raycaster_.cast(volume_.grid(), lv.k, T_world_camera_, roi_model, hint, model_.levels[0]);
    }
    // The hint is only valid inside the frame's ROI; outside it the rays march the cube (see RaycastParams).
    for (int l = 1; l < model_.count; ++l) {
        downsampleVertexMap(model_.levels[l - 1].vertex, model_.levels[l - 1].roi, model_.levels[l].vertex,
                            model_.levels[l].roi);
        cv::Rect unused;
        downsampleNormalMap(model_.levels[l - 1].normal, model_.levels[l - 1].roi, model_.levels[l].normal, unused);
    }
    T_world_model_ = T_world_camera_;
}

void Reconstructor::allocateModelWeight() {
    // IcpParams::confident_model_weight: the cast writes the model's weights beside its vertices (finest level), at
    // the pixels where it writes a vertex; ICP reads no other.
    SurfaceLevel& finest = model_.levels[0];
    if (params_.icp.confident_model_weight > 0.0f) finest.weight.create(finest.vertex.size(), CV_32FC1);
}

void Reconstructor::setModelLevel(int level) {
    if (!init_status_.isOk()) return;
    next_model_level_ = std::clamp(level, 0, params_.filter.levels - 1);
}

void Reconstructor::setModelCastEvery(int frames) {
    if (!init_status_.isOk()) return;
    cast_every_ = std::clamp(frames, 1, ReconParams::kMaxModelCastEvery);
}

void Reconstructor::setFuseEvery(int frames) {
    if (!init_status_.isOk()) return;
    fuse_every_ = std::clamp(frames, 1, ReconParams::kMaxFuseEvery);
}

void Reconstructor::reset() {
    std::lock_guard<std::mutex> lock(volume_mutex_);
    volume_.reset();
    T_world_camera_ = T_world_model_ = Pose::Identity();
    have_model_ = false;
    visible_ref_px_ = 0.0f;
    verify_next_ = false;
    frames_since_search_ = 0;
    frames_since_cast_ = 0;
    frames_since_fuse_ = 0;
    frames_integrated_ = 0;
    consecutive_failures_ = 0;
    region_ = HeadRegion{};
    trajectory_.clear();
    for (int l = 0; l < model_.count; ++l) model_.levels[l].roi = cv::Rect();
    model_cast_roi_ = cv::Rect();
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
    const int s = model_level_;  // model pixels -> frame pixels
    box =
        cv::Rect(x0 << s, y0 << s, (x1 - x0 + 1) << s, (y1 - y0 + 1) << s) & cv::Rect(0, 0, k_.width_px, k_.height_px);
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
