#include "recon/model_agreement.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "recon/parallel.hpp"

namespace facescan::recon {
namespace {

constexpr int kStripes = 16;  // fixed stripes: the counts sum in the same order on any core count

// One measured point and the model surface it is paired with.
struct Pair {
    int u, v;                  // source pixel
    Eigen::Vector3f s_model;   // measured point, model camera frame
    const cv::Vec3f* d_world;  // model surface at the associated pixel, world frame; null: the model has none there
};

// World -> model camera, for the model surface of a pair (a visitor transforms only what it needs).
struct ToModel {
    Eigen::Matrix3f r;
    Eigen::Vector3f t;
    explicit ToModel(const Pose& T_world_model) {
        const Pose T_model_world = T_world_model.inverse();
        r = T_model_world.linear();
        t = T_model_world.translation();
    }
    Eigen::Vector3f operator()(const cv::Vec3f& w) const { return r * Eigen::Vector3f(w[0], w[1], w[2]) + t; }
    float z(const cv::Vec3f& w) const { return r(2, 0) * w[0] + r(2, 1) * w[1] + r(2, 2) * w[2] + t.z(); }
};

// Algorithm 2's projective association over stripes of source rows: calls visit(stripe, pair) for every valid
// source point, in parallel across stripes (a stripe is visited by one thread, rows in order).
template <class Visit>
void forEachPair(const SurfaceLevel& src, const SurfaceLevel& model, const Pose& T_world_model,
                 const Pose& T_world_camera, Visit&& visit) {
    const Pose T_model_camera = T_world_model.inverse() * T_world_camera;
    const Eigen::Matrix3f r = T_model_camera.linear();
    const Eigen::Vector3f t = T_model_camera.translation();
    // Seen from the model's own pose (robust integration's pre-filter at the predicted pose, every tracked frame;
    // verification of a cast hypothesis), each pixel's ray is the model pixel's ray: the pair is that pixel, with
    // no transform or projection (which would return it, to rounding).
    const bool same_view = T_world_model.matrix() == T_world_camera.matrix() && src.k == model.k;
    // Stripe boundaries are multiples of 8 rows (but the first and last), so stripes also own disjoint rows of
    // coarser pyramid levels (up to level 3).
    const int rows = src.roi.height, top = src.roi.y, bottom = src.roi.y + src.roi.height;
    auto boundary = [&](int s) {
        if (s == 0) return top;
        if (s == kStripes) return bottom;
        return std::clamp((top + rows * s / kStripes + 7) & ~7, top, bottom);
    };
    parallelFor(0, kStripes, [&](int s_lo, int s_hi) {
        for (int s = s_lo; s < s_hi; ++s) {
            const int v0 = boundary(s), v1 = boundary(s + 1);
            for (int v = v0; v < v1; ++v) {
                const auto* vs = src.vertex.ptr<cv::Vec3f>(v);
                for (int u = src.roi.x; u < src.roi.x + src.roi.width; ++u) {
                    if (std::isnan(vs[u][0])) continue;
                    const Eigen::Vector3f p(vs[u][0], vs[u][1], vs[u][2]);
                    Pair pair{u, v, same_view ? p : Eigen::Vector3f(r * p + t), nullptr};
                    int ku = u, kv = v;
                    if (pair.s_model.z() > 0.0f &&
                        (same_view || model.k.nearestPixel(model.k.project(pair.s_model), ku, kv)) &&
                        model.roi.contains({ku, kv})) {
                        const cv::Vec3f& dw = model.vertex.at<cv::Vec3f>(kv, ku);
                        if (!std::isnan(dw[0])) pair.d_world = &dw;
                    }
                    visit(s, pair);
                }
            }
        }
    });
}

}  // namespace

PoseCheck checkPose(const SurfaceLevel& source, const SurfaceLevel& model, const Pose& T_world_model,
                    const Pose& T_world_camera, float agree_m, float conflict_m) {
    struct Acc {
        int measured = 0, associated = 0, agreeing = 0, conflicting = 0;
        double sq = 0.0;
    };
    std::array<Acc, kStripes> acc{};
    const float agree2 = agree_m * agree_m;
    const ToModel to_model(T_world_model);
    forEachPair(source, model, T_world_model, T_world_camera, [&](int s, const Pair& p) {
        Acc& a = acc[static_cast<size_t>(s)];
        ++a.measured;
        if (p.d_world == nullptr) return;
        ++a.associated;
        const Eigen::Vector3f d_model = to_model(*p.d_world);
        const float d2 = (p.s_model - d_model).squaredNorm();
        if (d2 <= agree2) {
            ++a.agreeing;
            a.sq += d2;
        } else if (p.s_model.z() > d_model.z() + conflict_m) {
            ++a.conflicting;  // the camera would see this point through the model's surface
        }
    });
    PoseCheck check;
    double sq = 0.0;
    for (const Acc& a : acc) {
        check.measured += a.measured, check.associated += a.associated;
        check.agreeing += a.agreeing, check.conflicting += a.conflicting, sq += a.sq;
    }
    check.rmse_m = check.agreeing > 0 ? static_cast<float>(std::sqrt(sq / check.agreeing)) : 0.0f;
    return check;
}

int rejectOccludingDepth(SurfacePyramid& pyramid, const SurfaceLevel& model, const Pose& T_world_model,
                         const Pose& T_world_camera, const VoxelBlockGrid& grid, float band_m, float min_weight,
                         cv::Mat* hint_m, int level) {
    const int levels = std::min(pyramid.count, 4);
    if (level < 0 || level >= levels || (level > 0 && hint_m != nullptr)) return 0;
    SurfaceLevel& frame = pyramid.levels[level];
    if (frame.roi.empty() || model.roi.empty() || grid.allocated_blocks == 0) return 0;
    std::array<int, kStripes> removed{};
    constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
    const ToModel to_model(T_world_model);
    forEachPair(frame, model, T_world_model, T_world_camera, [&](int s, const Pair& p) {
        if (p.d_world == nullptr) return;
        const float d_z = to_model.z(*p.d_world);
        if (p.s_model.z() >= d_z - band_m) return;
        // In front of the model by more than the band: an occluder, if the model there is confident.
        const Eigen::Vector3f vox = grid.toVoxel(Eigen::Vector3f((*p.d_world)[0], (*p.d_world)[1], (*p.d_world)[2]));
        const Voxel* vx = grid.voxel(static_cast<int>(std::lround(vox.x())), static_cast<int>(std::lround(vox.y())),
                                     static_cast<int>(std::lround(vox.z())));
        if (vx == nullptr || vx->weight < min_weight) return;
        // The pixel's row belongs to this stripe only, so writing it here is race-free.
        if (hint_m != nullptr) hint_m->ptr<float>(p.v)[p.u] = d_z;
        for (int l = level; l < levels; ++l) {
            SurfaceLevel& lv = pyramid.levels[l];
            const int u = p.u >> (l - level), v = p.v >> (l - level);
            lv.depth_m.ptr<float>(v)[u] = 0.0f;
            lv.vertex.ptr<cv::Vec3f>(v)[u] = cv::Vec3f(kNaN, kNaN, kNaN);
            lv.normal.ptr<cv::Vec3f>(v)[u] = cv::Vec3f(kNaN, kNaN, kNaN);
        }
        ++removed[static_cast<size_t>(s)];
    });
    int total = 0;
    for (int r : removed) total += r;
    return total;
}

}  // namespace facescan::recon
