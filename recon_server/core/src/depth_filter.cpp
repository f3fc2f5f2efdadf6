#include "recon/depth_filter.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>

#include "recon/parallel.hpp"

namespace facescan::recon {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

bool finitePositive(float z) { return std::isfinite(z) && z > 0.0f; }

// Half-resolution ROI covering every coarse pixel with at least one child in `roi`.
cv::Rect halfRoi(const cv::Rect& roi, const cv::Size& coarse_size) {
    const int x0 = roi.x / 2, y0 = roi.y / 2;
    const int x1 = std::min((roi.x + roi.width + 1) / 2, coarse_size.width);
    const int y1 = std::min((roi.y + roi.height + 1) / 2, coarse_size.height);
    return {x0, y0, std::max(0, x1 - x0), std::max(0, y1 - y0)};
}

// A level whose ROI has fewer pixels than this is computed on the calling thread: handing it to the pool costs more
// than the work (the coarse pyramid levels; on one core every parallelFor is a wake-up and a hand-back).
constexpr int kParallelMinPx = 16384;
constexpr int kStripes = 16;  // fixed stripes of the mask pass (its box is merged in the same order on any core count)

template <class Rows>
void forRows(const cv::Rect& roi, Rows&& rows) {
    if (roi.area() < kParallelMinPx) {
        rows(roi.y, roi.y + roi.height);
    } else {
        parallelFor(roi.y, roi.y + roi.height, rows);
    }
}

// Thesis eq. 4.9 for one pixel: its camera-frame point, NaN where the depth is 0.
cv::Vec3f vertexAt(const Intrinsics& k, int u, int v, float z) {
    if (!(z > 0.0f)) return cv::Vec3f(kNaN, kNaN, kNaN);
    const Eigen::Vector3f p = k.backProject(static_cast<float>(u), static_cast<float>(v), z);
    return cv::Vec3f(p.x(), p.y(), p.z());
}

// Eq. 4.4 at one pixel over the window rows [dv_lo, dv_hi] and columns [du_lo, du_hi] (offsets from the pixel,
// already clipped to the ROI): invalid neighbours (depth 0) and those past the range table's end weigh 0, so no
// tap branches. `space` points at the window's centre weight of eq. 4.5 (rows `side` apart), `range` is eq. 4.6's
// table. The pixels near the ROI's edges (and any radius but the default) take this path; the others go four at a
// time through bilateral4At(), whose lanes sum the same taps in the same order. Always inlined into the row loop: as
// a call (two pixels or more a row) the filter measured about 5 % slower.
[[gnu::always_inline]] inline float bilateralAt(const cv::Mat& masked, int u, int v, float zc, const float* space,
                                                int side, const float* range, float inv_step, int beyond, int dv_lo,
                                                int dv_hi, int du_lo, int du_hi) {
    float sum_w = 0.0f, sum_wz = 0.0f;
    for (int dv = dv_lo; dv <= dv_hi; ++dv) {
        const float* row = masked.ptr<float>(v + dv) + u;
        const float* space_row = space + dv * side;
        for (int du = du_lo; du <= du_hi; ++du) {
            const float z = row[du];
            const int idx = std::min(static_cast<int>(std::fabs(z - zc) * inv_step + 0.5f), beyond);
            const float wgt = z > 0.0f ? space_row[du] * range[idx] : 0.0f;
            sum_w += wgt;
            sum_wz += wgt * z;
        }
    }
    return sum_wz / sum_w;  // sum_w >= 1 (the centre pixel)
}

// Four neighbouring pixels u..u+3 of row v at once, each over its whole 5x5 window (the caller checks that the
// windows lie inside the ROI): the same taps as bilateralAt() over a whole window, summed in the same order, one
// lane per pixel (GCC/clang vector extensions: SIMD on any target without intrinsics; without FMA nothing is fused,
// as in the scalar form), so each lane is bit-identical to bilateralAt(). The table look-up stays four scalar loads
// but the subtraction, scaling, conversion and sums run 4 wide: the filter is the second largest cost of a frame.
// Lanes whose centre is invalid are computed (sum_w may be 0) and discarded by the caller.
using Float4 = float __attribute__((vector_size(16)));
using Int4 = int32_t __attribute__((vector_size(16)));

inline Float4 loadFloat4(const float* p) {
    Float4 x;
    std::memcpy(&x, p, sizeof x);
    return x;
}

inline Float4 bilateral4At(const cv::Mat& masked, int u, int v, const float* space, const float* range, float inv_step,
                           int beyond) {
    const Float4 zc = loadFloat4(masked.ptr<float>(v) + u);
    const Int4 abs_bits = {0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff};
    Float4 sum_w = {0.0f, 0.0f, 0.0f, 0.0f}, sum_wz = sum_w;
    for (int dv = -2; dv <= 2; ++dv) {
        const float* row = masked.ptr<float>(v + dv) + u;
        const float* space_row = space + dv * 5;
        for (int du = -2; du <= 2; ++du) {
            const Float4 z = loadFloat4(row + du);
            const Float4 dz = z - zc;
            const Float4 abs_dz = reinterpret_cast<Float4>(reinterpret_cast<Int4>(dz) & abs_bits);  // fabs
            Int4 idx = __builtin_convertvector(abs_dz * inv_step + 0.5f, Int4);  // truncates, like static_cast
            idx = idx < beyond ? idx : beyond;
            const Float4 r = {range[idx[0]], range[idx[1]], range[idx[2]], range[idx[3]]};
            const Float4 wgt = reinterpret_cast<Float4>(reinterpret_cast<Int4>(space_row[du] * r) & (z > 0.0f));
            sum_w += wgt;
            sum_wz += wgt * z;
        }
    }
    return sum_wz / sum_w;
}

}  // namespace

