// The observable region of G over a sequence of sensor views (rule in eval/observed_region.hpp) and the
// --gt-misses diagnosis.
#include "eval/observed_region.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <opencv2/core/utility.hpp>

namespace facescan::eval {
namespace {

using Vec3 = Eigen::Vector3f;
using Vec2 = Eigen::Vector2f;

// Metres: G is only projected where it is at least this far in front of the camera (a head at 0.4-4 m is).
constexpr float kNearM = 0.01f;
// Pixels: side of the screen-space bins that list the triangles overlapping them (occlusion queries).
constexpr int kCellPx = 8;

// The triangles of G binned by the screen cells their projected bounding box overlaps, for one view (counting
// sort into flat arrays, so a thread reuses its buffers from view to view).
struct TriangleBins {
    int cols = 0, rows = 0;
    std::vector<int> start;  // per cell, index into ids; start[cell + 1] - start[cell] triangles
    std::vector<int> ids;
    std::vector<cv::Rect> box;  // per triangle, in cells; empty when the triangle is not binned

    void build(const std::vector<Eigen::Vector3i>& tris, const std::vector<Vec3>& pc, const std::vector<Vec2>& px,
               const recon::Intrinsics& k) {
        cols = (k.width_px + kCellPx - 1) / kCellPx;
        rows = (k.height_px + kCellPx - 1) / kCellPx;
        start.assign(static_cast<size_t>(cols * rows) + 1, 0);
        box.assign(tris.size(), cv::Rect());
        for (size_t t = 0; t < tris.size(); ++t) {
            const Eigen::Vector3i& f = tris[t];
            if (!(pc[f[0]].z() > kNearM && pc[f[1]].z() > kNearM && pc[f[2]].z() > kNearM)) continue;
            const Vec2 lo = px[f[0]].cwiseMin(px[f[1]]).cwiseMin(px[f[2]]);
            const Vec2 hi = px[f[0]].cwiseMax(px[f[1]]).cwiseMax(px[f[2]]);
            const int c0 = std::max(0, static_cast<int>(std::floor(lo.x() / kCellPx)));
            const int r0 = std::max(0, static_cast<int>(std::floor(lo.y() / kCellPx)));
            const int c1 = std::min(cols - 1, static_cast<int>(std::floor(hi.x() / kCellPx)));
            const int r1 = std::min(rows - 1, static_cast<int>(std::floor(hi.y() / kCellPx)));
            if (c0 > c1 || r0 > r1) continue;
            box[t] = cv::Rect(c0, r0, c1 - c0 + 1, r1 - r0 + 1);
            for (int r = r0; r <= r1; ++r)
                for (int c = c0; c <= c1; ++c) ++start[static_cast<size_t>(r * cols + c) + 1];
        }
        for (size_t i = 1; i < start.size(); ++i) start[i] += start[i - 1];
        ids.resize(static_cast<size_t>(start.back()));
        std::vector<int> fill(start.begin(), start.end() - 1);
        for (size_t t = 0; t < tris.size(); ++t) {
            const cv::Rect& b = box[t];
            for (int r = b.y; r < b.y + b.height; ++r)
                for (int c = b.x; c < b.x + b.width; ++c)
                    ids[static_cast<size_t>(fill[r * cols + c]++)] = static_cast<int>(t);
        }
    }
};

// Whether the segment from the camera centre to p crosses triangle abc at a ray parameter below t_max (p at 1):
// Moller-Trumbore, camera frame.
bool segmentHits(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, float t_max) {
    const Vec3 e1 = b - a, e2 = c - a;
    const Vec3 h = p.cross(e2);
    const float det = e1.dot(h);
    if (std::fabs(det) < 1e-12f) return false;  // ray parallel to the triangle's plane
    const float inv = 1.0f / det;
    const Vec3 s = -a;
    const float u = inv * s.dot(h);
    if (u < 0 || u > 1) return false;
    const Vec3 q = s.cross(e1);
    const float v = inv * p.dot(q);
    if (v < 0 || u + v > 1) return false;
    const float t = inv * e2.dot(q);
    return t > 0 && t < t_max;
}

}  // namespace

Status ObservedRegionParams::validate() const {
    if (!(surface_tolerance_m > 0 && surface_tolerance_m < 0.01f))
        return invalidArgument("observed region: surface tolerance must be in (0, 0.01) m");
    if (!(min_cos_angle >= -1 && min_cos_angle <= 1)) return invalidArgument("observed region: cosine in [-1, 1]");
    return Status::ok();
}

StatusOr<std::vector<VertexSightings>> countSightings(const recon::Mesh& gt, const recon::Intrinsics& k,
                                                      const std::vector<SensorView>& views,
                                                      const ObservedRegionParams& params) {
    RETURN_IF_ERROR(params.validate());
    if (!k.valid()) return invalidArgument("observed region: invalid intrinsics");
    if (gt.n_faces() == 0 || !gt.has_vertex_normals())
        return invalidArgument("observed region: G needs faces and normals");
    for (size_t i = 0; i < views.size(); ++i) {
        const cv::Mat& d = views[i].depth_m;
        const cv::Mat& m = views[i].mask;
        if (d.type() != CV_32FC1 || d.cols != k.width_px || d.rows != k.height_px)
            return invalidArgument("observed region: view " + std::to_string(i) + " has no CV_32FC1 depth of " +
                                   std::to_string(k.width_px) + "x" + std::to_string(k.height_px));
        if (!m.empty() && (m.type() != CV_8UC1 || m.size() != d.size()))
            return invalidArgument("observed region: the mask of view " + std::to_string(i) +
                                   " is not CV_8UC1 of the depth's size");
    }
    std::vector<Vec3> points, normals;
    for (const auto vh : gt.vertices()) {
        const auto& p = gt.point(vh);
        const auto& n = gt.normal(vh);
        points.emplace_back(p[0], p[1], p[2]);
        normals.emplace_back(n[0], n[1], n[2]);
    }
    std::vector<Eigen::Vector3i> tris;
    for (const auto fh : gt.faces()) {
        Eigen::Vector3i f;
        int j = 0;
        for (const auto vh : gt.fv_range(fh)) {
            if (j < 3) f[j] = vh.idx();
            ++j;
        }
        if (j == 3) tris.push_back(f);
    }

    std::vector<VertexSightings> total(points.size());
    std::mutex merge;
    cv::parallel_for_(cv::Range(0, static_cast<int>(views.size())), [&](const cv::Range& range) {
        std::vector<VertexSightings> local(points.size());
        std::vector<Vec3> pc(points.size());
        std::vector<Vec2> px(points.size());
        TriangleBins bins;
        for (int i = range.start; i < range.end; ++i) {
            const SensorView& view = views[static_cast<size_t>(i)];
            for (size_t v = 0; v < points.size(); ++v) {
                pc[v] = view.T_camera_gt * points[v];
                px[v] = pc[v].z() > kNearM ? k.project(pc[v]) : Vec2(-1e6f, -1e6f);
            }
            bins.build(tris, pc, px, k);
            for (size_t v = 0; v < points.size(); ++v) {
                const Vec3& c = pc[v];
                if (!(c.z() > kNearM)) continue;
                const int u = static_cast<int>(std::lround(px[v].x())), w = static_cast<int>(std::lround(px[v].y()));
                if (!k.contains(u, w)) continue;
                const Vec3 n = view.T_camera_gt.linear() * normals[v];
                if (!(n.dot(c) < 0)) continue;                         // rule 1: seen from behind
                if (!(view.depth_m.at<float>(w, u) > 0.0f)) continue;  // rule 3 (cheap, so first)
                // Rule 2: no triangle of G (other than those around p) crosses p's ray more than the tolerance in
                // front of p.
                const int cell_c = std::clamp(static_cast<int>(std::floor(px[v].x() / kCellPx)), 0, bins.cols - 1);
                const int cell_r = std::clamp(static_cast<int>(std::floor(px[v].y() / kCellPx)), 0, bins.rows - 1);
                const int cell = cell_r * bins.cols + cell_c;
                const float t_max = 1.0f - params.surface_tolerance_m / c.norm();
                bool hidden = false;
                for (int j = bins.start[cell]; j < bins.start[cell + 1] && !hidden; ++j) {
                    const Eigen::Vector3i& f = tris[static_cast<size_t>(bins.ids[static_cast<size_t>(j)])];
                    const int vi = static_cast<int>(v);
                    if (f[0] == vi || f[1] == vi || f[2] == vi) continue;
                    hidden = segmentHits(c, pc[f[0]], pc[f[1]], pc[f[2]], t_max);
                }
                if (hidden) continue;
                ++local[v].measured;
                if (!view.mask.empty() && view.mask.at<uint8_t>(w, u) == 0) continue;
                ++local[v].in_mask;
                local[v].good += -n.dot(c.normalized()) >= params.min_cos_angle;
            }
        }
        const std::lock_guard<std::mutex> lock(merge);
        for (size_t v = 0; v < points.size(); ++v) {
            total[v].measured += local[v].measured;
            total[v].in_mask += local[v].in_mask;
            total[v].good += local[v].good;
        }
    });
    return total;
}

std::vector<uint8_t> observedMask(const std::vector<VertexSightings>& sightings) {
    std::vector<uint8_t> mask(sightings.size());
    for (size_t v = 0; v < sightings.size(); ++v) mask[v] = sightings[v].measured > 0;
    return mask;
}

Status writeMisses(const recon::Mesh& gt, const std::vector<VertexSightings>& sightings, const recon::Mesh& mesh,
                   const AccuracyReport& acc, const Vec3& nose, const AccuracyParams& ruler, const std::string& path) {
    if (sightings.size() != gt.n_vertices()) return invalidArgument("misses: one sighting count per GT vertex");
    if (mesh.n_vertices() == 0 || !gt.has_vertex_normals()) return invalidArgument("misses: empty mesh or bad GT");
    const SurfaceDistance dist(mesh);
    const recon::Pose T_mesh_gt = acc.T_gt_mesh.inverse();
    struct Row {
        Vec3 p;
        float d_mm;
        int cls;
    };
    std::vector<Row> rows;
    const char* names[] = {"covered", "never measured (not observable)", "measured, never in the mask",
                           "in the mask only at poor angles", "measured well, not covered (ours)"};
    int count[5] = {0, 0, 0, 0, 0}, below_chin[5] = {0, 0, 0, 0, 0}, sides[5] = {0, 0, 0, 0, 0};
    for (const auto vh : gt.vertices()) {
        const auto& q = gt.point(vh);
        const Vec3 p(q[0], q[1], q[2]);
        if ((p - nose).norm() > ruler.face_radius_m || gt.normal(vh)[2] < ruler.min_facing_cos) continue;
        const float d = dist.query(T_mesh_gt * p).distance_m;
        const VertexSightings& s = sightings[vh.idx()];
        const int cls = d <= ruler.complete_within_m ? 0
                        : s.measured == 0            ? 1
                        : s.in_mask == 0             ? 2
                        : s.good == 0                ? 3
                                                     : 4;
        ++count[cls];
        below_chin[cls] += p.y() < nose.y() - 0.06f;
        sides[cls] += std::fabs(p.x() - nose.x()) > 0.06f;
        rows.push_back({p, 1000.0f * d, cls});
    }
    std::printf("GT face vertices: %zu\n", rows.size());
    for (int c = 0; c < 5; ++c)
        std::printf("  %-33s %6d (%5.1f %%)  of which >6 cm below the nose tip %d, >6 cm to the side %d\n", names[c],
                    count[c], 100.0 * count[c] / static_cast<double>(std::max<size_t>(rows.size(), 1)), below_chin[c],
                    sides[c]);
    std::ofstream out(path);
    out << "ply\nformat ascii 1.0\nelement vertex " << rows.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
           "property uchar blue\nproperty float distance_mm\nproperty uchar miss_class\nend_header\n";
    const int rgb[5][3] = {{0, 200, 0}, {0, 0, 255}, {255, 255, 0}, {255, 0, 255}, {255, 0, 0}};
    for (const Row& r : rows)
        out << r.p.x() << ' ' << r.p.y() << ' ' << r.p.z() << ' ' << rgb[r.cls][0] << ' ' << rgb[r.cls][1] << ' '
            << rgb[r.cls][2] << ' ' << r.d_mm << ' ' << r.cls << '\n';
    if (!out) return unavailable("misses: cannot write " + path);
    return Status::ok();
}

}  // namespace facescan::eval
