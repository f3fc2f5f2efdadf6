// Head segmentation (thesis section 3.2): region growing from the face (Algorithm 1), then the head/torso split
// by the width criterion (eq. 3.7-3.13) and the neck shift. Everything outside the head becomes invalid depth.
// Works inside a head-sized ROI around the seed, so it costs well under 2 ms per 640x480 frame.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

struct HeadSegmenterParams {
    float grow_jump_m = 0.02f;  // delta_max of Algorithm 1: largest depth step between 4-neighbours (metres)
    // Algorithm 1 steps over no-data gaps up to this wide (the grazing-angle band between cheek and ear).
    float bridge_gap_m = 0.006f;  // metres
    // Kept below the top of the neck so the chin's underside stays in the model (the renderer's head label
    // also ends on a plane just under the chin).
    float chin_margin_m = 0.015f;       // metres
    float seed_band_m = 0.06f;          // seed pixels lie within this of the face box's median depth (metres)
    float min_depth_m = 0.4f;           // the sensor's near limit (Kinect v1's; adaptToSensor sets the camera's):
                                        // closer depth is "too close" (metres)
    float max_depth_m = 4.0f;           // farther depth is ignored (metres)
    float search_half_width_m = 0.30f;  // ROI half-width around the seed centre (metres at the seed depth)
    float search_above_m = 0.25f;       // ROI extent above the seed centre (metres)
    float search_below_m = 0.45f;       // ROI extent below: enough torso for the width split (metres)
    // Eq. 3.11 applies only when the torso is "significantly" wider than the head: mu_T >= ratio * mu_H.
    float torso_width_ratio = 1.3f;  // ratio
    // The eq. 3.11 line runs through the shoulders; the neck above it is removed by moving the line up to the top
    // of the neck (under the jaw), searched within this distance (the thesis' neck shift, made adaptive).
    float neck_shift_max_m = 0.10f;  // metres
    // What counts as a head (docs/design.md s1; also the depth-only fallback's blob test).
    float head_width_min_m = 0.08f;   // metres
    float head_width_max_m = 0.25f;   // metres
    float head_height_min_m = 0.10f;  // metres
    float head_height_max_m = 0.30f;  // metres

    Status validate() const;
    // Whether a region of this width and height (x, y of extent_m, metres) is head-sized.
    bool headSized(const Eigen::Vector3f& extent_m) const;
};

struct HeadSegmentation {
    bool found = false;
    std::string reason;                                    // why not found (empty when found)
    cv::Mat mask;                                          // CV_8UC1, 255 on the head, full frame size
    cv::Mat depth_m;                                       // the input depth with everything outside the head set to 0
    cv::Rect head_box_px;                                  // bounding box of the mask
    Eigen::Vector3f centroid_m = Eigen::Vector3f::Zero();  // mean head point, depth camera frame (metres)
    Eigen::Vector3f extent_m = Eigen::Vector3f::Zero();    // width, height, depth of the head (metres)
    float depth_median_m = 0;                              // median depth of the seed (metres)
    int pixels = 0;                                        // head pixels
    int split_row = -1;  // image row of the head/torso cut, -1 when no torso was attached

    // Not found, because `why`: mask and depth become all-zero images of depth_m's size (when it has one), so
    // callers can use them without checking.
    void markNotFound(const cv::Mat& depth_m, std::string why);
    // Makes mask and depth_m all-zero images of `size`, allocating only when the size changes and otherwise clearing
    // only what the last call wrote (written_px): the frame loop neither allocates nor sweeps two whole frames.
    void clearImages(const cv::Size& size);
    cv::Rect written_px;  // where mask/depth_m may be nonzero (what the last segmentation wrote)
};

// Why depth_m cannot be segmented (empty, not CV_32FC1 metres, not the camera's size), or nullptr when it can.
const char* depthInputProblem(const cv::Mat& depth_m, const Intrinsics& intrinsics);

class HeadSegmenter {
 public:
    explicit HeadSegmenter(const HeadSegmenterParams& params = {}) : params_(params) {}

    // seed_box_px: the face (or predicted head) box in depth pixels. Never throws; bad input gives a reason.
    void segment(const cv::Mat& depth_m, const Intrinsics& intrinsics, const cv::Rect& seed_box_px,
                 HeadSegmentation& out);

    const HeadSegmenterParams& params() const { return params_; }

 private:
    HeadSegmenterParams params_;
    // Scratch reused between frames.
    std::vector<uint8_t> visited_;  // ROI-sized, row-major
    std::vector<int> queue_;
    std::vector<int> row_count_, col_hist_, row_hist_;
    std::vector<float> scratch_;
};

// The span (in bins) between the 1st and 99th percentile of a histogram of `pixels` samples: a region's extent
// without the few stray pixels (flying pixels at the silhouette) that would make a head look too wide.
float percentileSpanPx(const std::vector<int>& hist, int pixels);
// "0.59 m wide, 0.51 m tall" for a region's extent (x, y of extent_m, metres).
std::string sizeText(const Eigen::Vector3f& extent_m);

// Eq. 3.9-3.13: given per-row pixel counts of a region (rows with 0 pixels allowed), the split row y (last head
// row) maximising w_H w_T (mu_H - mu_T)^2 over y in [first, last]; -1 when no row qualifies. Exposed for tests.
int widthCriterionSplit(const std::vector<int>& row_count, int first, int last);

}  // namespace facescan::recon