Status FilterParams::validate() const {
    if (!(sigma_space_px > 0.0f) || !(sigma_depth_m > 0.0f)) return invalidArgument("filter sigmas must be > 0");
    if (radius_px < 0 || radius_px > 4) return invalidArgument("filter radius_px must be in [0, 4]");
    if (levels < 1 || levels > kMaxPyramidLevels) return invalidArgument("filter levels must be in [1, 4]");
    if (!(pyramid_max_step_m > 0.0f)) return invalidArgument("pyramid_max_step_m must be > 0");
    if (!(min_depth_m >= 0.0f) || !(max_depth_m > min_depth_m)) return invalidArgument("bad depth range");
    return Status::ok();
}

void SurfacePyramid::allocate(const Intrinsics& k, int level_count) {
    count = std::clamp(level_count, 1, kMaxPyramidLevels);
    for (int l = 0; l < count; ++l) {
        SurfaceLevel& lv = levels[l];
        lv.k = k.scaled(l);
        lv.depth_m.create(lv.k.height_px, lv.k.width_px, CV_32FC1);
        lv.vertex.create(lv.k.height_px, lv.k.width_px, CV_32FC3);
        lv.normal.create(lv.k.height_px, lv.k.width_px, CV_32FC3);
        lv.depth_m.setTo(0.0f);
        lv.vertex.setTo(cv::Scalar::all(kNaN));
        lv.normal.setTo(cv::Scalar::all(kNaN));
        lv.roi = cv::Rect();
    }
}

DepthFilter::DepthFilter(const Intrinsics& k, const FilterParams& p) : k_(k), params_(p) {
    masked_.create(k.height_px, k.width_px, CV_32FC1);
    masked_.setTo(0.0f);
    // Eq. 4.5 depends only on the squared pixel distance; eq. 4.6 on |dz|, tabulated up to 3 sigma (beyond it the
    // weight is below 1.1 %, and cutting it there keeps foreground and background apart).
    const int side = 2 * p.radius_px + 1;
    space_weight_.assign(static_cast<size_t>(side * side), 0.0f);
    for (int dv = -p.radius_px; dv <= p.radius_px; ++dv) {
        for (int du = -p.radius_px; du <= p.radius_px; ++du) {
            space_weight_[static_cast<size_t>((dv + p.radius_px) * side + du + p.radius_px)] =
                std::exp(-static_cast<float>(du * du + dv * dv) / (2.0f * p.sigma_space_px * p.sigma_space_px));
        }
    }
    // kRangeSteps entries up to 3 sigma, then one 0: the filter clamps its index to it (no branch per tap).
    range_step_m_ = 3.0f * p.sigma_depth_m / static_cast<float>(kRangeSteps - 1);
    range_lut_[kRangeSteps] = 0.0f;
    for (size_t i = 0; i < kRangeSteps; ++i) {
        const float dz = static_cast<float>(i) * range_step_m_;
        range_lut_[i] = std::exp(-dz * dz / (2.0f * p.sigma_depth_m * p.sigma_depth_m));
    }
}

