// Head segmentation from the tracked model. Once the head is tracked, the ray-cast model says where
// its surface will be in the next frame: pixels whose depth lies within a margin of that prediction are head
// (the seeds), and so are the pixels that grow from them through depth-continuous neighbours (Algorithm 1's test,
// thesis section 3.2) inside a band around the predicted footprint. Growth stops at the head region, a world-frame
// bound fixed at the scan's first frame: a sphere around the head's centre cut by a plane under the chin. The
// torso, a hand near the face or a hood therefore cannot join however they touch the head in depth, which
// is where the width criterion of eq. 3.7-3.13 alone fails (chin on the chest). Detection and the width
// criterion start a scan and check on it (FacePipeline); this runs on every tracked frame instead of them.
#pragma once

#include <Eigen/Core>
#include <array>
#include <opencv2/core.hpp>
#include <vector>

#include "recon/camera.hpp"
#include "recon/depth_filter.hpp"
#include "recon/head_segmenter.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

struct HeadRegionParams {
    float radius_m = 0.17f;            // metres; a head fits in this sphere around its centre (crown to chin
                                       // 0.23 m, ear to ear 0.15 m, nose to back 0.20 m, plus margin)
    float centre_behind_m = 0.07f;     // metres; the centre lies this far behind the first frame's head points'
                                       // centroid along the view ray (as TsdfParams::centre_behind_surface_m)
    float below_lowest_m = 0.01f;      // metres; the chin plane lies this far below the first frame's lowest head
                                       // point (its neck cut)
    float max_below_centre_m = 0.16f;  // metres; and never further below the centre than this (a first mask that
                                       // kept a neck without torso must not let the torso in later)
    Status validate() const;
};

// Where the head can be, in the world frame (the first camera's frame, in which the head is static).
struct HeadRegion {
    bool valid = false;
    Eigen::Vector3f centre_world = Eigen::Vector3f::Zero();  // metres
    Eigen::Vector3f down_world = Eigen::Vector3f::UnitY();   // unit; the person's down in the first camera
    float below_centre_m = 0.0f;                             // metres; the chin plane's distance below the centre
    float radius_m = 0.0f;                                   // metres
    float centre_behind_m = 0.0f;  // metres; the centre is this far behind the visible head's centroid (as found)

    bool contains(const Eigen::Vector3f& p_world) const {
        const Eigen::Vector3f d = p_world - centre_world;
        return d.squaredNorm() <= radius_m * radius_m && d.dot(down_world) <= below_centre_m;
    }
    // From the first frame's head (level 0 of the filtered pyramid, camera frame = world frame) and the person's
    // down direction in that camera (unit; +y upright, ImageRoll::downCamera when the camera is rolled). False
    // when the level holds no valid point.
    static bool fromFirstFrame(const SurfaceLevel& level0, const HeadRegionParams& p, HeadRegion& out,
                               const Eigen::Vector3f& down_camera = Eigen::Vector3f::UnitY());
};

// What the tracked model predicts about the head in the next frame (Reconstructor::predictHead).
struct HeadPrediction {
    const SurfaceLevel* model = nullptr;     // the ray-cast model: world-frame vertices, cast inside its roi, at the
                                             // depth's resolution or whole pyramid levels coarser
    Pose T_world_camera = Pose::Identity();  // the pose it was cast from (the last tracked frame)
    HeadRegion region;                       // where the head can be (world frame)
    cv::Rect box;                            // the model's box in the image (depth pixels)
};

struct ModelSegmenterParams {
    float seed_margin_m = 0.02f;   // metres; a pixel within this of the predicted depth is head (a 3 deg/frame
                                   // turn moves the face's edge ~5 mm; the sensor's noise at 1 m is ~3 mm)
    float grow_jump_m = 0.01f;     // metres; largest depth step between 4-neighbours while growing (Algorithm 1)
    float band_m = 0.04f;          // metres (at the head's depth); growth stays within this of the predicted box
    int min_pixels = 500;          // pixels; fewer head pixels = no head
    float min_seed_share = 0.15f;  // ratio; of the predicted pixels that must be confirmed by the frame
    Status validate() const;
};

class ModelSegmenter {
 public:
    explicit ModelSegmenter(const ModelSegmenterParams& p = {}) : params_(p) {}

    // Segments the head of depth_m (CV_32F metres, camera size) using the prediction; writes out.mask,
    // out.depth_m (allocated on first use only), head_box_px, centroid_m, extent_m, pixels. out.found is false,
    // with a reason, when the frame does not confirm the prediction (the head left, turned away or is hidden) or
    // the result is not head-sized (HeadSegmenterParams' ranges). No allocation after the first call.
    void segment(const cv::Mat& depth_m, const Intrinsics& k, const HeadPrediction& prediction,
                 const HeadSegmenterParams& size_limits, HeadSegmentation& out);

    const ModelSegmenterParams& params() const { return params_; }
    int lastSeeds() const { return seeds_; }  // seeds of the last call (pixels confirming the prediction)

 private:
    ModelSegmenterParams params_;
    static constexpr int kStripes = 16;  // fixed stripes of rows: the parallel passes' reductions merge in order
    cv::Mat state_;                      // CV_8U per pixel: 0 untouched, 1 head, 2 tried and outside the region
    std::vector<int> queue_;             // growth's queue: head pixels with an untouched neighbour, then grown ones
    std::array<std::vector<int>, kStripes> frontier_;     // per stripe: its seeds with an untouched neighbour
    std::array<std::vector<int>, kStripes> stripe_cols_;  // per stripe: head pixels per column
    std::vector<int> col_hist_, row_hist_;
    int seeds_ = 0;
};

}  // namespace facescan::recon
