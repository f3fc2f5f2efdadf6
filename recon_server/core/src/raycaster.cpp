#include "recon/raycaster.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "recon/parallel.hpp"

namespace facescan::recon {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Slab test of the ray o + s d (s >= 0) against the cube of voxel centres [0, N-1]^3 (voxel coordinates).
bool clipToCube(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float n_max, float& s0, float& s1) {
    s0 = 0.0f;
    s1 = std::numeric_limits<float>::max();
    for (int a = 0; a < 3; ++a) {
        if (std::fabs(d[a]) < 1e-12f) {
            if (o[a] < 0.0f || o[a] > n_max) return false;
            continue;
        }
        float t0 = (0.0f - o[a]) / d[a], t1 = (n_max - o[a]) / d[a];
        if (t0 > t1) std::swap(t0, t1);
        s0 = std::max(s0, t0);
        s1 = std::min(s1, t1);
    }
    return s0 < s1;
}

// A sign change of D along a ray: a sample in front of the surface (s_front, d_front > 0) and one behind it
// (s_back, d_back <= 0), in voxel units along the ray.
struct Bracket {
    float s_front, d_front, s_back, d_back;
};

// The surface point in a bracket and its unit normal: the zero crossing by eq. 4.28, then one regula falsi step
// (with steps of up to mu, D is not linear over the bracket), and the normal as the gradient of D there (eq. 4.30).
// The cell of the first estimate is gathered with the 24 voxels around it once: D there comes from its corners and,
// when the refined point stays in that cell (nearly always: the step is a fraction of a voxel), the gradient from
// the same gather; the same values as sampling the cell and then taking the gradient. False where the gradient is
// unavailable or zero. With `weight`, also the accumulated weight W there (trilinear, from the same gather).
bool surfaceAt(const VoxelBlockGrid& g, const Eigen::Vector3f& o_vox, const Eigen::Vector3f& dir_vox, const Bracket& b,
               Eigen::Vector3f& p_vox, Eigen::Vector3f& n, float* weight = nullptr) {
    float s_hit = b.s_front + (b.s_back - b.s_front) * b.d_front / (b.d_front - b.d_back);  // eq. 4.28
    const Eigen::Vector3f p_first = o_vox + dir_vox * s_hit;
    VoxelBlockGrid::CrossCell cross;
    const bool gathered = g.gatherCross(p_first, cross);
    float d_hit = 0.0f;
    const bool have_d = gathered ? cross.cell_observed : g.sample(p_first, d_hit) == VoxelBlockGrid::Cell::kOk;
    if (have_d) {
        if (gathered) d_hit = cross.tsdfAt(p_first);
        if (d_hit > 0.0f) {
            s_hit += (b.s_back - s_hit) * d_hit / (d_hit - b.d_back);
        } else if (d_hit < 0.0f) {
            s_hit = b.s_front + (s_hit - b.s_front) * b.d_front / (b.d_front - d_hit);
        }
    }
    p_vox = o_vox + dir_vox * s_hit;
    if (!(gathered && cross.contains(p_vox)) && !g.gatherCross(p_vox, cross)) return false;
    if (!cross.cross_observed) return false;
    n = cross.gradientAt(p_vox);
    if (weight != nullptr) *weight = cross.weightAt(p_vox);
    const float len = n.norm();
    if (!(len > 0.0f)) return false;
    n /= len;
    return true;
}

// Marches one ray (eq. 4.27) in voxel coordinates between s_begin and s_end (units: voxels along the unit ray
// direction dir_vox); false when it crosses no surface, else the bracket of the first crossing. With have_prev,
// the march continues from a sample already taken (prev_s, prev_d > 0) instead.
bool marchRay(const VoxelBlockGrid& g, const Eigen::Vector3f& o_vox, const Eigen::Vector3f& dir_vox, float s_begin,
              float s_end, float step_vox, Bracket& out, bool have_prev = false, float prev_s = 0.0f,
              float prev_d = 0.0f) {
    using Cell = VoxelBlockGrid::Cell;
    const float block_skip = static_cast<float>(kBlockSide) * 0.5f;
    const float free_step_per_d = g.trunc_dist_m / g.voxel_size_m;  // voxels of free space per unit of D
    float s = have_prev ? prev_s + std::max(1.0f, std::min(step_vox, prev_d * free_step_per_d)) : s_begin;
    while (s <= s_end) {
        float d;
        const Cell cell = g.sample(o_vox + dir_vox * s, d);
        if (cell != Cell::kOk) {
            have_prev = false;
            // Empty space: half a block at a time so thin allocated shells are not jumped.
            s += cell == Cell::kUnallocated ? block_skip : step_vox;
            continue;
        }
        if (have_prev && prev_d > 0.0f && d <= 0.0f) {
            out = {prev_s, prev_d, s, d};
            return true;
        }
        if (have_prev && prev_d < 0.0f && d > 0.0f) return false;  // leaving a back face: not a visible surface
        prev_d = d;
        prev_s = s;
        have_prev = true;
        // In front of the surface the step is the distance D says is free (D is in units of mu), at least one
        // voxel and at most step_vox; the sign change is then bracketed within one step and refined above.
        s += d > 0.0f ? std::max(1.0f, std::min(step_vox, d * free_step_per_d)) : step_vox;
    }
    return false;
}

// A ray with a measured depth: the model surface lies within noise of it (the frame was just integrated there), so
// D at the measurement already says how far the crossing is. In front of it (0 < D < 1) the march goes on forward
// from there; behind it (D <= 0) it steps back by what D says until D turns positive, which brackets the crossing
// nearest the measurement. About three samples instead of six from start_before_hint_m in front. Where D there is
// unobserved or truncated (no surface within mu), the full march from s_begin decides.
bool marchFromHint(const VoxelBlockGrid& g, const Eigen::Vector3f& o_vox, const Eigen::Vector3f& dir_vox, float s_begin,
                   float s_hint, float s_end, float step_vox, Bracket& out) {
    using Cell = VoxelBlockGrid::Cell;
    const float free_step_per_d = g.trunc_dist_m / g.voxel_size_m;
    float d;
    if (!(s_hint > s_begin && s_hint < s_end) || g.sample(o_vox + dir_vox * s_hint, d) != Cell::kOk || d >= 1.0f ||
        d <= -1.0f) {
        return marchRay(g, o_vox, dir_vox, s_begin, s_end, step_vox, out);
    }
    if (d > 0.0f) return marchRay(g, o_vox, dir_vox, s_hint, s_end, step_vox, out, true, s_hint, d);
    float s_back = s_hint, d_back = d;
    for (;;) {
        const float s = s_back - std::max(1.0f, std::min(step_vox, -d_back * free_step_per_d));
        if (s < s_begin) return marchRay(g, o_vox, dir_vox, s_begin, s_end, step_vox, out);
        float d_front;
        if (g.sample(o_vox + dir_vox * s, d_front) != Cell::kOk)
            return marchRay(g, o_vox, dir_vox, s_begin, s_end, step_vox, out);
        if (d_front > 0.0f) {
            out = {s, d_front, s_back, d_back};
            return true;
        }
        s_back = s;
        d_back = d_front;
    }
}

// The nearest measured pixel of one hint row within `radius` of each pixel, for a left-to-right scan: amortised
// O(row) instead of up to 2 * radius reads per pixel without a measurement. Ties go left.
class RowHints {
 public:
    RowHints(const float* hint, int u_begin, int u_end, int radius)
        : hint_(hint), u_end_(u_end), radius_(radius), left_(u_begin - radius - 1), right_(u_begin) {}
    // Call for u = u_begin, u_begin + 1, ... in order; the depth of the nearest measured pixel other than u, 0
    // when none lies within the radius.
    float nearest(int u) {
        if (right_ <= u) {
            right_ = u + 1;
            while (right_ < u_end_ && !(hint_[right_] > 0.0f)) ++right_;
        }
        const int d_left = u - left_, d_right = right_ - u;
        if (d_left <= radius_ && d_left <= d_right) return hint_[left_];
        if (right_ < u_end_ && d_right <= radius_) return hint_[right_];
        return 0.0f;
    }
    // Call after pixel u: it is measured.
    void measured(int u) { left_ = u; }

