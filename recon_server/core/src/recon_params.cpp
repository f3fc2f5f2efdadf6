// ReconParams: the presets and the check of every stage's parameters (one struct per stage, recon/*.hpp).
#include "recon/reconstructor.hpp"

namespace facescan::recon {

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
    RETURN_IF_ERROR(head_region.validate());
    RETURN_IF_ERROR(reacquire.validate());
    if (icp.levels > filter.levels) return invalidArgument("icp.levels must not exceed filter.levels");
    if (reacquire.enabled && filter.levels < 3) return invalidArgument("re-acquisition needs filter.levels >= 3");
    if (!(occluder_band_m >= 0.0f && confident_weight > 0.0f && occluder_prefilter_m > 0.0f))
        return invalidArgument("occluder_band_m must be >= 0, occluder_prefilter_m and confident_weight > 0");
    if (predict_max_failures < 0) return invalidArgument("predict_max_failures must be >= 0");
    if (!(min_visible_share >= 0.0f && resume_visible_share >= min_visible_share && resume_visible_share <= 1.0f))
        return invalidArgument("need 0 <= min_visible_share <= resume_visible_share <= 1");
    if (min_head_pixels < 1) return invalidArgument("min_head_pixels must be >= 1");
    if (!(source_fps >= 0.0f && source_fps <= 1000.0f && max_motion_scale >= 1.0f && max_motion_scale <= 100.0f))
        return invalidArgument("source_fps must be in [0, 1000] and max_motion_scale in [1, 100]");
    if (roi_margin_px < 0) return invalidArgument("roi_margin_px must be >= 0");
    if (model_level < 0 || model_level >= filter.levels)
        return invalidArgument("model_level must be >= 0 and below filter.levels");
    if (model_cast_every < 1 || model_cast_every > kMaxModelCastEvery)
        return invalidArgument("model_cast_every must be in [1, " + std::to_string(kMaxModelCastEvery) + "]");
    if (fuse_every < 1 || fuse_every > kMaxFuseEvery)
        return invalidArgument("fuse_every must be in [1, " + std::to_string(kMaxFuseEvery) + "]");
    if (unfused_finest_level < 0 || unfused_finest_level >= icp.levels)
        return invalidArgument("unfused_finest_level must be >= 0 and below icp.levels");
    return Status::ok();
}

}  // namespace facescan::recon
