#include "recon/head_segmenter.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace facescan::recon {
namespace {

std::string metres(float v) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.2f m", static_cast<double>(v));
    return buf;
}

}  // namespace

Status HeadSegmenterParams::validate() const {
    if (!(grow_jump_m > 0) || !(seed_band_m > 0)) return invalidArgument("grow_jump_m and seed_band_m must be > 0");
    if (!(min_depth_m > 0 && max_depth_m > min_depth_m)) return invalidArgument("need 0 < min_depth_m < max_depth_m");
    if (!(search_half_width_m > 0 && search_above_m > 0 && search_below_m > 0)) {
        return invalidArgument("search extents must be > 0");
    }
    if (!(bridge_gap_m >= 0 && chin_margin_m >= 0)) return invalidArgument("bridge_gap_m, chin_margin_m must be >= 0");
    if (!(torso_width_ratio >= 1)) return invalidArgument("torso_width_ratio must be >= 1");
    if (!(neck_shift_max_m >= 0)) return invalidArgument("neck_shift_max_m must be >= 0");
    if (!(head_width_min_m > 0 && head_width_max_m > head_width_min_m && head_height_min_m > 0 &&
          head_height_max_m > head_height_min_m)) {
        return invalidArgument("head size ranges must be positive and ordered");
    }
    return Status::ok();
}

int widthCriterionSplit(const std::vector<int>& row_count, int first, int last) {
    const int n = static_cast<int>(row_count.size());
    first = std::max(first, 0);
    last = std::min(last, n - 2);  // the torso needs at least one row
    int rows_total = 0;
    long pixels_total = 0;
    for (int c : row_count) {
        rows_total += c > 0;
        pixels_total += c;
    }
    if (rows_total < 2 || first > last) return -1;
    int rows_h = 0;
    long pixels_h = 0;
    for (int y = 0; y < first; ++y)
        rows_h += row_count[static_cast<size_t>(y)] > 0, pixels_h += row_count[static_cast<size_t>(y)];
    int best = -1;
    double best_score = -1;
    for (int y = first; y <= last; ++y) {
        rows_h += row_count[static_cast<size_t>(y)] > 0;
        pixels_h += row_count[static_cast<size_t>(y)];
        const int rows_t = rows_total - rows_h;
        if (rows_h == 0 || rows_t == 0) continue;
        const double mu_h = static_cast<double>(pixels_h) / rows_h;                 // eq. 3.9
        const double mu_t = static_cast<double>(pixels_total - pixels_h) / rows_t;  // eq. 3.10
        const double w_h = static_cast<double>(rows_h) / rows_total;                // eq. 3.12
        const double w_t = static_cast<double>(rows_t) / rows_total;                // eq. 3.13
        const double score = w_h * w_t * (mu_h - mu_t) * (mu_h - mu_t);             // eq. 3.11
        if (score > best_score) best_score = score, best = y;
    }
    return best;
}

void HeadSegmentation::markNotFound(const cv::Mat& depth, std::string why) {
    found = false;
    reason = std::move(why);
    if (depth.empty()) return;
    clearImages(depth.size());
}

void HeadSegmentation::clearImages(const cv::Size& size) {
    // cv::Mat::setTo allocates on every call (OpenCV 4.6): rows are cleared by hand.
    cv::Rect dirty = written_px & cv::Rect(0, 0, size.width, size.height);
    if (mask.size() != size || mask.type() != CV_8UC1 || depth_m.size() != size || depth_m.type() != CV_32FC1) {
        mask.create(size, CV_8UC1);
        depth_m.create(size, CV_32FC1);
        dirty = cv::Rect(0, 0, size.width, size.height);
    }
    for (int v = dirty.y; v < dirty.br().y; ++v) {
        std::fill_n(mask.ptr<uint8_t>(v) + dirty.x, dirty.width, uint8_t{0});
        std::fill_n(depth_m.ptr<float>(v) + dirty.x, dirty.width, 0.0f);
    }
    written_px = cv::Rect();
}

