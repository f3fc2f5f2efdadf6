// Registration: projective point-to-plane ICP, coarse to fine (thesis section 4.1.3). Data association is the
// thesis' Algorithm 2 with distance and normal gates; each iteration solves the linearised point-to-plane system
// (eq. 4.14-4.20) by Cholesky and stops when the error of eq. 4.21 converges. Failures are values, never throws.
#pragma once

#include <array>
#include <vector>

#include "recon/camera.hpp"
#include "recon/depth_filter.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

enum class TrackingStatus {
    kFirstFrame,       // the frame defines the reference orientation (world = this camera); nothing to align
    kTracked,          // aligned; the frame was integrated
    kNotEnoughPoints,  // too few valid pixels or correspondences to constrain 6 degrees of freedom
    kDiverged,         // the solve was singular, not finite, or the residual stayed too large
    kLargeMotion,      // converged, but further from the prediction than the motion limits allow
    kNoHead,           // the head mask (or the depth inside it) was empty
    kInvalidInput,     // wrong sizes or types; the frame was not looked at
    kUnverified,       // after a loss: no fit of the frame passed verification (Reconstructor)
};
const char* trackingStatusName(TrackingStatus s);

struct TrackingResult {
    TrackingStatus status = TrackingStatus::kInvalidInput;
    Pose T_world_camera = Pose::Identity();  // the estimate (the prediction when the frame was rejected)
    float rmse_m = 0.0f;                     // metres; point-to-plane RMS of the inliers at the finest level used
    int inliers = 0;                         // count; pairs at the finest level used, last iteration (x stride^2)
    int iterations = 0;                      // count; iterations run over all levels
    float model_offset_m = 0.0f;  // metres; the model's offset found (IcpParams::model_offset_ridge), > 0 = in front
    bool ok() const { return status == TrackingStatus::kTracked || status == TrackingStatus::kFirstFrame; }
};

struct IcpParams {
    int levels = 3;  // count; pyramid levels used (<= FilterParams::levels)
    // Iterations per level, index 0 = finest (Meyer: 20/15/10 fine to coarse); the convergence test usually
    // stops far earlier.
    std::array<int, kMaxPyramidLevels> iterations = {20, 15, 10, 10};
    // Distance gate of Algorithm 2 per level (metres), finest first (Meyer: 50..200 mm).
    std::array<float, kMaxPyramidLevels> dist_gate_m = {0.05f, 0.1f, 0.2f, 0.2f};
    // Normal-angle gate of Algorithm 2 per level (degrees), finest first (Meyer: 30..45 deg).
    std::array<float, kMaxPyramidLevels> normal_gate_deg = {30.0f, 37.5f, 45.0f, 45.0f};
    // Residual scale of the robust (Huber) weight (metres; 0 = plain least squares as in the thesis). Pairs that
    // pass the gates but sit far off the tangent plane (hair, silhouette) then pull less.
    float huber_m = 0.003f;
    // Frame-to-model ICP cannot tell a model grown uniformly thicker from a camera moved away from it: with the
    // pose alone as the unknown, a bias of the model's thickness moves the camera, the frame is fused where the
    // model already was, and the bias stays. A seventh unknown, the model's offset along its normals, takes part of
    // that up instead. On a face only the turn of the normals tells the offset from a translation along the view,
    // and on a nearly flat patch the two are one motion, so a prior holds the offset at 0 with this share of the
    // pairs' own weight. Negative: the thesis' six unknowns. Against six unknowns, the synthetic sensors' gentle
    // turn, wide turn and orbit (facescan-bench recon --input synthetic:sensor=S,scenario=M,frames=300,
    // subject=auto --gt-accuracy --mask pipeline), model error in mm: Kinect v1 0.081 / 0.087 / 0.084 -> 0.077 /
    // 0.082 / 0.078, Azure Kinect 0.148 / 0.143 / 0.154 -> 0.141 / 0.134 / 0.139, near-range 0.109 / 0.148 /
    // 0.099 -> 0.100 / 0.158 / 0.098, D415 0.047 / 0.046 / 0.043 -> 0.050 / 0.047 / 0.040 (docs/benchmarks.md,
    // "The model's offset as an unknown of ICP"). A share of 0.01 let the offset trade against the translation
    // (near-range wide turn 0.19 mm); 0.1 to 0.3 read alike.
    float model_offset_ridge = 0.1f;
    // TSDF weight (a frontal view adds about 0.9); 0 = every pair alike (the thesis). A pair whose model point has
    // an accumulated weight W below this counts W / this of a pair: surface fused from a view or two, or only at a
    // slant (the side of the head when a turn first shows it), is where the model is least right, and frame-to-model
    // ICP moves the camera to meet whatever the model says. As ElasticFusion registers against its confident
    // surfels. Read at the model's finest level only (SurfaceLevel::weight). Against 0, the synthetic sensors'
    // gentle turn, wide turn and orbit (the per-sensor command, docs/benchmarks.md "Registration weighted by the
    // model's confidence"), model error in mm: near-range 0.100 / 0.158 / 0.098 -> 0.103 / 0.130 / 0.098, Kinect v1
    // 0.077 / 0.082 / 0.078 -> 0.076 / 0.079 / 0.076; 5 and 12 read alike.
    float confident_model_weight = 8.0f;
    // pixels; the finest level pairs every n-th pixel of every n-th row. Its neighbours are nearly the same
    // constraint (the bilateral filter already averaged them), and the coarser levels have brought the pose within
    // a fraction of a voxel. 2 against 1, 5 seeds of each synthetic scenario (facescan-bench recon --input
    // synthetic:scenario=S,seed=N --mask pipeline --gt-accuracy): finest ICP 1.05 -> 0.62 ms with mean distance,
    // completeness, tracked share and losses the same within 0.008 mm / 0.1 %; 7-Scenes ATE 10.41 -> 10.35 mm.
    int finest_stride_px = 2;
    float convergence_rel = 1e-4f;  // ratio; stop a level when the error (eq. 4.21) changes less than this
    // metres; or when the update moves points less than this. 50 um is 1/30 of a voxel: on the synthetic head,
    // against 10 um, the finest level ran 29 % fewer pair evaluations with the same accuracy (mean 0.095 mm,
    // completeness 72.5 %, ATE 1.78 mm; facescan-bench recon --input synthetic --mask pipeline --gt-accuracy).
    float convergence_step_m = 5e-5f;
    int min_inliers = 200;                  // count; fewer correspondences at the finest level = kNotEnoughPoints
    float min_inlier_share = 0.2f;          // ratio; of the source's valid pixels at the finest level
    float max_rmse_m = 0.01f;               // metres; a larger final residual = kDiverged
    float max_translation_m = 0.08f;        // metres; a larger change from the prediction = kLargeMotion
    float max_rotation_deg = 25.0f;         // degrees; likewise for rotation
    int max_failures_before_reacquire = 5;  // count; consecutive rejected frames before the pipeline re-acquires
    Status validate() const;
};