int DepthFilter::filter(const cv::Mat& depth_m, const cv::Mat& mask, SurfacePyramid& out, const cv::Rect& mask_box,
                        int normals_from_level) {
    const FilterParams& p = params_;
    const int w = k_.width_px, h = k_.height_px;
    // Mask, range-check and find the head's box in one pass, over fixed stripes of rows (a third of the filter's
    // time ran on one core here: 307k pixels a frame); each stripe's box is merged afterwards. Only the mask's box
    // is swept: everything below reads masked_ inside the ROI found here, which lies inside that box (a tracked
    // head's box is a fifth of the frame or less; the whole-frame sweep was 3 % of a four-session server's CPU).
    const cv::Rect sweep = mask_box.empty() ? cv::Rect(0, 0, w, h) : mask_box & cv::Rect(0, 0, w, h);
    struct Box {
        int x_min, x_max, y_min, y_max;
    };
    std::array<Box, kStripes> boxes;
    parallelFor(0, kStripes, [&](int s_lo, int s_hi) {
        for (int s = s_lo; s < s_hi; ++s) {
            Box b{w, -1, h, -1};
            for (int v = sweep.y + sweep.height * s / kStripes; v < sweep.y + sweep.height * (s + 1) / kStripes; ++v) {
                const float* src = depth_m.ptr<float>(v);
                const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(v);
                float* dst = masked_.ptr<float>(v);
                int row_min = w, row_max = -1;
                for (int u = sweep.x; u < sweep.x + sweep.width; ++u) {
                    const float z = src[u];
                    const bool keep =
                        (m == nullptr || m[u] != 0) && finitePositive(z) && z >= p.min_depth_m && z <= p.max_depth_m;
                    dst[u] = keep ? z : 0.0f;
                    if (keep) {
                        row_min = std::min(row_min, u);
                        row_max = u;
                    }
                }
                if (row_max < 0) continue;
                b.x_min = std::min(b.x_min, row_min);
                b.x_max = std::max(b.x_max, row_max);
                b.y_min = std::min(b.y_min, v);
                b.y_max = v;
            }
            boxes[static_cast<size_t>(s)] = b;
        }
    });
    int x_min = w, x_max = -1, y_min = h, y_max = -1;
    for (const Box& b : boxes) {
        x_min = std::min(x_min, b.x_min), x_max = std::max(x_max, b.x_max);
        y_min = std::min(y_min, b.y_min), y_max = std::max(y_max, b.y_max);
    }
    for (int l = 0; l < out.count; ++l) out.levels[l].roi = cv::Rect();
    if (x_max < 0) return 0;
    const cv::Rect roi(x_min, y_min, x_max - x_min + 1, y_max - y_min + 1);

    // Bilateral filter, eq. 4.4: invalid pixels stay invalid and never contribute. The window is clipped to the ROI
    // once per pixel, and a tap's weight is space(du, dv) * range(|dz|) with range 0 past the table's end (3 sigma)
    // and for invalid neighbours (depth 0): no branch per tap.
    SurfaceLevel& l0 = out.levels[0];
    l0.roi = roi;
    const int radius = p.radius_px;
    const int side = 2 * radius + 1;
    const float inv_step = 1.0f / range_step_m_;
    constexpr int kBeyond = static_cast<int>(kRangeSteps);  // index of the table's trailing 0
    const float* space = &space_weight_[static_cast<size_t>(radius * side + radius)];  // the window's centre
    // The level's vertex map (eq. 4.9) and the count of valid pixels come out of the same pass.
    std::atomic<int> valid{0};
    parallelFor(roi.y, roi.y + roi.height, [&](int v_lo, int v_hi) {
        int valid_here = 0;
        for (int v = v_lo; v < v_hi; ++v) {
            float* dst = l0.depth_m.ptr<float>(v);
            auto* vertex = l0.vertex.ptr<cv::Vec3f>(v);
            const float* centre_row = masked_.ptr<float>(v);
            const int dv_lo = std::max(-radius, roi.y - v), dv_hi = std::min(radius, roi.y + roi.height - 1 - v);
            // One output pixel: the filtered depth and its vertex, or invalid where the centre has no depth.
            auto put = [&](int u, float z_filtered) {
                if (centre_row[u] <= 0.0f) {
                    dst[u] = 0.0f;
                    vertex[u] = cv::Vec3f(kNaN, kNaN, kNaN);
                    return;
                }
                dst[u] = z_filtered;
                vertex[u] = vertexAt(l0.k, u, v, z_filtered);
                ++valid_here;
            };
            // Pixels u..u+3 go through bilateral4At() when all four windows lie inside the ROI (the default radius).
            const bool rows_inside = radius == 2 && dv_lo == -2 && dv_hi == 2;
            const int u_quad_end = roi.x + roi.width - 2 - 3;  // a quad at u needs u + 3 + 2 inside
            for (int u = roi.x; u < roi.x + roi.width; ++u) {
                if (rows_inside && u - 2 >= roi.x && u < u_quad_end) {
                    const Float4 z4 = bilateral4At(masked_, u, v, space, range_lut_.data(), inv_step, kBeyond);
                    for (int i = 0; i < 4; ++i) put(u + i, z4[i]);
                    u += 3;  // and the loop's ++u
                    continue;
                }
                if (centre_row[u] <= 0.0f) {
                    put(u, 0.0f);
                    continue;
                }
                const int du_lo = std::max(-radius, roi.x - u), du_hi = std::min(radius, roi.x + roi.width - 1 - u);
                put(u, bilateralAt(masked_, u, v, centre_row[u], space, side, range_lut_.data(), inv_step, kBeyond,
                                   dv_lo, dv_hi, du_lo, du_hi));
            }
        }
        valid.fetch_add(valid_here, std::memory_order_relaxed);
    });

    // Coarser levels: mean of the valid 2x2 children close in depth to the first valid one.
    for (int l = 1; l < out.count; ++l) {
        const SurfaceLevel& fine = out.levels[l - 1];
        SurfaceLevel& coarse = out.levels[l];
        coarse.roi = halfRoi(fine.roi, coarse.depth_m.size());
        forRows(coarse.roi, [&](int v_lo, int v_hi) {
            for (int v = v_lo; v < v_hi; ++v) {
                float* dst = coarse.depth_m.ptr<float>(v);
                for (int u = coarse.roi.x; u < coarse.roi.x + coarse.roi.width; ++u) {
                    float ref = 0.0f, sum = 0.0f;
                    int n = 0;
                    for (int dy = 0; dy < 2; ++dy) {
                        const int fv = 2 * v + dy;
                        if (fv < fine.roi.y || fv >= fine.roi.y + fine.roi.height) continue;
                        const float* src = fine.depth_m.ptr<float>(fv);
                        for (int dx = 0; dx < 2; ++dx) {
                            const int fu = 2 * u + dx;
                            if (fu < fine.roi.x || fu >= fine.roi.x + fine.roi.width) continue;
                            const float z = src[fu];
                            if (z <= 0.0f) continue;
                            if (n == 0) ref = z;
                            if (std::fabs(z - ref) > p.pyramid_max_step_m) continue;
                            sum += z;
                            ++n;
                        }
                    }
                    dst[u] = n > 0 ? sum / static_cast<float>(n) : 0.0f;
                }
            }
        });
    }

    for (int l = 0; l < out.count; ++l) {
        SurfaceLevel& lv = out.levels[l];
        if (l > 0) computeVertexMap(lv.k, lv.depth_m, lv.roi, lv.vertex);  // level 0's came with the filter
        if (l >= normals_from_level) computeNormals(lv);
    }
    return valid.load();
}

