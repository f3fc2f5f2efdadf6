#include "recon/head_finder.hpp"

#include <algorithm>
#include <numeric>

namespace facescan::recon {

Status HeadFinderParams::validate() const {
    if (level < 0 || level > 4) return invalidArgument("level must be 0..4");
    if (!(blob_jump_m > 0)) return invalidArgument("blob_jump_m must be > 0");
    if (min_blob_px < 1 || max_blobs_tried < 1) return invalidArgument("min_blob_px and max_blobs_tried must be >= 1");
    if (!(seed_top_m >= 0 && seed_height_m > 0)) return invalidArgument("seed_top_m >= 0 and seed_height_m > 0");
    return Status::ok();
}

void HeadFinder::find(const cv::Mat& depth_m, const Intrinsics& k, HeadSegmentation& out) {
    out.found = false;
    auto fail = [&](std::string why) { out.markNotFound(depth_m, std::move(why)); };
    if (const Status s = params_.validate(); !s.isOk()) return fail("bad head finder params: " + s.message());
    if (const char* problem = depthInputProblem(depth_m, k)) return fail(problem);

    const HeadSegmenterParams& sp = segmenter_.params();
    const Intrinsics ks = k.scaled(params_.level);
    // Every 2^level-th pixel (cv::resize's INTER_NEAREST, by hand: no allocation in the frame loop).
    const int w = ks.width_px, h = ks.height_px, step = 1 << params_.level;
    small_.create(h, w, CV_32FC1);
    labels_.create(h, w, CV_32SC1);
    for (int v = 0; v < h; ++v) {
        const float* src = depth_m.ptr<float>(v * step);
        float* dst = small_.ptr<float>(v);
        for (int u = 0; u < w; ++u) dst[u] = src[u * step];
        std::fill_n(labels_.ptr<int>(v), w, 0);
    }
    // At most one blob per pixel: reserved once, so a noisy frame with many blobs does not reallocate.
    blobs_.reserve(static_cast<size_t>(w) * static_cast<size_t>(h) + 1);
    queue_.reserve(static_cast<size_t>(w) * static_cast<size_t>(h));
    order_.reserve(static_cast<size_t>(w) * static_cast<size_t>(h));
    blobs_.clear();
    blobs_.push_back({});  // label 0: none
    queue_.clear();
    int valid = 0, too_close = 0;
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            const float z0 = small_.at<float>(v, u);
            valid += z0 > 0;
            too_close += z0 > 0 && z0 < sp.min_depth_m;
            if (labels_.at<int>(v, u) != 0 || z0 < sp.min_depth_m || z0 > sp.max_depth_m) continue;
            const int id = static_cast<int>(blobs_.size());
            Blob blob;
            blob.top = v;
            queue_.clear();
            queue_.push_back(v * w + u);
            labels_.at<int>(v, u) = id;
            for (size_t q = 0; q < queue_.size(); ++q) {
                const int y = queue_[q] / w, x = queue_[q] - (queue_[q] / w) * w;
                const float z = small_.at<float>(y, x);
                ++blob.pixels;
                blob.depth_sum_m += z;
                blob.top = std::min(blob.top, y);
                const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
                for (int n = 0; n < 4; ++n) {
                    if (nx[n] < 0 || ny[n] < 0 || nx[n] >= w || ny[n] >= h) continue;
                    int& l = labels_.at<int>(ny[n], nx[n]);
                    const float nz = small_.at<float>(ny[n], nx[n]);
                    if (l != 0 || nz < sp.min_depth_m || nz > sp.max_depth_m) continue;
                    if (std::fabs(nz - z) >= params_.blob_jump_m) continue;
                    l = id;
                    queue_.push_back(ny[n] * w + nx[n]);
                }
            }
            blobs_.push_back(blob);
        }
    }
    if (valid == 0) return fail("no valid depth in the frame");

    order_.clear();
    for (int id = 1; id < static_cast<int>(blobs_.size()); ++id) {
        if (blobs_[static_cast<size_t>(id)].pixels >= params_.min_blob_px) order_.push_back(id);
    }
    std::sort(order_.begin(), order_.end(), [&](int a, int b) {
        return blobs_[static_cast<size_t>(a)].mean_depth_m() < blobs_[static_cast<size_t>(b)].mean_depth_m();
    });
    if (order_.size() > static_cast<size_t>(params_.max_blobs_tried))
        order_.resize(static_cast<size_t>(params_.max_blobs_tried));

    const int scale = step;
    std::string last_reason;  // empty until a blob fails: the found path builds no string
    for (int id : order_) {
        const Blob& blob = blobs_[static_cast<size_t>(id)];
        const float px_per_m = ks.fy_px / blob.mean_depth_m();
        // The seed: the blob's pixels in a band just below its top (the crown of a head, if it is one).
        const int r0 = blob.top + static_cast<int>(params_.seed_top_m * px_per_m);
        const int r1 = std::min(h - 1, r0 + std::max(1, static_cast<int>(params_.seed_height_m * px_per_m)));
        int c0 = w, c1 = -1;
        for (int v = r0; v <= r1; ++v) {
            const int* l = labels_.ptr<int>(v);
            for (int u = 0; u < w; ++u) {
                if (l[u] == id) c0 = std::min(c0, u), c1 = std::max(c1, u);
            }
        }
        if (c1 < c0) continue;
        const cv::Rect seed(c0 * scale, r0 * scale, (c1 - c0 + 1) * scale, (r1 - r0 + 1) * scale);
        segmenter_.segment(depth_m, k, seed, out);
        if (out.found) return;
        last_reason = out.reason;
    }
    if (valid > 0 && too_close * 5 > valid) {
        return fail("too close: most of the scene is nearer than the sensor's " +
                    std::to_string(static_cast<int>(sp.min_depth_m * 100)) + " cm minimum");
    }
    fail("no head-sized blob found by depth (" +
         (last_reason.empty() ? std::string("no depth blob large enough to hold a head") : last_reason) + ")");
}

}  // namespace facescan::recon