// Thesis eq. 4.11: the translation that moves the centroid of `source` (camera frame, transformed by
// T_world_camera) onto the centroid of `target` (world frame). Returns false when either has no valid point.
bool centroidAlignment(const SurfaceLevel& source, const SurfaceLevel& target_world, Pose& T_world_camera);

// Projective ICP of a frame (camera-frame pyramid) against the model (world-frame vertex/normal pyramid rendered
// from T_world_model; its finest level may be whole levels coarser than the frame's, each frame level then pairs
// with the model level of its size or the model's finest). Holds the per-thread reduction buffers, so align()
// does not allocate.
class Icp {
 public:
    explicit Icp(const IcpParams& p);

    // T_world_camera: in, the initial guess; out, the estimate when status is kTracked (left unchanged otherwise,
    // and returned in the result either way). `prediction` is what the motion limits are measured against;
    // motion_scale (>= 1) multiplies them: the limits are per frame, and a frame may come several frames after the
    // prediction's (a live server skips frames when it is behind). finest_level: the last level registered (0 = the
    // finest; ReconParams::unfused_finest_level); the inlier and residual checks are made at that level, against its
    // own valid pixels, and finer levels are not read (their normal maps may be stale).
    TrackingResult align(const SurfacePyramid& source, const SurfacePyramid& model_world, const Pose& T_world_model,
                         const Pose& prediction, Pose& T_world_camera, float motion_scale = 1.0f, int finest_level = 0);

    const IcpParams& params() const { return params_; }

 private:
    IcpParams params_;
    // One row per stripe of the parallel reduction: A^T A's upper triangle and A^T b (eq. 4.20) for up to
    // kMaxUnknowns unknowns, then the error and the pair count; padded to whole 64-byte cache lines.
    static constexpr int kMaxUnknowns = 7;  // the pose's six and the model's offset
    static constexpr int kErrorSlot = kMaxUnknowns * (kMaxUnknowns + 1) / 2 + kMaxUnknowns;
    static constexpr int kCountSlot = kErrorSlot + 1;
    using Partial = std::array<double, (kCountSlot + 1 + 7) / 8 * 8>;
    std::vector<Partial> partial_;
};

}  // namespace facescan::recon
