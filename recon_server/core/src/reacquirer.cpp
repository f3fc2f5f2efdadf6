#include "recon/reacquirer.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace facescan::recon {
namespace {

constexpr float kDegToRad = static_cast<float>(M_PI / 180.0);
constexpr int kCoarseLevel = 2, kVerifyLevel = 1;

RaycastParams windowCast(const ReacquireParams& p) {
    RaycastParams r;
    r.start_before_hint_m = p.window_before_m;
    r.search_after_hint_m = p.window_after_m;
    r.hint_search_px = 2;
    r.hint_widen_m = 0.0f;
    return r;
}

// One level, wide gates: a hypothesis may be half a step (6 deg) and the centroid guess a few cm off.
IcpParams coarseIcp(IcpParams p) {
    p.model_offset_ridge = -1.0f;  // the pose alone: a hypothesis is judged by how well the head's shape fits
    p.levels = 1;
    p.iterations[0] = 10;
    p.dist_gate_m[0] = 0.10f;
    p.normal_gate_deg[0] = 45.0f;
    p.min_inliers = 40;
    p.max_rmse_m = 0.02f;
    p.max_translation_m = 0.15f;
    p.max_rotation_deg = 20.0f;
    return p;
}

// Levels 1 and 2 of the frame, tighter gates: from a coarse fit to within a millimetre or so.
IcpParams refineIcp(IcpParams p) {
    p.model_offset_ridge = -1.0f;
    p.levels = 2;
    p.iterations[0] = 10;
    p.iterations[1] = 10;
    p.dist_gate_m[0] = 0.03f;
    p.dist_gate_m[1] = 0.06f;
    p.normal_gate_deg[0] = 30.0f;
    p.normal_gate_deg[1] = 40.0f;
    p.min_inliers = 100;
    p.max_rmse_m = 0.01f;
    p.max_translation_m = 0.05f;
    p.max_rotation_deg = 10.0f;
    return p;
}

}  // namespace

Status ReacquireParams::validate() const {
    if (!(yaw_step_deg > 0.0f && pitch_step_deg > 0.0f)) return invalidArgument("reacquire steps must be > 0");
    if (yaw_steps < 0 || pitch_steps < 0 || yaw_steps > 10 || pitch_steps > 5)
        return invalidArgument("reacquire yaw_steps in [0, 10], pitch_steps in [0, 5]");
    if (refine_candidates < 1) return invalidArgument("reacquire refine_candidates must be >= 1");
    if (min_points < 6) return invalidArgument("reacquire min_points must be >= 6");
    if (!(window_before_m > 0.0f && window_after_m > 0.0f)) return invalidArgument("reacquire windows must be > 0");
    if (!(agree_m > 0.0f && conflict_m > agree_m)) return invalidArgument("reacquire needs 0 < agree_m < conflict_m");
    if (!(min_agree_share > 0.0f && min_agree_share <= 1.0f && max_conflict_share >= 0.0f && max_rmse_m > 0.0f))
        return invalidArgument("reacquire verification thresholds out of range");
    if (!(min_covered_share > 0.0f && min_covered_share <= 1.0f))
        return invalidArgument("reacquire min_covered_share must be in (0, 1]");
    return Status::ok();
}

Reacquirer::Reacquirer(const Intrinsics& k, const ReacquireParams& p, const IcpParams& icp)
    : params_(p), wide_(windowCast(p)), coarse_icp_(coarseIcp(icp)), refine_icp_(refineIcp(icp)) {
    cast_.allocate(k, kCoarseLevel + 1);
    const int hypotheses = (2 * p.yaw_steps + 1) * (2 * p.pitch_steps + 1);
    candidates_.reserve(static_cast<size_t>(std::max(hypotheses, p.refine_candidates) + 1));
}

void Reacquirer::castLevel(const VoxelBlockGrid& grid, const SurfaceLevel& frame_level, const Pose& T_world_camera,
                           SurfaceLevel& out) const {
    const int m = 2;
    const cv::Rect& r = frame_level.roi;
    wide_.cast(grid, frame_level.k, T_world_camera, cv::Rect(r.x - m, r.y - m, r.width + 2 * m, r.height + 2 * m),
               frame_level.depth_m, out);
}

PoseCheck Reacquirer::verify(const VoxelBlockGrid& grid, const SurfacePyramid& frame, const Pose& T_world_camera) {
    if (frame.count <= kVerifyLevel) return {};
    SurfaceLevel& model = cast_.levels[kVerifyLevel];
    castLevel(grid, frame.levels[kVerifyLevel], T_world_camera, model);
    return checkPose(frame.levels[kVerifyLevel], model, T_world_camera, T_world_camera, params_.agree_m,
                     params_.conflict_m);
}

bool Reacquirer::accepts(const PoseCheck& c) const {
    return c.measured > 0 && c.agreeShare() >= params_.min_agree_share &&
           c.conflictShare() <= params_.max_conflict_share && c.rmse_m <= params_.max_rmse_m;
}

