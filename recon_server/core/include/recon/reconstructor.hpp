// The reconstruction pipeline of thesis Figure 1.1 on segmented frames: filter -> point cloud -> register against
// the ray-cast model -> integrate -> ray cast. Detection and segmentation run before it (callers pass the head
// mask). One object per scan; everything is allocated in the constructor, processFrame() does not allocate.
#pragma once

#include <cstdint>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "recon/camera.hpp"
#include "recon/depth_filter.hpp"
#include "recon/frame.hpp"
#include "recon/icp.hpp"
#include "recon/marching_cubes.hpp"
#include "recon/mesh.hpp"
#include "recon/model_agreement.hpp"
#include "recon/model_segmenter.hpp"
#include "recon/raycaster.hpp"
#include "recon/reacquirer.hpp"
#include "recon/recon_state.hpp"
#include "recon/status.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

class Stopwatch;  // recon/timing.hpp

struct ReconParams {
    FilterParams filter;
    IcpParams icp;
    TsdfParams tsdf;
    RaycastParams raycast;
    MeshParams mesh;
    HeadRegionParams head_region;  // where the head can be, fixed at the first frame (model-based segmentation)
    ReacquireParams reacquire;     // re-acquisition after a loss (hypothesis search, verification)
    int min_head_pixels = 500;     // count; fewer valid head pixels after filtering = kNoHead
    int roi_margin_px = 8;         // pixels; margin around the head mask's box for filtering and ray casting
    // Pyramid level at which the model is ray cast for tracking and segmentation (0 = every pixel, 1 = every 2nd
    // pixel of every 2nd row: a quarter of the rays). ICP's finest level then pairs each frame pixel with the model
    // pixel it projects into, ~2 mm away. Measured (facescan-bench recon --mask pipeline --model-level 1, 5 seeds):
    // the ray cast -59 % and a frame's serial cost 12.0 -> 9.0 ms; the default sequence keeps its accuracy (mean
    // 0.0954 -> 0.0944 mm, ATE 1.61 -> 1.68 mm), but the wide turn loses some (mean +0.017 mm, ATE 1.76 -> 1.95 mm;
    // with the renderer's mask instead, ATE improves: the loss is in the model-based segmentation, cause not yet
    // found). So full resolution stays the default, and a loaded server casts coarse.
    // Must be below filter.levels.
    int model_level = 0;
    // The model is ray cast after one integrated frame in model_cast_every (1 = after every frame, as in the
    // thesis); the frames between register against the last cast, from the pose it was cast at (ICP and the
    // segmenter take that pose). The cast is the frame's largest stage. Measured (facescan-bench recon --mask
    // pipeline --cast-every 2, the default and the five scenarios): a frame's serial cost 10.3 -> 8.0 ms, and the
    // accuracy kept: mean distance within -0.007..+0.008 mm of every frame's, ATE 1.63-1.92 mm against 1.55-1.90.
    // The model at half resolution (model_level 1) saves more (7.1 ms) but tracks worse (ATE 2.04-2.84 mm), so a
    // loaded server casts every 2nd frame first. A cast still follows the first frames, a re-acquisition
    // and a change of model level. Must be in [1, kMaxModelCastEvery].
    int model_cast_every = 1;
    static constexpr int kMaxModelCastEvery = 4;
    // A tracked frame is fused (thesis 4.2.1, Algorithm 3) when it is one in fuse_every (1 = every tracked frame,
    // as in the thesis); the frames between are registered (their pose is known and in the trajectory) but leave
    // the model alone, and so are not ray cast after either (model_cast_every counts fused frames). Integration is
    // a loaded server's largest stage once the model is cast coarse and every other frame; fusing every other
    // frame of a 30 Hz stream halves it and still averages each surface over many views. The first
    // two frames and every frame after a rejected or held one (a re-acquisition, a verified fit) are always fused.
    // Must be in [1, kMaxFuseEvery].
    int fuse_every = 1;
    static constexpr int kMaxFuseEvery = 4;
    // A frame that will not be fused (fuse_every > 1) is registered down to this pyramid level only, and the finer
    // levels' normal maps are not made: its pose is only the next frame's start and a trajectory entry, and the
    // next fused frame is registered at every level. 0 = every level, as for fused frames. Only for a frame right
    // after the last tracked one: after skipped frames, a rejected or held one, or when this fit fails, the frame
    // is registered at every level (and verified, searched for) as any other. Measured (facescan-bench recon --mask
    // pipeline --gt-accuracy --model-level 1 --fuse-every 2 or 3 --unfused-level 0 or 1, the five scenarios, seeds 1
    // and 2): mean distance -0.006..+0.007 mm, completeness within 0.1 %, the same frames tracked, ATE lower in 16 of
    // 20 runs (-0.10..+0.03 mm); with --serial at --fuse-every 3, filter and ICP 3.4 -> 2.5 ms a frame (medians of 5
    // alternated runs). Must be below icp.levels.
    int unfused_finest_level = 1;
    // Robust integration: a measurement more than occluder_band_m (0 = the truncation distance mu) in front of a
    // model surface whose weight is at least confident_weight is not fused; one more than occluder_prefilter_m in
    // front of it at the predicted pose is removed before registration too.
    bool robust_integration = true;
    float occluder_band_m = 0.0f;        // metres
    float occluder_prefilter_m = 0.03f;  // metres; beyond a 3 deg/frame turn's and the sensor noise's reach
    float confident_weight = 3.0f;       // TSDF weight (a frontal view adds ~0.9, a grazing one ~0.2)
    // The model keeps predicting the head (predictHead) for this many rejected frames after the last good one;
    // then callers find the head by detection again.
    int predict_max_failures = 3;  // count
    // A tracked frame whose head shows fewer pixels than this share of the usual (running mean over fused
    // frames: a hand across the face, a head half out of view) is tracked but not fused: too little surface to
    // trust the pose for fusion.
    float min_visible_share = 0.5f;     // ratio
    float resume_visible_share = 0.8f;  // ratio; after such frames, fusion resumes only above this share
    // ICP's motion limits hold per frame of a source at source_fps. A frame that comes n frame periods after the
    // last tracked one (its timestamp says so: a live server that is behind skips frames) may have moved n times as
    // far, up to max_motion_scale times; a fit beyond the one-frame limits is fused only once verified (the
    // re-acquisition's check).
    float source_fps = 30.0f;       // frames per second; 0 = every frame counts as the next one
    float max_motion_scale = 4.0f;  // ratio

