// Point-to-surface distance against a triangle mesh, in the recon core (the finishing stage reports how far a
// simplified or closed model lies from the full one). The bench's ruler (eval::SurfaceDistance) uses the same
// closest-point function.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "recon/indexed_mesh.hpp"

namespace facescan::recon {

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, section 5.1.5).
Eigen::Vector3f closestPointOnTriangle(const Eigen::Vector3f& p, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                       const Eigen::Vector3f& c);

// Exact distances from points to a mesh's triangles through a uniform grid of the triangles' bounding boxes
// (cells about two mean edges wide): a query visits rings of cells outwards until no unvisited cell can be nearer
// than the best triangle found. The mesh is copied in; queries are const and thread-safe.
class TriangleGrid {
 public:
    explicit TriangleGrid(const IndexedMesh& mesh);
    bool empty() const { return triangles_.empty(); }
    // metres; the distance from p to the nearest triangle (infinity for a mesh without triangles).
    float distance(const Eigen::Vector3f& p) const;

 private:
    std::vector<Eigen::Vector3f> positions_m_;
    std::vector<Triangle> triangles_;
    Eigen::Vector3f origin_m_ = Eigen::Vector3f::Zero();
    float cell_m_ = 1;
    Eigen::Vector3i dims_ = Eigen::Vector3i::Ones();
    std::vector<uint32_t> cell_start_, cell_triangles_;  // CSR: the triangles overlapping each cell
};

// Distances from a set of points to a surface, summarised in millimetres.
struct DistanceFigures {
    double mean_mm = 0;
    double p99_mm = 0;  // 99th percentile
    double max_mm = 0;
    size_t samples = 0;
};
// From every vertex of `from` to the surface of `to` (both in the same frame, metres). Parallel over vertices.
// max_samples > 0: from every k-th vertex only, k chosen so that at most max_samples are measured.
DistanceFigures vertexToSurfaceDistance(const IndexedMesh& from, const IndexedMesh& to, size_t max_samples = 0);

}  // namespace facescan::recon
