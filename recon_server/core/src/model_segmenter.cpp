#include "recon/model_segmenter.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "recon/parallel.hpp"

namespace facescan::recon {
Status HeadRegionParams::validate() const {
    if (!(radius_m > 0.05f)) return invalidArgument("head region radius_m must be > 0.05");
    if (!(centre_behind_m >= 0.0f && below_lowest_m >= 0.0f && max_below_centre_m > 0.0f))
        return invalidArgument("head region distances must be >= 0 (max_below_centre_m > 0)");
    return Status::ok();
}

bool HeadRegion::fromFirstFrame(const SurfaceLevel& lv, const HeadRegionParams& p, HeadRegion& out,
                                const Eigen::Vector3f& down_camera) {
    Eigen::Vector3f centroid;
    if (validCentroid(lv, centroid) == 0) return false;
    out.centre_world = centroid + centroid.normalized() * p.centre_behind_m;
    out.down_world = down_camera;
    float lowest = -1e9f;
    for (int v = lv.roi.y; v < lv.roi.y + lv.roi.height; ++v) {
        const auto* row = lv.vertex.ptr<cv::Vec3f>(v);
        for (int u = lv.roi.x; u < lv.roi.x + lv.roi.width; ++u) {
            if (std::isnan(row[u][0])) continue;
            const Eigen::Vector3f d(row[u][0] - out.centre_world.x(), row[u][1] - out.centre_world.y(),
                                    row[u][2] - out.centre_world.z());
            lowest = std::max(lowest, d.dot(out.down_world));
        }
    }
    out.below_centre_m = std::min(lowest + p.below_lowest_m, p.max_below_centre_m);
    out.radius_m = p.radius_m;
    out.centre_behind_m = p.centre_behind_m;
    out.valid = true;
    return true;
}

Status ModelSegmenterParams::validate() const {
    if (!(seed_margin_m > 0.0f && grow_jump_m > 0.0f && band_m >= 0.0f))
        return invalidArgument("model segmenter margins must be > 0 (band_m >= 0)");
    if (min_pixels < 1) return invalidArgument("model segmenter min_pixels must be >= 1");
    if (!(min_seed_share >= 0.0f && min_seed_share <= 1.0f))
        return invalidArgument("model segmenter min_seed_share must be in [0, 1]");
    return Status::ok();
}

void ModelSegmenter::segment(const cv::Mat& depth_m, const Intrinsics& k, const HeadPrediction& prediction,
                             const HeadSegmenterParams& limits, HeadSegmentation& out) {
    out.found = false;
    out.reason.clear();
    out.pixels = 0;
    out.split_row = -1;
    out.head_box_px = {};
    seeds_ = 0;
    if (const char* problem = depthInputProblem(depth_m, k)) return out.markNotFound(depth_m, problem);
    // The model may be cast at a coarser pyramid level (ReconParams::model_level): its pixel (u >> s, v >> s)
    // predicts the depth pixel (u, v); shift = s.
    const int shift = prediction.model != nullptr
                          ? pyramidLevelOfWidth(depth_m.cols, prediction.model->k.width_px, kMaxPyramidLevels)
                          : 0;
    if (prediction.model == nullptr || prediction.model->roi.empty() || !prediction.region.valid ||
        (prediction.model->k.width_px << shift) != depth_m.cols ||
        (prediction.model->k.height_px << shift) != depth_m.rows ||
        prediction.model->vertex.rows < prediction.model->k.height_px ||
        prediction.model->vertex.cols < prediction.model->k.width_px) {
        return out.markNotFound(depth_m, "no model prediction");
    }
    const int w = depth_m.cols, h = depth_m.rows;
    const cv::Rect bounds(0, 0, w, h);
    // Outputs of our own, reused every frame: only the area written last time (out.written_px) is cleared, by hand
    // (cv::Mat::setTo allocates on every call in OpenCV 4.6; see HeadSegmentation::clearImages).
    out.clearImages(depth_m.size());
    state_.create(depth_m.size(), CV_8UC1);

    const SurfaceLevel& model = *prediction.model;
    const cv::Rect roi_m =
        cv::Rect(model.roi.x << shift, model.roi.y << shift, model.roi.width << shift, model.roi.height << shift) &
        bounds;
    const Pose T_camera_world = prediction.T_world_camera.inverse();
    const Pose& T_world_camera = prediction.T_world_camera;
    const HeadRegion& region = prediction.region;
    const float zmin = limits.min_depth_m, zmax = limits.max_depth_m, margin = params_.seed_margin_m;

    // 1. Seeds: measured depth within the margin of the predicted surface, inside the head region. Parallel over
    //    fixed stripes of rows; each stripe keeps its own counts and box (summed in order afterwards).
    struct Partial {
        int predicted = 0, seeds = 0, u0 = 1 << 30, v0 = 1 << 30, u1 = -1, v1 = -1;
        double z_sum = 0;
    };
    std::array<Partial, kStripes> partial{};
    for (int v = roi_m.y; v < roi_m.br().y; ++v) std::fill_n(state_.ptr<uint8_t>(v) + roi_m.x, roi_m.width, uint8_t{0});
    parallelFor(0, kStripes, [&](int s_lo, int s_hi) {
        for (int s = s_lo; s < s_hi; ++s) {
            Partial acc;
            const int v_begin = roi_m.y + roi_m.height * s / kStripes;
            const int v_end = roi_m.y + roi_m.height * (s + 1) / kStripes;
            for (int v = v_begin; v < v_end; ++v) {
                const auto* vert_row = model.vertex.ptr<cv::Vec3f>(v >> shift);
                const float* z = depth_m.ptr<float>(v);
                uint8_t* st = state_.ptr<uint8_t>(v);
                for (int u = roi_m.x; u < roi_m.x + roi_m.width; ++u) {
                    const cv::Vec3f& vert = vert_row[u >> shift];
                    if (std::isnan(vert[0])) continue;
                    const Eigen::Vector3f p_cam = T_camera_world * Eigen::Vector3f(vert[0], vert[1], vert[2]);
                    ++acc.predicted;
                    acc.z_sum += p_cam.z();
                    acc.u0 = std::min(acc.u0, u), acc.u1 = std::max(acc.u1, u);
                    acc.v0 = std::min(acc.v0, v), acc.v1 = std::max(acc.v1, v);
                    const float zu = z[u];
                    if (!(zu >= zmin && zu <= zmax) || std::fabs(zu - p_cam.z()) > margin) continue;
                    if (!region.contains(T_world_camera *
                                         k.backProject(static_cast<float>(u), static_cast<float>(v), zu)))
                        continue;
                    st[u] = 1;
                    ++acc.seeds;
                }
            }
            partial[static_cast<size_t>(s)] = acc;
        }
    });
    Partial all;
    for (const Partial& p : partial) {
        all.predicted += p.predicted, all.seeds += p.seeds, all.z_sum += p.z_sum;
        all.u0 = std::min(all.u0, p.u0), all.v0 = std::min(all.v0, p.v0);
        all.u1 = std::max(all.u1, p.u1), all.v1 = std::max(all.v1, p.v1);
    }
    seeds_ = all.seeds;
    if (all.predicted == 0) return out.markNotFound(depth_m, "the model predicts no head surface in view");
    if (all.seeds < params_.min_seed_share * static_cast<float>(all.predicted) || all.seeds == 0) {
        return out.markNotFound(depth_m, "the head is not where the tracked model predicts it");
    }

    // 2. Growth (Algorithm 1's depth-continuity test) from the seeds, inside the predicted box widened by the band
    //    and inside the head region.
    const float z_ref = static_cast<float>(all.z_sum / all.predicted);
    const int band_px = static_cast<int>(params_.band_m * k.fx_px / z_ref);
    const cv::Rect grow_roi =
        cv::Rect(cv::Point(all.u0 - band_px, all.v0 - band_px), cv::Point(all.u1 + band_px + 1, all.v1 + band_px + 1)) &
        bounds;
    // state_ is 0 on the band outside roi_m from earlier frames' growth only where cleared: clear the rest.
    for (int v = grow_roi.y; v < grow_roi.y + grow_roi.height; ++v) {
        uint8_t* st = state_.ptr<uint8_t>(v);
        for (int u = grow_roi.x; u < grow_roi.x + grow_roi.width; ++u) {
            if (!roi_m.contains({u, v})) st[u] = 0;
        }
    }
    // Growth starts from the seeds that have an untouched neighbour in the box: a seed whose four neighbours are
    // all seeds adds nothing, and those were most of the head (a serial pass of 4 reads each over every head
    // pixel). Found in parallel, per stripe of rows, and queued in stripe order.
    const int box_rows = all.v1 - all.v0 + 1;
    const auto untouched = [&](int u, int v) { return grow_roi.contains({u, v}) && state_.ptr<uint8_t>(v)[u] == 0; };
    parallelFor(0, kStripes, [&](int s_lo, int s_hi) {
        for (int s = s_lo; s < s_hi; ++s) {
            std::vector<int>& frontier = frontier_[static_cast<size_t>(s)];
            frontier.clear();
            // Room for every pixel of the stripe's rows (at most ceil(h / kStripes)): no allocation after the first
            // call, however the head's outline changes.
            frontier.reserve(static_cast<size_t>((h + kStripes - 1) / kStripes) * static_cast<size_t>(w));
            for (int v = all.v0 + box_rows * s / kStripes; v < all.v0 + box_rows * (s + 1) / kStripes; ++v) {
                const uint8_t* st = state_.ptr<uint8_t>(v);
                for (int u = all.u0; u <= all.u1; ++u) {
                    if (st[u] == 1 &&
                        (untouched(u - 1, v) || untouched(u + 1, v) || untouched(u, v - 1) || untouched(u, v + 1)))
                        frontier.push_back(v * w + u);
                }
            }
        }
    });
    queue_.clear();
    queue_.reserve(static_cast<size_t>(w) * static_cast<size_t>(h));  // no-op after the first frame
    for (const std::vector<int>& f : frontier_) queue_.insert(queue_.end(), f.begin(), f.end());
    const float jump = params_.grow_jump_m;
    int head_pixels = all.seeds;
    for (size_t head = 0; head < queue_.size(); ++head) {
        const int idx = queue_[head];
        const int y = idx / w, x = idx - y * w;
        const float z = depth_m.ptr<float>(y)[x];
        const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
        for (int n = 0; n < 4; ++n) {
            if (!grow_roi.contains({nx[n], ny[n]})) continue;
            uint8_t& st = state_.ptr<uint8_t>(ny[n])[nx[n]];
            if (st) continue;
            const float nz = depth_m.ptr<float>(ny[n])[nx[n]];
            if (!(nz >= zmin && nz <= zmax) || std::fabs(nz - z) >= jump) continue;
            // Tried either way: a pixel outside the region is not tried again from another side.
            if (!region.contains(T_world_camera *
                                 k.backProject(static_cast<float>(nx[n]), static_cast<float>(ny[n]), nz))) {
                st = 2;
                continue;
            }
            st = 1;
            ++head_pixels;
            queue_.push_back(ny[n] * w + nx[n]);
        }
    }

    // 3. Mask, masked depth, box, centroid and extents (as HeadSegmenter reports them), in parallel over stripes of
    //    the growth's box; each stripe keeps its own sums and column counts (merged in order afterwards).
    if (head_pixels < params_.min_pixels) {
        return out.markNotFound(depth_m, "too few head pixels confirm the tracked model");
    }
    struct Summary {
        int umin, umax, vmin, vmax;
        float z_lo, z_hi;
        Eigen::Vector3d sum;
    };
    std::array<Summary, kStripes> summary;
    row_hist_.assign(static_cast<size_t>(h), 0);
    parallelFor(0, kStripes, [&](int s_lo, int s_hi) {
        for (int s = s_lo; s < s_hi; ++s) {
            Summary acc{w, -1, h, -1, 1e9f, 0.0f, Eigen::Vector3d::Zero()};
            std::vector<int>& cols = stripe_cols_[static_cast<size_t>(s)];
            cols.assign(static_cast<size_t>(w), 0);
            const int v_begin = grow_roi.y + grow_roi.height * s / kStripes;
            const int v_end = grow_roi.y + grow_roi.height * (s + 1) / kStripes;
            for (int v = v_begin; v < v_end; ++v) {
                const uint8_t* st = state_.ptr<uint8_t>(v);
                const float* zrow = depth_m.ptr<float>(v);
                uint8_t* mask = out.mask.ptr<uint8_t>(v);
                float* masked = out.depth_m.ptr<float>(v);
                int in_row = 0;
                for (int u = grow_roi.x; u < grow_roi.br().x; ++u) {
                    if (st[u] != 1) continue;
                    const float z = zrow[u];
                    mask[u] = 255;
                    masked[u] = z;
                    acc.sum += k.backProject(static_cast<float>(u), static_cast<float>(v), z).cast<double>();
                    acc.z_lo = std::min(acc.z_lo, z), acc.z_hi = std::max(acc.z_hi, z);
                    acc.umin = std::min(acc.umin, u), acc.umax = std::max(acc.umax, u);
                    ++cols[static_cast<size_t>(u)];
                    ++in_row;
                }
                if (in_row == 0) continue;
                row_hist_[static_cast<size_t>(v)] = in_row;
                acc.vmin = std::min(acc.vmin, v), acc.vmax = v;
            }
            summary[static_cast<size_t>(s)] = acc;
        }
    });
    col_hist_.assign(static_cast<size_t>(w), 0);
    int umin = w, umax = -1, vmin = h, vmax = -1;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    float z_lo = 1e9f, z_hi = 0;
    for (int s = 0; s < kStripes; ++s) {
        const Summary& acc = summary[static_cast<size_t>(s)];
        umin = std::min(umin, acc.umin), umax = std::max(umax, acc.umax);
        vmin = std::min(vmin, acc.vmin), vmax = std::max(vmax, acc.vmax);
        z_lo = std::min(z_lo, acc.z_lo), z_hi = std::max(z_hi, acc.z_hi);
        sum += acc.sum;
        const std::vector<int>& cols = stripe_cols_[static_cast<size_t>(s)];
        for (int u = acc.umin; u <= acc.umax; ++u) col_hist_[static_cast<size_t>(u)] += cols[static_cast<size_t>(u)];
    }
    out.pixels = head_pixels;
    out.head_box_px = cv::Rect(cv::Point(umin, vmin), cv::Point(umax + 1, vmax + 1));
    out.written_px = out.head_box_px;
    out.centroid_m = (sum / out.pixels).cast<float>();
    out.depth_median_m = out.centroid_m.z();
    const float z_c = out.centroid_m.z();
    out.extent_m = {percentileSpanPx(col_hist_, out.pixels) * z_c / k.fx_px,
                    percentileSpanPx(row_hist_, out.pixels) * z_c / k.fy_px, z_hi - z_lo};
    if (!limits.headSized(out.extent_m)) {
        out.reason = "the tracked head region is not head-sized (" + sizeText(out.extent_m) + ")";
        return;
    }
    out.found = true;
}

}  // namespace facescan::recon
