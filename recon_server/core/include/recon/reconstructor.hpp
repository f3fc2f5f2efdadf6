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
#include "recon/raycaster.hpp"
#include "recon/recon_state.hpp"
#include "recon/status.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

struct ReconParams {
    FilterParams filter;
    IcpParams icp;
    TsdfParams tsdf;
    RaycastParams raycast;
    MeshParams mesh;
    int min_head_pixels = 500;  // count; fewer valid head pixels after filtering = kNoHead
    int roi_margin_px = 8;      // pixels; margin around the head mask's box for filtering and ray casting

    // Meyer's values (DESIGN.md section 1): 256^3 voxels over 0.386 m, mu 5 mm, W max 256, bilateral 1 px / 50 mm,
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
    bool integrated = false;       // the frame was fused into the model
    bool reacquiring = false;      // tracking was lost for max_failures_before_reacquire frames: callers should
                                   // re-detect the head; the frame is registered against the model from the last
                                   // good pose with centroid pre-alignment (eq. 4.11), never by starting over
    int consecutive_failures = 0;  // count; rejected frames in a row, this one included
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
    // head_mask CV_8U nonzero = head, or empty for the whole frame. Bad input gives kInvalidInput, never a crash.
    FrameResult processFrame(const RgbdFrame& frame, const cv::Mat& head_mask);

    void reset();  // starts a new scan (clears the model and trajectory)

    int framesIntegrated() const { return frames_integrated_; }
    Pose lastPose() const { return T_world_camera_; }  // T_world_camera of the last tracked frame
    // Timestamp (ns) and T_world_camera of every integrated frame; world = the first frame's camera.
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

    // Replication (recon_state.hpp). captureState copies the blocks integrated after `since_generation` (all
    // blocks when 0, or when the model was reset since) and the trajectory from `trajectory_from` on; call it on
    // the frame thread between frames. restoreState makes a fresh reconstructor continue from a full state: the
    // volume, poses and counters, and the model ray cast again from the last pose so tracking goes on.
    void captureState(uint64_t since_generation, size_t trajectory_from, ReconState& out) const;
    Status restoreState(const ReconState& full_state);

    // Where the model projects in the last camera (the box of the last ray cast): lets callers skip detection
    // while tracking. False before the first frame, while re-acquiring, or when the model is not visible.
    bool predictedHeadBox(cv::Rect& box) const;

    const ReconParams& params() const { return params_; }
    const Intrinsics& intrinsics() const { return k_; }
    const TsdfVolume& volume() const { return volume_; }  // not thread-safe: the frame thread only

 private:
    bool checkInput(const RgbdFrame& frame, const cv::Mat& head_mask, FrameResult& result) const;
    // Casts the model seen from T_world_camera over roi into model_ (all levels); sets T_world_model_.
    void raycastModel(const Pose& T_world_camera, const cv::Rect& roi, const cv::Mat& depth_hint_m);

    Intrinsics k_;
    ReconParams params_;
    Status init_status_;
    DepthFilter filter_;
    Icp icp_;
    TsdfVolume volume_;
    Raycaster raycaster_;
    SurfacePyramid frame_;  // the current frame, camera frame
    SurfacePyramid model_;  // the ray-cast model, world frame, seen from T_world_model_
    cv::Mat depth_clean_;   // CV_32F: the input with NaN/inf replaced by 0
    Pose T_world_camera_ = Pose::Identity();
    Pose T_world_model_ = Pose::Identity();
    bool have_model_ = false;
    int frames_integrated_ = 0;
    int consecutive_failures_ = 0;
    std::vector<std::pair<int64_t, Pose>> trajectory_;
    mutable std::mutex volume_mutex_;  // guards volume_ between processFrame and snapshot/preview callers
};

// One line of a TUM trajectory (DESIGN.md section 7): "timestamp tx ty tz qx qy qz qw", timestamp in seconds.
std::string toTumLine(int64_t timestamp_ns, const Pose& T_world_camera);

}  // namespace facescan::recon