    // Meyer's values (docs/design.md section 1): 256^3 voxels over 0.386 m, mu 5 mm, W max 256, bilateral 1 px / 50 mm,
    // 3 levels, ICP 20/15/10 iterations, gates 50-200 mm and 30-45 deg, re-acquire after 5 failed frames.
    static ReconParams faceDefaults();
    // Faster: fewer ICP iterations, a looser convergence test, coarser ray steps. Same volume and accuracy class.
    static ReconParams fast();
    Status validate() const;
};

// Wall-clock milliseconds of each stage for one frame. detect/segment/mesh are filled by callers that run them.
struct StageTimesMs {
    float detect = 0, segment = 0, filter = 0, icp = 0, integrate = 0, raycast = 0, mesh = 0;
    float total() const { return detect + segment + filter + icp + integrate + raycast + mesh; }
};

struct FrameResult {
    TrackingResult tracking;
    bool integrated = false;       // the frame was tracked and fused into the model
    bool tracked = false;          // the pose was fitted: integrated, or tracked only (ReconParams::fuse_every)
    bool reacquiring = false;      // tracking was lost for max_failures_before_reacquire frames: callers should
                                   // re-detect the head; the frame is registered against the model from the last
                                   // good pose with centroid pre-alignment (eq. 4.11), never by starting over
    int consecutive_failures = 0;  // count; rejected frames in a row, this one included
    bool reacquired = false;       // after a loss: the pose came from the hypothesis search (and was verified)
    bool search_deferred = false;  // lost, and searches are rationed (setSearchEvery): only the plain fit was tried
    bool restarted = false;        // a model of one frame had lost the head: the scan started over from this frame
                                   // (world = this camera; the trajectory holds this frame only)
    bool verified = false;         // after a loss: the fit was verified before fusing (check holds the figures)
    PoseCheck check;               // the verification's figures (the winner's, or the best rejected fit's)
    int hypotheses = 0;            // count; re-acquisition hypotheses tried this frame
    float reacquire_ms = 0;        // milliseconds of verification and search (included in ms.icp)
    int occluding_pixels = 0;      // count; measurements in front of a confident model (occluders), left out:
                                   // pixels of level finest_level (level 0 unless registered coarse)
    bool model_cast = false;       // the model was ray cast after this frame (ReconParams::model_cast_every)
    int finest_level = 0;          // the finest pyramid level registered (ReconParams::unfused_finest_level)
    StageTimesMs ms;
    const char* reason = "";  // empty when tracked; otherwise why, a static string (no allocation per frame)
};

