// Point-to-surface distance: nanoflann k-d tree over the vertices, then exact point-triangle distance over the
// triangles incident to the k nearest vertices (the closest surface point lies on one of them unless the mesh is
// far coarser than the query's distance, which the ruler's 3 mm GT edges never are).
#include <algorithm>
#include <cmath>
#include <limits>
#include <nanoflann.hpp>
#include <vector>

#include "eval/accuracy.hpp"
#include "recon/mesh_distance.hpp"

namespace facescan::eval {
namespace {

using Vec3 = Eigen::Vector3f;

// The recon core's closest point on a triangle (Ericson, Real-Time Collision Detection, 5.1.5).
using recon::closestPointOnTriangle;

struct Cloud {
    std::vector<Vec3> pts;
    size_t kdtree_get_point_count() const { return pts.size(); }
    float kdtree_get_pt(size_t i, size_t dim) const { return pts[i][static_cast<int>(dim)]; }
    template <class Box>
    bool kdtree_get_bbox(Box&) const {
        return false;
    }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Cloud>, Cloud, 3, uint32_t>;
constexpr int kNeighbours = 6;
// A point in a crease may have the opposite wall's vertices nearest: look further for its own wall.
constexpr int kFacingNeighbours = 12;

}  // namespace

struct SurfaceDistance::Impl {
    Cloud cloud;
    std::vector<Eigen::Vector3i> tris;
    std::vector<Vec3> tri_normals;
    std::vector<int> face_ids;          // mesh face index of each triangle
    std::vector<int> ring_start, ring;  // CSR: triangles incident to each vertex
    Cloud tree_cloud;                   // the vertices that carry triangles, indexed by the k-d tree
    std::vector<int> surface_vertex;    // tree index -> vertex index
    std::unique_ptr<KdTree> tree;
};

SurfaceDistance::SurfaceDistance(const recon::Mesh& mesh) : impl_(std::make_unique<Impl>()) {
    Impl& m = *impl_;
    m.cloud.pts.reserve(mesh.n_vertices());
    for (const auto vh : mesh.vertices()) {
        const auto& p = mesh.point(vh);
        m.cloud.pts.emplace_back(p[0], p[1], p[2]);
    }
    std::vector<int> count(mesh.n_vertices() + 1, 0);
    for (const auto fh : mesh.faces()) {
        Eigen::Vector3i t;
        int k = 0;
        for (const auto vh : mesh.fv_range(fh)) {
            if (k < 3) t[k] = vh.idx();
            ++k;
        }
        if (k != 3) continue;
        m.tris.push_back(t);
        m.face_ids.push_back(fh.idx());
        const Vec3 n = (m.cloud.pts[t[1]] - m.cloud.pts[t[0]]).cross(m.cloud.pts[t[2]] - m.cloud.pts[t[0]]);
        m.tri_normals.push_back(n.norm() > 0 ? Vec3(n.normalized()) : Vec3::UnitZ());
        for (int c = 0; c < 3; ++c) ++count[t[c] + 1];
    }
    for (size_t i = 1; i < count.size(); ++i) count[i] += count[i - 1];
    m.ring_start = count;
    m.ring.resize(count.back());
    std::vector<int> fill(count.begin(), count.end() - 1);
    for (int f = 0; f < static_cast<int>(m.tris.size()); ++f) {
        for (int c = 0; c < 3; ++c) m.ring[fill[m.tris[f][c]]++] = f;
    }
    // Only vertices that carry triangles are surface: an isolated vertex is not (a cut hole stays a hole).
    for (int v = 0; v < static_cast<int>(m.cloud.pts.size()); ++v) {
        if (m.ring_start[v + 1] > m.ring_start[v]) {
            m.surface_vertex.push_back(v);
            m.tree_cloud.pts.push_back(m.cloud.pts[v]);
        }
    }
    m.tree = std::make_unique<KdTree>(3, m.tree_cloud, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    if (!m.tree_cloud.pts.empty()) m.tree->buildIndex();
}

SurfaceDistance::~SurfaceDistance() = default;

SurfaceDistance::Hit SurfaceDistance::query(const Vec3& p) const { return nearest(p, nullptr); }

SurfaceDistance::Hit SurfaceDistance::query(const Vec3& p, const Vec3& facing) const {
    const Hit hit = nearest(p, &facing);
    return hit.face >= 0 ? hit : nearest(p, nullptr);
}

SurfaceDistance::Hit SurfaceDistance::nearest(const Vec3& p, const Vec3* facing) const {
    const Impl& m = *impl_;
    Hit hit;
    hit.distance_m = std::numeric_limits<float>::infinity();
    if (m.tree_cloud.pts.empty()) return hit;
    uint32_t idx[kFacingNeighbours];
    float d2[kFacingNeighbours];
    const size_t found = m.tree->knnSearch(p.data(), facing ? kFacingNeighbours : kNeighbours, idx, d2);
    if (found == 0) return hit;
    for (size_t i = 0; i < found; ++i) idx[i] = static_cast<uint32_t>(m.surface_vertex[idx[i]]);
    hit.nearest_vertex = static_cast<int>(idx[0]);
    // Every vertex lies on its incident triangles, so the best triangle is never worse than the vertex.
    float best = std::numeric_limits<float>::infinity();
    for (size_t i = 0; i < found; ++i) {
        for (int r = m.ring_start[idx[i]]; r < m.ring_start[idx[i] + 1]; ++r) {
            const int f = m.ring[r];
            if (facing && m.tri_normals[f].dot(*facing) <= 0) continue;
            const auto& t = m.tris[f];
            const Vec3 q = closestPointOnTriangle(p, m.cloud.pts[t[0]], m.cloud.pts[t[1]], m.cloud.pts[t[2]]);
            const float d = (q - p).norm();
            if (d < best) {
                best = d;
                hit.distance_m = d;
                hit.closest = q;
                hit.face = m.face_ids[f];
                hit.normal = m.tri_normals[f];
            }
        }
    }
    return hit;
}

int countVerticesFarFrom(const recon::Mesh& mesh, const recon::Mesh& reference, float max_distance_m,
                         const std::vector<uint8_t>* allowed) {
    const SurfaceDistance distance(reference);
    int far = 0;
    for (const auto vh : mesh.vertices()) {
        const auto& p = mesh.point(vh);
        const SurfaceDistance::Hit hit = distance.query(Eigen::Vector3f(p[0], p[1], p[2]));
        const bool not_allowed = allowed != nullptr && hit.nearest_vertex >= 0 &&
                                 static_cast<size_t>(hit.nearest_vertex) < allowed->size() &&
                                 (*allowed)[static_cast<size_t>(hit.nearest_vertex)] == 0;
        far += hit.distance_m > max_distance_m || not_allowed;
    }
    return far;
}

}  // namespace facescan::eval