 private:
    const float* hint_;
    int u_end_, radius_;
    int left_;   // the last measured pixel before the current one (far left: none)
    int right_;  // the first measured pixel after the current one, u_end_ when none
};

// Whether the voxel-space point lies in the cube of voxel centres [0, n_max]^3.
bool insideCube(const Eigen::Vector3f& p_vox, float n_max) {
    return p_vox.x() >= 0.0f && p_vox.y() >= 0.0f && p_vox.z() >= 0.0f && p_vox.x() <= n_max && p_vox.y() <= n_max &&
           p_vox.z() <= n_max;
}

}  // namespace

Status RaycastParams::validate() const {
    if (!(step_trunc_fraction > 0.0f && step_trunc_fraction <= 1.0f))
        return invalidArgument("raycast step_trunc_fraction must be in (0, 1] (a step over mu misses surfaces)");
    if (!(start_before_hint_m >= 0.0f) || !(search_after_hint_m >= 0.0f) || !(hint_widen_m >= 0.0f))
        return invalidArgument("raycast hint margins must be >= 0");
    if (hint_search_px < 0) return invalidArgument("raycast hint_search_px must be >= 0");
    return Status::ok();
}

void Raycaster::cast(const VoxelBlockGrid& grid, const Intrinsics& k, const Pose& T_world_camera,
                     const cv::Rect& roi_in, const cv::Mat& depth_hint_m, SurfaceLevel& out) const {
    const cv::Rect roi = roi_in & cv::Rect(0, 0, k.width_px, k.height_px);
    out.k = k;
    out.roi = roi;
    if (roi.empty() || grid.allocated_blocks == 0) {
        out.roi = cv::Rect();
        return;
    }
    const float vs = grid.voxel_size_m;
    const float n_max = static_cast<float>(grid.resolution_vox - 1);
    const float step_vox = params_.step_trunc_fraction * grid.trunc_dist_m / vs;
    const Eigen::Matrix3f r = T_world_camera.linear();
    const Eigen::Vector3f o_vox = grid.toVoxel(T_world_camera.translation());
    const bool have_hint = !depth_hint_m.empty();
    const bool with_weight = out.weight.size() == out.vertex.size() && out.weight.type() == CV_32FC1;
    const int u_begin = roi.x, u_end = roi.x + roi.width;
    parallelFor(roi.y, roi.y + roi.height, [&](int v_lo, int v_hi) {
        for (int v = v_lo; v < v_hi; ++v) {
            auto* vert = out.vertex.ptr<cv::Vec3f>(v);
            auto* norm = out.normal.ptr<cv::Vec3f>(v);
            std::fill(vert + u_begin, vert + u_end, cv::Vec3f(kNaN, kNaN, kNaN));
            std::fill(norm + u_begin, norm + u_end, cv::Vec3f(kNaN, kNaN, kNaN));
            float* weight = with_weight ? out.weight.ptr<float>(v) : nullptr;  // read only where a vertex is
            const float* hint = have_hint ? depth_hint_m.ptr<float>(v) : nullptr;
            RowHints row_hints(hint, u_begin, u_end, params_.hint_search_px);
            const float ray_y = k.ray(0.0f, static_cast<float>(v)).y();
            for (int u = u_begin; u < u_end; ++u) {
                float z_hint = hint ? hint[u] : 0.0f;
                const bool measured = z_hint > 0.0f;
                float widen_m = 0.0f;
                if (hint && measured) row_hints.measured(u);
                if (hint && !measured) {
                    // No measurement here (ROI margin, dropout, background inside the head box): the nearest
                    // measured pixel of the row, with a wider window, says where the head can be. Without one the
                    // ray is skipped, before any of its set-up: marching the whole cube for background pixels
                    // cost most of the ray cast.
                    z_hint = row_hints.nearest(u);
                    widen_m = params_.hint_widen_m;
                    if (!(z_hint > 0.0f) && !params_.march_without_hint) continue;
                }
                const Eigen::Vector3f ray_cam(k.ray(static_cast<float>(u), 0.0f).x(), ray_y, 1.0f);
                const float ray_len = ray_cam.norm();                   // metres along the ray per metre of depth
                const Eigen::Vector3f dir_vox = r * ray_cam / ray_len;  // unit direction; voxel units per vs
                float s0, s1;                                           // voxel units along dir_vox
                if (z_hint > 0.0f) {
                    // The hint's window; clipped to the cube only where it leaves it (rarely: the cube holds the
                    // head), which is what clipping first and intersecting gave.
                    s0 = (z_hint - params_.start_before_hint_m - widen_m) * ray_len / vs;
                    s1 = (z_hint + params_.search_after_hint_m + widen_m) * ray_len / vs;
                    if (!(s0 >= 0.0f && insideCube(o_vox + dir_vox * s0, n_max) &&
                          insideCube(o_vox + dir_vox * s1, n_max))) {
                        float c0, c1;
                        if (!clipToCube(o_vox, dir_vox, n_max, c0, c1)) continue;
                        s0 = std::max(s0, c0);
                        s1 = std::min(s1, c1);
                    }
                    if (!(s0 < s1)) continue;
                } else if (!clipToCube(o_vox, dir_vox, n_max, s0, s1)) {
                    continue;
                }
                Bracket bracket;
                const bool crossed =
                    measured ? marchFromHint(grid, o_vox, dir_vox, s0, z_hint * ray_len / vs, s1, step_vox, bracket)
                             : marchRay(grid, o_vox, dir_vox, s0, s1, step_vox, bracket);
                Eigen::Vector3f p_vox, n_world;
                if (!crossed ||
                    !surfaceAt(grid, o_vox, dir_vox, bracket, p_vox, n_world, weight ? weight + u : nullptr))
                    continue;
                const Eigen::Vector3f p_world = grid.toWorld(p_vox);  // eq. 4.29
                vert[u] = cv::Vec3f(p_world.x(), p_world.y(), p_world.z());
                norm[u] = cv::Vec3f(n_world.x(), n_world.y(), n_world.z());
            }
        }
    });
}