class Reconstructor {
 public:
    // k: the depth camera; p must validate() (an invalid p leaves the object unusable: processFrame returns
    // kInvalidInput with the reason). Allocates every buffer up front.
    Reconstructor(const Intrinsics& k, const ReconParams& p);

    const Status& initStatus() const { return init_status_; }

    // One frame: depth (CV_32F metres, 0/NaN invalid, camera size), optional colour (CV_8UC3, camera size),
    // head_mask CV_8U nonzero = head, or empty for the whole frame. mask_box: where head_mask may be nonzero (a
    // segmentation's box: HeadObservation::mask_box), or empty when unknown; only that box is read (DepthFilter).
    // Bad input gives kInvalidInput, never a crash.
    FrameResult processFrame(const RgbdFrame& frame, const cv::Mat& head_mask, const cv::Rect& mask_box = {});

    // A frame in which the caller found no head (the pipeline could not segment one): counts as a rejected
    // frame (kNoHead), so a loss is noticed and the next head seen is verified before it is fused. `why` must
    // outlive the result (a static string or the caller's).
    FrameResult noHead(const char* why);

    void reset();  // starts a new scan (clears the model and trajectory)

    // The person's down direction in the camera frame (unit; +y for an upright camera, ImageRoll::downCamera for a
    // rolled one): the head region's chin plane of the next scan's first frame lies along it. Kept across reset().
    void setPersonDown(const Eigen::Vector3f& down_camera) { person_down_camera_ = down_camera; }

    int framesIntegrated() const { return frames_integrated_; }
    Pose lastPose() const { return T_world_camera_; }  // T_world_camera of the last tracked frame
    // Timestamp (ns) and T_world_camera of every tracked frame (fused or not: ReconParams::fuse_every); world =
    // the first frame's camera.
    const std::vector<std::pair<int64_t, Pose>>& trajectory() const { return trajectory_; }

    // Thread-safe against processFrame (another thread may call these while frames flow): copies only the
    // allocated blocks under a short lock. Mesh the snapshot off the frame path with extractMesh(snapshot, p).
    void copyVolume(TsdfSnapshot& snapshot) const;
    // Full-resolution mesh of the current model (copies the volume, then meshes without holding the lock).
    Mesh extractMesh(const MeshParams& p) const;
    Mesh extractMesh() const { return extractMesh(params_.mesh); }

    // Shaded image of the model from a pose (e.g. lastPose()); thread-safe like copyVolume (holds the lock while
    // casting, so prefer calling it at preview rates, not per frame).
    void renderPreview(const Pose& T_world_camera, cv::Mat& shaded_bgr) const;

    // Replication (recon_state.hpp, reconstructor_state.cpp). captureState copies the blocks integrated after
    // `since_generation` (all blocks when 0, or when the model was reset since) and the trajectory from
    // `trajectory_from` on; call it on the frame thread between frames. restoreState makes a fresh reconstructor
    // continue from a full state: the volume, poses, head region and counters, and the model ray cast again from
    // the last pose so tracking goes on.
    void captureState(uint64_t since_generation, size_t trajectory_from, ReconState& out) const;
    Status restoreState(const ReconState& full_state);

