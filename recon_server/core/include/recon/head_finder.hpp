// Depth-only head finding: the fallback when there is no colour or the cascade misses (profile views).
// Splits the depth image into depth-connected blobs, and from the nearest blob inwards asks the head segmenter
// (Algorithm 1 + eq. 3.7-3.13) to cut a head off the blob's top; the first head-sized result wins
// (80-250 mm wide, 100-300 mm tall by default: HeadSegmenterParams).
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "recon/camera.hpp"
#include "recon/head_segmenter.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

struct HeadFinderParams {
    int level = 2;                // blobs are found on every 2^level-th pixel (160x120 for VGA) (pyramid level)
    float blob_jump_m = 0.05f;    // depth step that separates blobs at that level (metres)
    int min_blob_px = 40;         // smaller blobs (at `level`) are noise (pixels)
    int max_blobs_tried = 6;      // nearest blobs handed to the segmenter, at most (count)
    float seed_top_m = 0.03f;     // the seed box starts this far below the blob's top (skips hair fringe) (metres)
    float seed_height_m = 0.10f;  // and is this tall (metres)

    Status validate() const;
};

class HeadFinder {
 public:
    explicit HeadFinder(const HeadFinderParams& params = {}, const HeadSegmenterParams& segmenter = {})
        : params_(params), segmenter_(segmenter) {}

    // Finds the nearest head-sized blob and segments it into `out`; out.reason says why when none is found.
    void find(const cv::Mat& depth_m, const Intrinsics& intrinsics, HeadSegmentation& out);

    const HeadFinderParams& params() const { return params_; }

 private:
    struct Blob {
        int pixels = 0;
        double depth_sum_m = 0;
        int top = 0;  // first row (at level)
        float mean_depth_m() const { return static_cast<float>(depth_sum_m / pixels); }
    };
    HeadFinderParams params_;
    HeadSegmenter segmenter_;
    cv::Mat small_, labels_;
    std::vector<int> queue_;
    std::vector<Blob> blobs_;
    std::vector<int> order_;  // blob ids nearest first
};

}  // namespace facescan::recon