void Raycaster::renderShaded(const VoxelBlockGrid& grid, const Intrinsics& k, const Pose& T_world_camera,
                             cv::Mat& shaded_bgr) const {
    shaded_bgr.create(k.height_px, k.width_px, CV_8UC3);
    shaded_bgr.setTo(cv::Scalar::all(0));
    if (grid.allocated_blocks == 0) return;
    const float vs = grid.voxel_size_m;
    const float n_max = static_cast<float>(grid.resolution_vox - 1);
    const float step_vox = params_.step_trunc_fraction * grid.trunc_dist_m / vs;
    const Eigen::Matrix3f r = T_world_camera.linear();
    const Eigen::Vector3f o_vox = grid.toVoxel(T_world_camera.translation());
    parallelFor(0, k.height_px, [&](int v_lo, int v_hi) {
        for (int v = v_lo; v < v_hi; ++v) {
            auto* out = shaded_bgr.ptr<cv::Vec3b>(v);
            for (int u = 0; u < k.width_px; ++u) {
                const Eigen::Vector3f ray_cam = k.ray(static_cast<float>(u), static_cast<float>(v));
                const Eigen::Vector3f dir_vox = r * ray_cam.normalized();
                float s0, s1;
                if (!clipToCube(o_vox, dir_vox, n_max, s0, s1)) continue;
                Bracket bracket;
                Eigen::Vector3f p_vox, n;
                if (!marchRay(grid, o_vox, dir_vox, s0, s1, step_vox, bracket) ||
                    !surfaceAt(grid, o_vox, dir_vox, bracket, p_vox, n))
                    continue;
                // Lambert with the light at the camera: brightness = cos(normal, ray back to the camera).
                const float lambert = std::max(0.0f, -n.dot(dir_vox));
                const float shade = 0.15f + 0.85f * lambert;
                Eigen::Vector3f bgr(200.0f, 200.0f, 200.0f);
                Eigen::Vector3f c;
                if (grid.interpolateColour(p_vox, c) && c.maxCoeff() > 0.0f) bgr = c;
                out[u] =
                    cv::Vec3b(cv::saturate_cast<uint8_t>(bgr[0] * shade), cv::saturate_cast<uint8_t>(bgr[1] * shade),
                              cv::saturate_cast<uint8_t>(bgr[2] * shade));
            }
        }
    });
}

}  // namespace facescan::recon