    // Where the model projects in the last camera (the box of the last ray cast): lets callers skip detection
    // while tracking. False before the first frame, while re-acquiring, or when the model is not visible.
    bool predictedHeadBox(cv::Rect& box) const;
    // The model's prediction of the next frame's head for model-based segmentation (FacePipeline): the last ray
    // cast, the pose it was cast from and the head region. False before the first frame and once more than
    // predict_max_failures frames in a row were rejected. `out.model` points into this object and is valid
    // until the next processFrame/reset (frame thread only).
    bool predictHead(HeadPrediction& out) const;
    // Where the head can be (world frame), fixed at the first frame; invalid before it.
    const HeadRegion& headRegion() const { return region_; }
    int consecutiveFailures() const { return consecutive_failures_; }
    // While lost, run the hypothesis search (~20 casts and fits, tens of ms) on one frame in `frames` only; the
    // others try the plain fit from the last good pose and its verification. 1 (the default) = every frame. A
    // server that is behind rations a lost session's searches so it does not starve the others (frame thread).
    void setSearchEvery(int frames) { search_every_ = frames < 1 ? 1 : frames; }
    // The pyramid level of the model from the next cast on (ReconParams::model_level; clamped to the valid
    // range): a loaded server casts coarser rather than skip frames. The current model stays in use until then;
    // a change allocates the model's maps once.
    void setModelLevel(int level);
    int modelLevel() const { return model_level_; }  // of the model in use
    // The model is cast after one integrated frame in `frames` from the next frame on (ReconParams::
    // model_cast_every; clamped to its valid range): a loaded server casts less often before it casts coarser.
    void setModelCastEvery(int frames);
    int modelCastEvery() const { return cast_every_; }
    // One tracked frame in `frames` is fused from the next frame on (ReconParams::fuse_every; clamped to its
    // valid range): a loaded server's last economy step.
    void setFuseEvery(int frames);
    int fuseEvery() const { return fuse_every_; }
    int requestedModelLevel() const { return next_model_level_; }  // of the next cast
    // Verifies a pose for the current frame as re-acquisition does (for tests and diagnostics): run after a
    // processFrame of that frame, which leaves the filtered frame in place.
    PoseCheck verifyPose(const Pose& T_world_camera);
    bool acceptsCheck(const PoseCheck& check) const { return reacquirer_.accepts(check); }

    const ReconParams& params() const { return params_; }
    const Intrinsics& intrinsics() const { return k_; }
    const TsdfVolume& volume() const { return volume_; }  // not thread-safe: the frame thread only