void DepthFilter::computeNormals(SurfaceLevel& level) const {
    computeNormalMap(level.vertex, level.roi, params_.pyramid_max_step_m, level.normal);
}

int validCentroid(const SurfaceLevel& lv, Eigen::Vector3f& centroid) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int n = 0;
    for (int v = lv.roi.y; v < lv.roi.y + lv.roi.height; ++v) {
        const auto* row = lv.vertex.ptr<cv::Vec3f>(v);
        for (int u = lv.roi.x; u < lv.roi.x + lv.roi.width; ++u) {
            if (std::isnan(row[u][0])) continue;
            sum += Eigen::Vector3d(row[u][0], row[u][1], row[u][2]);
            ++n;
        }
    }
    if (n > 0) centroid = (sum / static_cast<double>(n)).cast<float>();
    return n;
}

void computeVertexMap(const Intrinsics& k, const cv::Mat& depth_m, const cv::Rect& roi, cv::Mat& vertex) {
    forRows(roi, [&](int v_lo, int v_hi) {
        for (int v = v_lo; v < v_hi; ++v) {
            const float* z = depth_m.ptr<float>(v);
            auto* dst = vertex.ptr<cv::Vec3f>(v);
            for (int u = roi.x; u < roi.x + roi.width; ++u) dst[u] = vertexAt(k, u, v, z[u]);
        }
    });
}