bool Reacquirer::acceptsNewView(const PoseCheck& c) const {
    return c.measured > 0 &&
           static_cast<float>(c.associated) >= params_.min_covered_share * static_cast<float>(c.measured) &&
           static_cast<float>(c.agreeing) >= params_.min_agree_share * static_cast<float>(c.associated) &&
           c.conflictShare() <= params_.max_conflict_share && c.rmse_m <= params_.max_rmse_m;
}

ReacquireResult Reacquirer::search(const VoxelBlockGrid& grid, const SurfacePyramid& frame, const Pose& last_good,
                                   const HeadRegion& region) {
    ReacquireResult result;
    if (frame.count <= kCoarseLevel || grid.allocated_blocks == 0 || !region.valid) {
        result.why = "re-acquisition needs a model, a head region and a 3-level frame pyramid";
        return result;
    }
    // The frame's head centre (camera frame): its points' centroid pushed back along the view ray, as the head
    // region's centre was found at the first frame.
    const SurfaceLevel& coarse = frame.levels[kCoarseLevel];
    Eigen::Vector3f centroid;
    if (validCentroid(coarse, centroid) < params_.min_points) {
        result.why = "too few head points to re-acquire";
        return result;
    }
    const Eigen::Vector3f centre_cam = centroid + centroid.normalized() * region.centre_behind_m;

    // 1. Coarse: every hypothesis, cast and aligned at level 2; keep the best few by agreement.
    candidates_.clear();
    src_view_.count = model_view_.count = 1;
    src_view_.levels[0] = coarse;
    // The head's vertical axis is the person's down (the first camera's y when it was upright, its x when held in
    // portrait); the nodding axis is across the face, perpendicular to it and to the first view.
    const Eigen::Vector3f yaw_axis = region.down_world;
    const Eigen::Vector3f pitch_axis = region.down_world.cross(Eigen::Vector3f::UnitZ()).normalized();
    for (int ip = -params_.pitch_steps; ip <= params_.pitch_steps; ++ip) {
        for (int iy = -params_.yaw_steps; iy <= params_.yaw_steps; ++iy) {
            Pose hypothesis = Pose::Identity();
            hypothesis.linear() =
                (Eigen::AngleAxisf(static_cast<float>(iy) * params_.yaw_step_deg * kDegToRad, yaw_axis) *
                 Eigen::AngleAxisf(static_cast<float>(ip) * params_.pitch_step_deg * kDegToRad, pitch_axis))
                    .toRotationMatrix() *
                last_good.linear();
            hypothesis.translation() = region.centre_world - hypothesis.linear() * centre_cam;
            ++result.hypotheses;
            SurfaceLevel& model = cast_.levels[kCoarseLevel];
            castLevel(grid, coarse, hypothesis, model);
            model_view_.levels[0] = model;
            Pose estimate = hypothesis;
            if (!coarse_icp_.align(src_view_, model_view_, hypothesis, hypothesis, estimate).ok()) continue;
            const PoseCheck c =
                checkPose(coarse, model, hypothesis, estimate, 2.0f * params_.agree_m, params_.conflict_m);
            candidates_.push_back({estimate, c.agreeShare() - c.conflictShare()});
        }
    }
    std::sort(candidates_.begin(), candidates_.end(),
              [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
    if (candidates_.size() > static_cast<size_t>(params_.refine_candidates))
        candidates_.resize(static_cast<size_t>(params_.refine_candidates));
    if (candidates_.empty()) {
        result.why = "no re-acquisition hypothesis converged";
        return result;
    }

    // 2. Refine at levels 1-2 against a cast from the coarse fit, then verify; the best verified fit wins.
    src_view_.count = model_view_.count = 2;
    src_view_.levels[0] = frame.levels[1];
    src_view_.levels[1] = frame.levels[2];
    bool have_best = false;
    for (const Candidate& cand : candidates_) {
        castLevel(grid, frame.levels[1], cand.pose, cast_.levels[1]);
        downsampleVertexMap(cast_.levels[1].vertex, cast_.levels[1].roi, cast_.levels[2].vertex, cast_.levels[2].roi);
        cv::Rect unused;
        downsampleNormalMap(cast_.levels[1].normal, cast_.levels[1].roi, cast_.levels[2].normal, unused);
        model_view_.levels[0] = cast_.levels[1];
        model_view_.levels[1] = cast_.levels[2];
        Pose estimate = cand.pose;
        if (!refine_icp_.align(src_view_, model_view_, cand.pose, cand.pose, estimate).ok()) continue;
        const PoseCheck check = verify(grid, frame, estimate);
        ++result.refined;
        if (accepts(check)) {
            if (!result.found || check.agreeShare() > result.check.agreeShare()) {
                result.found = true;
                result.T_world_camera = estimate;
                result.check = check;
            }
        } else if (!result.found && (!have_best || check.agreeShare() > result.check.agreeShare())) {
            result.check = check;  // the best rejected candidate, for the report
            have_best = true;
        }
    }
    // Release the frame's images (the views share them) until the next search.
    src_view_.levels[0] = src_view_.levels[1] = SurfaceLevel();
    if (!result.found) {
        result.why = result.refined > 0 ? "no re-acquisition hypothesis passed verification"
                                        : "no re-acquisition hypothesis refined";
    }
    return result;
}

}  // namespace facescan::recon