 private:
    // What a frame needs before it is filtered: whether it follows a gap, how many frame periods after the last
    // tracked one it comes, and the finest pyramid level registration will read.
    struct FramePlan {
        bool after_gap = false;
        float motion_scale = 1.0f;
        int coarse_level = 0;
    };
    // processFrame's steps (Figure 1.1), in order.
    bool checkInput(const RgbdFrame& frame, const cv::Mat& head_mask, FrameResult& result) const;
    FramePlan planFrame(int64_t timestamp_ns) const;
    // A frame not aligned (thesis 4.1: discarded): counted towards re-acquisition; returns a copy of result.
    FrameResult rejectFrame(FrameResult& result, TrackingStatus status, const char* why);
    void restartOneFrameModelIfLost(FrameResult& result);
    // The first frame: places the volume and defines the world; false when no head point places it.
    bool startModel(int valid_px, FrameResult& result);
    // Surface alignment with the robustness policies: false when the frame is held or rejected (result says why);
    // `fuse` says whether a tracked frame is fused.
    bool trackFrame(const FramePlan& plan, int valid_px, Stopwatch& watch, FrameResult& result, bool& fuse);
    // Registration on the coarse levels alone; false (the finer levels prepared) when the full path must follow.
    bool registerCoarse(int coarse_level, FrameResult& result, Pose& estimate);
    static const char* whyNotRegistered(TrackingStatus status);
    void recordPose(int64_t timestamp_ns, FrameResult& result);
    void integrateFrame(const RgbdFrame& frame, FrameResult& result);
    void castModelIfDue(FrameResult& result);
    void allocateModelWeight();
    void raycastModel(const cv::Rect& roi, const cv::Mat& depth_hint_m);
    // Robust integration's pre-filter (ReconParams::occluder_prefilter_m) over the frame's pyramid from `level` on,
    // at the predicted pose (result.occluding_pixels: what it removed); at level 0 it also refreshes the next
    // cast's depth hint.
    void prefilterOccluders(int level, FrameResult& result);
    // True (and the hold recorded) when the frame shows too little of the head to register or fuse.
    bool headMostlyHidden(int visible_px);
    // ICP from `estimate` (in: the start, out: the fit), with verification and search after a loss; false with
    // result.tracking.status saying why.
    bool registerFrame(int valid_px, float motion_scale, FrameResult& result, Pose& estimate);
    // How many frame periods (at least 1, at most max_motion_scale) lie between the last tracked frame and one
    // taken at timestamp_ns.
    float motionScale(int64_t timestamp_ns) const;
    // True when `estimate` moved from the last tracked pose by more than ICP's one-frame limits.
    bool beyondFrameLimits(const Pose& estimate) const;
    // After a loss: verify a plain ICP fit, else search hypotheses; true with T_world_camera_ set when verified.
    bool reacquire(bool icp_ok, const Pose& icp_estimate, int valid_px, FrameResult& result);

    Intrinsics k_;
    ReconParams params_;
    Status init_status_;
    DepthFilter filter_;
    Icp icp_;
    TsdfVolume volume_;
    Raycaster raycaster_;
    Reacquirer reacquirer_;
    SurfacePyramid frame_;     // the current frame, camera frame
    SurfacePyramid model_;     // the ray-cast model, world frame, seen from T_world_model_; its level 0 is the
                               // frame's level model_level_
    cv::Rect model_cast_roi_;  // the last cast's pixels, at the frame's full resolution
    cv::Mat depth_clean_;      // CV_32F: the input with NaN/inf replaced by 0
    cv::Mat hint_m_;           // CV_32F: the frame's depth with occluded pixels replaced by the model's (next cast)
    cv::Mat hint_model_m_;     // CV_32F: that hint at the model's resolution (when model_level > 0)
    Pose T_world_camera_ = Pose::Identity();
    Pose T_world_model_ = Pose::Identity();
    bool have_model_ = false;
    int cast_every_ = 1;         // ReconParams::model_cast_every, then setModelCastEvery
    int frames_since_cast_ = 0;  // integrated frames since the model was last cast
    int fuse_every_ = 1;         // ReconParams::fuse_every, then setFuseEvery
    int frames_since_fuse_ = 0;  // tracked frames since the last fused one
    int frames_integrated_ = 0;
    int consecutive_failures_ = 0;
    Eigen::Vector3f person_down_camera_ = Eigen::Vector3f::UnitY();  // setPersonDown
    HeadRegion region_;            // fixed at the first frame (part of the scan's state, like the volume and the pose)
    float visible_ref_px_ = 0.0f;  // running mean of the head's pixels (pyramid level 2) over fused frames
    bool verify_next_ = false;     // a mostly hidden frame was not fused: verify the next fit before fusing
    int search_every_ = 1;         // count; setSearchEvery
    int model_level_ = 0;          // pyramid level of model_ (ReconParams::model_level, then setModelLevel)
    int next_model_level_ = 0;     // the level of the next cast
    int frames_since_search_ = 0;  // count; lost frames since the last hypothesis search
    std::vector<std::pair<int64_t, Pose>> trajectory_;
    mutable std::mutex volume_mutex_;  // guards volume_ between processFrame and snapshot/preview callers
};

// One line of a TUM trajectory (docs/design.md section 7): "timestamp tx ty tz qx qy qz qw", timestamp in seconds.
std::string toTumLine(int64_t timestamp_ns, const Pose& T_world_camera);

}  // namespace facescan::recon