void computeNormalMap(const cv::Mat& vertex, const cv::Rect& roi, float max_step_m, cv::Mat& normal) {
    const float max_step2 = max_step_m * max_step_m;
    forRows(roi, [&](int v_lo, int v_hi) {
        for (int v = v_lo; v < v_hi; ++v) {
            const auto* row = vertex.ptr<cv::Vec3f>(v);
            const bool has_next_row = v + 1 < roi.y + roi.height;
            const auto* next = has_next_row ? vertex.ptr<cv::Vec3f>(v + 1) : nullptr;
            auto* dst = normal.ptr<cv::Vec3f>(v);
            for (int u = roi.x; u < roi.x + roi.width; ++u) {
                dst[u] = cv::Vec3f(kNaN, kNaN, kNaN);
                if (!has_next_row || u + 1 >= roi.x + roi.width) continue;
                const cv::Vec3f& p = row[u];
                const cv::Vec3f& pu = row[u + 1];
                const cv::Vec3f& pv = next[u];
                if (std::isnan(p[0]) || std::isnan(pu[0]) || std::isnan(pv[0])) continue;
                const cv::Vec3f du = pu - p, dv = pv - p;
                if (du.dot(du) > max_step2 || dv.dot(dv) > max_step2) continue;
                cv::Vec3f n = du.cross(dv);  // eq. 4.10
                const float len = std::sqrt(n.dot(n));
                if (!(len > 0.0f)) continue;
                n *= (n.dot(p) > 0.0f ? -1.0f : 1.0f) / len;  // face the camera
                dst[u] = n;
            }
        }
    });
}

namespace {

void downsampleMap(const cv::Mat& src, const cv::Rect& src_roi, cv::Mat& dst, cv::Rect& dst_roi, bool normalise) {
    dst_roi = halfRoi(src_roi, dst.size());
    forRows(dst_roi, [&](int v_lo, int v_hi) {
        for (int v = v_lo; v < v_hi; ++v) {
            auto* out = dst.ptr<cv::Vec3f>(v);
            for (int u = dst_roi.x; u < dst_roi.x + dst_roi.width; ++u) {
                cv::Vec3f sum(0, 0, 0);
                bool all = true;
                for (int dy = 0; dy < 2 && all; ++dy) {
                    const int sv = 2 * v + dy;
                    if (sv >= src.rows) {
                        all = false;
                        break;
                    }
                    const auto* in = src.ptr<cv::Vec3f>(sv);
                    for (int dx = 0; dx < 2; ++dx) {
                        const int su = 2 * u + dx;
                        if (su >= src.cols || !src_roi.contains({su, sv}) || std::isnan(in[su][0])) {
                            all = false;
                            break;
                        }
                        sum += in[su];
                    }
                }
                // All four children, or none: mixing a silhouette's two sides would invent points in mid-air.
                if (!all) {
                    out[u] = cv::Vec3f(kNaN, kNaN, kNaN);
                    continue;
                }
                if (normalise) {
                    const float len = std::sqrt(sum.dot(sum));
                    out[u] = len > 0.0f ? sum / len : cv::Vec3f(kNaN, kNaN, kNaN);
                } else {
                    out[u] = sum * 0.25f;
                }
            }
        }
    });
}

}  // namespace

void downsampleVertexMap(const cv::Mat& src, const cv::Rect& src_roi, cv::Mat& dst, cv::Rect& dst_roi) {
    downsampleMap(src, src_roi, dst, dst_roi, false);
}
void downsampleNormalMap(const cv::Mat& src, const cv::Rect& src_roi, cv::Mat& dst, cv::Rect& dst_roi) {
    downsampleMap(src, src_roi, dst, dst_roi, true);
}

}  // namespace facescan::recon
