#include "recon/icp.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "recon/parallel.hpp"

namespace facescan::recon {
namespace {

constexpr int kStripes = 16;  // fixed stripe count: the reduction sums in the same order on any core count
constexpr double kDegToRad = M_PI / 180.0;
constexpr float kMaxPixel = 1 << 20;  // pixels; beyond any image

// One pair's row a (weight w, right-hand side b) into the normal equations of N unknowns, 6 (the pose) or 7 (and
// the model's offset): the upper triangle of A^T A, then A^T b (eq. 4.20). Fully unrolled (straight-line
// multiply-adds): this is the loop's hottest part.
template <int N, size_t Size>
inline void accumulatePair(std::array<double, Size>& acc, const double* a, double w, double b) {
    constexpr int kRhs = N * (N + 1) / 2;
    int k = 0;
#pragma GCC unroll 7
    for (int i = 0; i < N; ++i) {
        const double wai = w * a[i];
#pragma GCC unroll 7
        for (int j = i; j < N; ++j) acc[k++] += wai * a[j];  // A^T A, upper (eq. 4.20)
        acc[kRhs + i] += wai * b;                            // A^T b
    }
}

// Rigid transform of the ICP unknowns x = [alpha beta gamma tx ty tz] (eq. 4.16). The rotation is built exactly
// from the angles (eq. 4.2) rather than from the small-angle matrix of eq. 4.14, which is only used to linearise:
// the estimate stays a proper rotation after many updates.
Pose incrementFromX(const Eigen::Matrix<double, 6, 1>& x) {
    const Eigen::Matrix3d r =
        (Eigen::AngleAxisd(x[2], Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(x[1], Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(x[0], Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
    Pose t = Pose::Identity();
    t.linear() = r.cast<float>();
    t.translation() = x.tail<3>().cast<float>();
    return t;
}

float rotationDeg(const Pose& t) {
    const float c = std::clamp((t.linear().trace() - 1.0f) * 0.5f, -1.0f, 1.0f);
    return std::acos(c) * static_cast<float>(180.0 / M_PI);
}

}  // namespace

const char* trackingStatusName(TrackingStatus s) {
    switch (s) {
        case TrackingStatus::kFirstFrame: return "first_frame";
        case TrackingStatus::kTracked: return "tracked";
        case TrackingStatus::kNotEnoughPoints: return "not_enough_points";
        case TrackingStatus::kDiverged: return "diverged";
        case TrackingStatus::kLargeMotion: return "large_motion";
        case TrackingStatus::kNoHead: return "no_head";
        case TrackingStatus::kInvalidInput: return "invalid_input";
        case TrackingStatus::kUnverified: return "unverified";
    }
    return "unknown";
}

Status IcpParams::validate() const {
    if (levels < 1 || levels > kMaxPyramidLevels) return invalidArgument("icp levels must be in [1, 4]");
    for (int l = 0; l < levels; ++l) {
        if (iterations[l] < 0 || iterations[l] > 100) return invalidArgument("icp iterations must be in [0, 100]");
        if (!(dist_gate_m[l] > 0.0f)) return invalidArgument("icp dist_gate_m must be > 0");
        if (!(normal_gate_deg[l] > 0.0f && normal_gate_deg[l] <= 90.0f))
            return invalidArgument("icp normal_gate_deg must be in (0, 90]");
    }
    if (iterations[0] < 1) return invalidArgument("icp needs at least one iteration at the finest level");
    if (!(huber_m >= 0.0f)) return invalidArgument("icp huber_m must be >= 0");
    if (finest_stride_px < 1 || finest_stride_px > 8) return invalidArgument("icp finest_stride_px must be in [1, 8]");
    if (!(convergence_rel >= 0.0f) || !(convergence_step_m >= 0.0f))
        return invalidArgument("icp convergence thresholds must be >= 0");
    if (!(confident_model_weight >= 0.0f) || !std::isfinite(confident_model_weight))
        return invalidArgument("icp confident_model_weight must be >= 0 and finite (0: every pair alike)");
    if (min_inliers < 6) return invalidArgument("icp min_inliers must be >= 6 (six unknowns)");
    if (!std::isfinite(model_offset_ridge))
        return invalidArgument("icp model_offset_ridge must be finite (negative: no offset unknown)");
    if (!(min_inlier_share >= 0.0f && min_inlier_share <= 1.0f))
        return invalidArgument("icp min_inlier_share must be in [0, 1]");
    if (!(max_rmse_m > 0.0f) || !(max_translation_m > 0.0f) || !(max_rotation_deg > 0.0f))
        return invalidArgument("icp failure limits must be > 0");
    if (max_failures_before_reacquire < 1) return invalidArgument("max_failures_before_reacquire must be >= 1");
    return Status::ok();
}

bool centroidAlignment(const SurfaceLevel& source, const SurfaceLevel& target_world, Pose& T_world_camera) {
    Eigen::Vector3f mu_s, mu_d;
    if (validCentroid(source, mu_s) == 0 || validCentroid(target_world, mu_d) == 0) return false;
    // Eq. 4.11 with the source first moved by the current estimate: T = [I, mu_D - T mu_S] T.
    const Eigen::Vector3f moved = T_world_camera * mu_s;
    Pose shift = Pose::Identity();
    shift.translation() = mu_d - moved;
    T_world_camera = shift * T_world_camera;
    return true;
}

Icp::Icp(const IcpParams& p) : params_(p), partial_(kStripes) {}

TrackingResult Icp::align(const SurfacePyramid& source, const SurfacePyramid& model_world, const Pose& T_world_model,
                          const Pose& prediction, Pose& T_world_camera, float motion_scale, int finest_level) {
    TrackingResult result;
    result.T_world_camera = T_world_camera;
    const int levels = std::min(params_.levels, source.count);
    if (model_world.count < 1 || levels < 1) return result;
    const int finest = std::clamp(finest_level, 0, levels - 1);
    // The model may be cast coarser than the frame (ReconParams::model_level): whole levels coarser, source level
    // l pairs with the model level of its own size, or with the model's finest where the source is finer.
    const int model_shift =
        pyramidLevelOfWidth(source.levels[0].k.width_px, model_world.levels[0].k.width_px, kMaxPyramidLevels);
    // IcpParams::model_offset_ridge: a seventh unknown, the model's offset along its normals (metres, > 0 = the
    // model lies in front of the frame's surface). It starts at 0 on every frame and carries over the levels.
    const bool with_offset = params_.model_offset_ridge >= 0.0f;
    double offset_m = 0.0;
    Pose estimate = T_world_camera;
    const Pose T_model_world = T_world_model.inverse();

    int last_inliers = 0;
    double last_error = 0.0;
    bool solve_failed = false;
    for (int level = levels - 1; level >= finest; --level) {
        const SurfaceLevel& src = source.levels[level];
        const SurfaceLevel& dst = model_world.levels[std::clamp(level - model_shift, 0, model_world.count - 1)];
        const float dist_gate2 = params_.dist_gate_m[level] * params_.dist_gate_m[level];
        const float cos_gate = static_cast<float>(std::cos(params_.normal_gate_deg[level] * kDegToRad));
        const float huber = params_.huber_m;
        // Every stride-th pixel of every stride-th row at the finest level (IcpParams::finest_stride_px).
        const int stride = level == 0 ? params_.finest_stride_px : 1;
        // IcpParams::confident_model_weight: where the model level carries its weights (its finest level).
        const bool by_confidence = params_.confident_model_weight > 0.0f && dst.weight.size() == dst.vertex.size();
        const float inv_confident = by_confidence ? 1.0f / params_.confident_model_weight : 0.0f;
        double prev_error = -1.0, prev_prev_error = -1.0;  // eq. 4.21 one and two iterations ago (-1: none)
        for (int it = 0; it < params_.iterations[level]; ++it) {
            // Everything an iteration needs in the model camera: source point -> world (estimate) -> model camera.
            const Pose T_model_camera = T_model_world * estimate;
            const Eigen::Matrix3f r_wc = estimate.linear();
            const Eigen::Vector3f t_wc = estimate.translation();
            const int rows = src.roi.height;
            parallelFor(0, kStripes, [&](int s_lo, int s_hi) {
                for (int s = s_lo; s < s_hi; ++s) {
                    // Summed on this thread's stack and stored once: adjacent stripes' partials share cache lines,
                    // and two threads accumulating into them pair by pair slowed ICP by a third.
                    Partial acc{};
                    const int v0 = src.roi.y + rows * s / kStripes, v1 = src.roi.y + rows * (s + 1) / kStripes;
                    for (int v = v0 + (stride - v0 % stride) % stride; v < v1; v += stride) {
                        const auto* vs = src.vertex.ptr<cv::Vec3f>(v);
                        const auto* ns = src.normal.ptr<cv::Vec3f>(v);
                        for (int u = src.roi.x; u < src.roi.x + src.roi.width; u += stride) {
                            if (std::isnan(vs[u][0]) || std::isnan(ns[u][0])) continue;
                            // Algorithm 2: transform the source vertex and normal by T, project into the model.
                            const Eigen::Vector3f p_cam(vs[u][0], vs[u][1], vs[u][2]);
                            const Eigen::Vector3f p_model = T_model_camera * p_cam;
                            if (p_model.z() <= 0.0f) continue;
                            const Eigen::Vector2f px = dst.k.project(p_model);
                            // Nearest pixel; std::lround is a libm call per pair. Off the image (NaN included) is
                            // outside any ROI, and checked before the conversion to int.
                            const float fu = px.x() + 0.5f, fv = px.y() + 0.5f;
                            if (!(fu >= 0.0f && fv >= 0.0f && fu < kMaxPixel && fv < kMaxPixel)) continue;
                            const int ku = static_cast<int>(fu), kv = static_cast<int>(fv);
                            if (!dst.roi.contains({ku, kv})) continue;
                            const cv::Vec3f& dv = dst.vertex.at<cv::Vec3f>(kv, ku);
                            const cv::Vec3f& dn = dst.normal.at<cv::Vec3f>(kv, ku);
                            if (std::isnan(dv[0]) || std::isnan(dn[0])) continue;
                            const Eigen::Vector3f s_w = r_wc * p_cam + t_wc;
                            const Eigen::Vector3f d_w(dv[0], dv[1], dv[2]);
                            const Eigen::Vector3f n_d(dn[0], dn[1], dn[2]);
                            if ((s_w - d_w).squaredNorm() > dist_gate2) continue;
                            const Eigen::Vector3f n_s = r_wc * Eigen::Vector3f(ns[u][0], ns[u][1], ns[u][2]);
                            if (n_s.dot(n_d) < cos_gate) continue;
                            // Eq. 4.17-4.18: A_i = [s x n, n], b_i = n.(d - s); with the offset unknown, A_i gains
                            // a 1: the model's surface, moved back by the offset, is d - offset n.
                            const float b = n_d.dot(d_w - s_w);
                            const Eigen::Vector3f sxn = s_w.cross(n_d);
                            const double a[7] = {sxn.x(), sxn.y(), sxn.z(), n_d.x(), n_d.y(), n_d.z(), 1.0};
                            const double residual = static_cast<double>(b) - offset_m;
                            const double abs_r = std::fabs(residual);
                            double w = (huber > 0.0f && abs_r > huber) ? huber / abs_r : 1.0;
                            if (by_confidence) w *= std::min(1.0f, dst.weight.at<float>(kv, ku) * inv_confident);
                            if (with_offset) {
                                accumulatePair<7>(acc, a, w, b);
                            } else {
                                accumulatePair<6>(acc, a, w, b);
                            }
                            acc[kErrorSlot] += residual * residual;  // eq. 4.21 error
                            acc[kCountSlot] += 1.0;
                        }
                    }
                    partial_[s] = acc;
                }
            });
            Partial sum{};
            for (const auto& part : partial_)
                for (int i = 0; i <= kCountSlot; ++i) sum[i] += part[i];
            const int count = static_cast<int>(sum[kCountSlot]);
            ++result.iterations;
            if (count < 6) {
                if (level == finest) last_inliers = count * stride * stride;
                break;  // nothing to solve at this level; a finer one may still have pairs
            }
            const int n = with_offset ? 7 : 6;
            Eigen::Matrix<double, 7, 7> ata = Eigen::Matrix<double, 7, 7>::Identity();
            Eigen::Matrix<double, 7, 1> atb = Eigen::Matrix<double, 7, 1>::Zero();
            int k = 0;
            for (int i = 0; i < n; ++i) {
                for (int j = i; j < n; ++j) ata(i, j) = ata(j, i) = sum[k++];
            }
            for (int i = 0; i < n; ++i) atb[i] = sum[k++];
            // A sphere, a plane or a cylinder leaves some combination of the six unknowns unconstrained (A^T A
            // nearly singular). Cholesky then returns whatever the rounding makes of it, a different large motion
            // with and without FMA. A damping of 1e-6 of the mean diagonal keeps such directions still and changes
            // the constrained ones by a relative 1e-6 at most.
            ata.diagonal().head<6>().array() += 1e-6 * ata.topLeftCorner<6, 6>().trace() / 6.0;
            // The offset's prior (IcpParams::model_offset_ridge): a share of the pairs' own weight pulls it to 0.
            // Its column is all ones (the weights' sum on the diagonal), so it stays positive definite.
            if (with_offset) ata(6, 6) *= 1.0 + static_cast<double>(params_.model_offset_ridge);
            // Eq. 4.20 by Cholesky, as the thesis does (the unused seventh row is the identity's: x[6] = 0).
            const Eigen::LLT<Eigen::Matrix<double, 7, 7>> llt(ata);
            const Eigen::Matrix<double, 7, 1> x7 = llt.solve(atb);
            if (llt.info() != Eigen::Success || !x7.allFinite()) {
                solve_failed = true;
                break;
            }
            const Eigen::Matrix<double, 6, 1> x = x7.head<6>();
            if (with_offset) offset_m = x7[6];
            estimate = incrementFromX(x) * estimate;  // eq. 4.13
            const double error = sum[kErrorSlot] / count;
            if (level == finest) {
                last_inliers = count * stride * stride;  // the pixels the sampled pairs stand for
                last_error = error;
            }
            // Eq. 4.21 convergence: the error stopped changing, or the update moves points by almost nothing
            // (rotation angles times a head's radius, plus the translation).
            // A third test stops a two-state cycle: near the optimum the nearest-pixel association can flip a few
            // pairs back and forth, the estimate alternating between two poses a few microns apart with the same
            // two errors; without it such a level ran all its iterations (6 of 300 frames at the finest level, 12 at
            // the middle one, on the synthetic head: a tenth of the iterations run).
            const double step_m = x.head<3>().norm() * 0.1 + x.tail<3>().norm();
            const auto same = [&](double before) {
                return before >= 0.0 && std::fabs(before - error) <= params_.convergence_rel * before;
            };
            const bool converged = same(prev_error) || same(prev_prev_error) || step_m < params_.convergence_step_m;
            prev_prev_error = prev_error;
            prev_error = error;
            if (converged) break;
        }
        if (solve_failed) break;
    }

    int source_valid = 0;
    const SurfaceLevel& s0 = source.levels[finest];
    for (int v = s0.roi.y; v < s0.roi.y + s0.roi.height; ++v) {
        const auto* row = s0.normal.ptr<cv::Vec3f>(v);
        for (int u = s0.roi.x; u < s0.roi.x + s0.roi.width; ++u) source_valid += std::isnan(row[u][0]) ? 0 : 1;
    }
    result.inliers = last_inliers;
    result.model_offset_m = static_cast<float>(offset_m);
    result.rmse_m = static_cast<float>(std::sqrt(last_error));
    if (solve_failed || !estimate.matrix().allFinite()) {
        result.status = TrackingStatus::kDiverged;
        return result;
    }
    if (last_inliers < params_.min_inliers ||
        static_cast<float>(last_inliers) < params_.min_inlier_share * static_cast<float>(source_valid)) {
        result.status = TrackingStatus::kNotEnoughPoints;
        return result;
    }
    if (result.rmse_m > params_.max_rmse_m) {
        result.status = TrackingStatus::kDiverged;
        return result;
    }
    const Pose delta = prediction.inverse() * estimate;
    const float scale = std::max(1.0f, motion_scale);
    if (delta.translation().norm() > scale * params_.max_translation_m ||
        rotationDeg(delta) > scale * params_.max_rotation_deg) {
        result.status = TrackingStatus::kLargeMotion;
        return result;
    }
    result.status = TrackingStatus::kTracked;
    result.T_world_camera = estimate;
    T_world_camera = estimate;
    return result;
}

}  // namespace facescan::recon