const char* depthInputProblem(const cv::Mat& depth_m, const Intrinsics& k) {
    if (depth_m.empty()) return "depth image is empty";
    if (depth_m.type() != CV_32FC1) return "depth must be CV_32FC1 metres";
    if (depth_m.cols != k.width_px || depth_m.rows != k.height_px) return "depth size differs from the intrinsics";
    return nullptr;
}

void HeadSegmenter::segment(const cv::Mat& depth_m, const Intrinsics& k, const cv::Rect& seed_box_px,
                            HeadSegmentation& out) {
    out.found = false;
    out.reason.clear();
    out.pixels = 0;
    out.split_row = -1;
    out.head_box_px = {};
    auto fail = [&](std::string why) { out.markNotFound(depth_m, std::move(why)); };
    if (const Status s = params_.validate(); !s.isOk()) return fail("bad segmenter params: " + s.message());
    if (const char* problem = depthInputProblem(depth_m, k)) return fail(problem);
    const cv::Rect bounds(0, 0, depth_m.cols, depth_m.rows);
    const cv::Rect seed = seed_box_px & bounds;
    if (seed.area() == 0) return fail("face box lies outside the image");

    // Seed depth: the median over the central half of the box (the box corners often hold background).
    const cv::Rect core = cv::Rect(seed.x + seed.width / 4, seed.y + seed.height / 4, std::max(1, seed.width / 2),
                                   std::max(1, seed.height / 2)) &
                          bounds;
    // Scratch sized for the whole frame on the first call: a later, larger head never reallocates it.
    scratch_.reserve(depth_m.total());
    queue_.reserve(depth_m.total());
    visited_.reserve(depth_m.total());
    row_count_.reserve(static_cast<size_t>(depth_m.rows));
    row_hist_.reserve(static_cast<size_t>(depth_m.rows));
    col_hist_.reserve(static_cast<size_t>(depth_m.cols));
    scratch_.clear();
    int too_close = 0;
    for (int v = core.y; v < core.br().y; ++v) {
        const float* z = depth_m.ptr<float>(v);
        for (int u = core.x; u < core.br().x; ++u) {
            if (z[u] >= params_.min_depth_m && z[u] <= params_.max_depth_m) scratch_.push_back(z[u]);
            too_close += z[u] > 0 && z[u] < params_.min_depth_m;
        }
    }
    if (scratch_.empty()) {
        return fail(too_close > 0 ? "too close: the face is nearer than " + metres(params_.min_depth_m)
                                  : "no valid depth inside the face box");
    }
    auto mid = scratch_.begin() + static_cast<std::ptrdiff_t>(scratch_.size() / 2);
    std::nth_element(scratch_.begin(), mid, scratch_.end());
    const float z_seed = *mid;
    out.depth_median_m = z_seed;
    if (static_cast<size_t>(too_close) > scratch_.size()) {
        return fail("too close: most of the face is nearer than " + metres(params_.min_depth_m));
    }

    // ROI: a head-plus-shoulders window in metres around the seed centre.
    const float px_per_m = k.fx_px / z_seed;
    const int cu = seed.x + seed.width / 2, cv_ = seed.y + seed.height / 2;
    const int half_w = static_cast<int>(params_.search_half_width_m * px_per_m);
    const int above = static_cast<int>(params_.search_above_m * px_per_m);
    const int below = static_cast<int>(params_.search_below_m * px_per_m);
    const cv::Rect roi =
        cv::Rect(cv::Point(cu - half_w, cv_ - above), cv::Point(cu + half_w + 1, cv_ + below + 1)) & bounds;
    const int w = roi.width, h = roi.height;

    // Algorithm 1: grow R from the seed pixels through 4-neighbours whose depth differs by < delta_max.
    visited_.assign(static_cast<size_t>(w) * static_cast<size_t>(h), uint8_t{0});
    queue_.clear();
    for (int v = core.y; v < core.br().y; ++v) {
        const float* z = depth_m.ptr<float>(v);
        for (int u = core.x; u < core.br().x; ++u) {
            if (!roi.contains({u, v}) || std::fabs(z[u] - z_seed) > params_.seed_band_m) continue;
            const int idx = (v - roi.y) * w + (u - roi.x);
            visited_[idx] = 1;
            queue_.push_back(idx);
        }
    }
    const float zmin = params_.min_depth_m, zmax = params_.max_depth_m, jump = params_.grow_jump_m;
    const int gap_px = static_cast<int>(params_.bridge_gap_m * px_per_m);
    for (size_t head = 0; head < queue_.size(); ++head) {
        const int idx = queue_[head];
        const int y = idx / w, x = idx - y * w;
        const float z = depth_m.at<float>(y + roi.y, x + roi.x);
        // A neighbour without depth may be a thin no-data band (grazing angle at the ears and jaw): look up to
        // gap_px further in the same direction for depth that continues the surface, and jump the gap.
        auto visit = [&](int dx, int dy) {
            for (int step = 1; step <= gap_px + 1; ++step) {
                const int nx = x + dx * step, ny = y + dy * step;
                if (nx < 0 || ny < 0 || nx >= w || ny >= h) return;
                const float nz = depth_m.at<float>(ny + roi.y, nx + roi.x);
                if (nz <= 0.0f) continue;  // no data: try one further
                const int nidx = ny * w + nx;
                if (visited_[nidx] || nz < zmin || nz > zmax || std::fabs(nz - z) >= jump * static_cast<float>(step)) {
                    return;
                }
                visited_[nidx] = 1;
                queue_.push_back(nidx);
                return;
            }
        };
        visit(-1, 0);
        visit(1, 0);
        visit(0, -1);
        visit(0, 1);
    }
    if (queue_.empty()) return fail("no pixel of the face box is at the face's depth");

    // Per-row widths of R (eq. 3.9-3.10 count pixels per row).
    row_count_.assign(static_cast<size_t>(h), 0);
    for (int idx : queue_) {
        const int y = idx / w;
        ++row_count_[static_cast<size_t>(y)];
    }
    int top = 0, bottom = h - 1;
    while (top < h && row_count_[static_cast<size_t>(top)] == 0) ++top;
    while (bottom > top && row_count_[static_cast<size_t>(bottom)] == 0) --bottom;

    // Eq. 3.7-3.13: the head/torso line, searched only where the head would have a plausible height.
    int cut = bottom;
    const int h_min_px = static_cast<int>(params_.head_height_min_m * px_per_m);
    const int h_max_px = static_cast<int>(params_.head_height_max_m * px_per_m);
    const int split = widthCriterionSplit(row_count_, top + h_min_px, top + h_max_px + h_max_px / 2);
    if (split >= 0) {
        long ph = 0, pt = 0;
        int rh = 0, rt = 0;
        for (int y = top; y <= bottom; ++y) {
            const int c = row_count_[static_cast<size_t>(y)];
            (y <= split ? ph : pt) += c;
            (y <= split ? rh : rt) += c > 0;
        }
        const double mu_h = rh ? static_cast<double>(ph) / rh : 0, mu_t = rt ? static_cast<double>(pt) / rt : 0;
        if (rt > 0 && mu_t >= params_.torso_width_ratio * mu_h) {
            // Neck shift: the neck is the narrowest part between the face and the shoulder line, and it is about
            // as wide all along; the head ends where it starts, under the jaw. So: the narrowest (3-row mean)
            // width in the search band, then the highest row of the band whose width is within 15% of it.
            const int shift_px = static_cast<int>(params_.neck_shift_max_m * px_per_m);
            const int from = std::max({top + h_min_px / 2, cv_ - roi.y, split - shift_px, top + 1});
            auto width3 = [&](int y) {
                return (row_count_[static_cast<size_t>(y - 1)] + row_count_[static_cast<size_t>(y)] +
                        row_count_[static_cast<size_t>(y + 1)]) /
                       3.0;
            };
            double narrowest = 1e30;
            for (int y = from; y <= split && y + 1 < h; ++y) narrowest = std::min(narrowest, width3(y));
            cut = split;
            for (int y = from; y <= split && y + 1 < h; ++y) {
                if (width3(y) <= 1.15 * narrowest) {
                    cut = y;
                    break;
                }
            }
            cut = std::min(split, cut + static_cast<int>(params_.chin_margin_m * px_per_m));
            out.split_row = cut + roi.y;
        }
    }

    // Head = R above the cut. Mask, masked depth, extents.
    out.clearImages(depth_m.size());
    out.written_px = roi;
    int umin = w, umax = -1, vmin = h, vmax = -1;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    float z_lo = 1e9f, z_hi = 0;
    for (int idx : queue_) {
        const int y = idx / w, x = idx - y * w;
        if (y > cut) continue;
        const int u = x + roi.x, v = y + roi.y;
        out.mask.at<uchar>(v, u) = 255;
        const float z = depth_m.at<float>(v, u);
        out.depth_m.at<float>(v, u) = z;
        sum += k.backProject(static_cast<float>(u), static_cast<float>(v), z).cast<double>();
        z_lo = std::min(z_lo, z), z_hi = std::max(z_hi, z);
        umin = std::min(umin, u), umax = std::max(umax, u), vmin = std::min(vmin, v), vmax = std::max(vmax, v);
        ++out.pixels;
    }
    if (out.pixels == 0) return fail("the head region is empty after the head/torso split");
    out.head_box_px = cv::Rect(cv::Point(umin, vmin), cv::Point(umax + 1, vmax + 1));
    out.centroid_m = (sum / out.pixels).cast<float>();
    const float z_c = out.centroid_m.z();
    // Extents between the 1st and 99th percentile of columns and rows: a few stray pixels (flying pixels at the
    // silhouette) must not make a head look too wide.
    col_hist_.assign(static_cast<size_t>(w), 0);
    row_hist_.assign(static_cast<size_t>(h), 0);
    for (int idx : queue_) {
        const int y = idx / w;
        if (y > cut) continue;
        ++row_hist_[static_cast<size_t>(y)];
        ++col_hist_[static_cast<size_t>(idx - y * w)];
    }
    out.extent_m = {percentileSpanPx(col_hist_, out.pixels) * z_c / k.fx_px,
                    percentileSpanPx(row_hist_, out.pixels) * z_c / k.fy_px, z_hi - z_lo};
    if (!params_.headSized(out.extent_m)) {
        out.reason = "region at the face is not head-sized (" + sizeText(out.extent_m) + ")";
        return;  // mask kept for inspection; found stays false
    }
    out.found = true;
}

float percentileSpanPx(const std::vector<int>& hist, int pixels) {
    const int lo_n = pixels / 100, hi_n = pixels - pixels / 100;
    int acc = 0, lo = -1, hi = -1;
    for (int i = 0; i < static_cast<int>(hist.size()); ++i) {
        acc += hist[static_cast<size_t>(i)];
        if (lo < 0 && acc > lo_n) lo = i;
        if (hi < 0 && acc >= hi_n) hi = i;
    }
    return static_cast<float>(hi - lo + 1);
}

bool HeadSegmenterParams::headSized(const Eigen::Vector3f& extent_m) const {
    return extent_m.x() >= head_width_min_m && extent_m.x() <= head_width_max_m && extent_m.y() >= head_height_min_m &&
           extent_m.y() <= head_height_max_m;
}

std::string sizeText(const Eigen::Vector3f& extent_m) {
    return metres(extent_m.x()) + " wide, " + metres(extent_m.y()) + " tall";
}

}  // namespace facescan::recon
