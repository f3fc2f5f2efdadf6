// Point-to-surface distances for the finishing stage's report (mesh_distance.hpp).
#include "recon/mesh_distance.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "recon/parallel.hpp"

namespace facescan::recon {

using Vec3 = Eigen::Vector3f;

Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
    const Vec3 ab = b - a, ac = c - a, ap = p - a;
    const float d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return a;
    const Vec3 bp = p - b;
    const float d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return b;
    const float vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
    const Vec3 cp = p - c;
    const float d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return c;
    const float vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
    const float va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    const float denom = 1.0f / (va + vb + vc);
    return a + ab * (vb * denom) + ac * (vc * denom);
}

namespace {
// The grid never gets more cells than this per axis (a 0.4 m head at 2 mm cells is 200).
constexpr int kMaxCellsPerAxis = 256;
// Share of a cell by which a cell's box is grown when it is skipped for lying farther than the best triangle found:
// the cells' bounds are computed in floats, as are the triangles' cells.
constexpr float kCellPad = 1e-3f;
}  // namespace

TriangleGrid::TriangleGrid(const IndexedMesh& mesh) : positions_m_(mesh.positions_m) {
    triangles_.reserve(mesh.triangleCount());
    for (const Triangle& t : mesh.triangles) {
        if (t[0] < positions_m_.size() && t[1] < positions_m_.size() && t[2] < positions_m_.size()) {
            triangles_.push_back(t);
        }
    }
    if (triangles_.empty()) return;
    Vec3 lo = Vec3::Constant(std::numeric_limits<float>::max()), hi = -lo;
    double edge_sum = 0;
    for (const Triangle& t : triangles_) {
        for (int k = 0; k < 3; ++k) {
            lo = lo.cwiseMin(positions_m_[t[k]]);
            hi = hi.cwiseMax(positions_m_[t[k]]);
            edge_sum += (positions_m_[t[k]] - positions_m_[t[(k + 1) % 3]]).norm();
        }
    }
    const float mean_edge_m = static_cast<float>(edge_sum / (3.0 * static_cast<double>(triangles_.size())));
    const float extent_m = (hi - lo).maxCoeff();
    cell_m_ = std::max({2.0f * mean_edge_m, extent_m / kMaxCellsPerAxis, 1e-6f});
    origin_m_ = lo;
    for (int a = 0; a < 3; ++a) dims_[a] = std::max(1, static_cast<int>(std::floor((hi[a] - lo[a]) / cell_m_)) + 1);
    const size_t cells = static_cast<size_t>(dims_.x()) * dims_.y() * dims_.z();
    auto cellRange = [&](const Triangle& t, Eigen::Vector3i& c0, Eigen::Vector3i& c1) {
        const Vec3 tlo = positions_m_[t[0]].cwiseMin(positions_m_[t[1]]).cwiseMin(positions_m_[t[2]]);
        const Vec3 thi = positions_m_[t[0]].cwiseMax(positions_m_[t[1]]).cwiseMax(positions_m_[t[2]]);
        for (int a = 0; a < 3; ++a) {
            c0[a] = std::clamp(static_cast<int>((tlo[a] - origin_m_[a]) / cell_m_), 0, dims_[a] - 1);
            c1[a] = std::clamp(static_cast<int>((thi[a] - origin_m_[a]) / cell_m_), 0, dims_[a] - 1);
        }
    };
    auto cellIndex = [&](int x, int y, int z) { return (static_cast<size_t>(z) * dims_.y() + y) * dims_.x() + x; };
    cell_start_.assign(cells + 1, 0);
    Eigen::Vector3i c0, c1;
    for (const Triangle& t : triangles_) {
        cellRange(t, c0, c1);
        for (int z = c0.z(); z <= c1.z(); ++z)
            for (int y = c0.y(); y <= c1.y(); ++y)
                for (int x = c0.x(); x <= c1.x(); ++x) ++cell_start_[cellIndex(x, y, z) + 1];
    }
    for (size_t i = 0; i < cells; ++i) cell_start_[i + 1] += cell_start_[i];
    cell_triangles_.resize(cell_start_[cells]);
    std::vector<uint32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
    for (uint32_t i = 0; i < triangles_.size(); ++i) {
        cellRange(triangles_[i], c0, c1);
        for (int z = c0.z(); z <= c1.z(); ++z)
            for (int y = c0.y(); y <= c1.y(); ++y)
                for (int x = c0.x(); x <= c1.x(); ++x) cell_triangles_[fill[cellIndex(x, y, z)]++] = i;
    }
}

float TriangleGrid::distance(const Vec3& p) const {
    float best_sq = std::numeric_limits<float>::infinity();
    if (triangles_.empty()) return best_sq;
    Eigen::Vector3i c;
    for (int a = 0; a < 3; ++a) {
        c[a] = std::clamp(static_cast<int>(std::floor((p[a] - origin_m_[a]) / cell_m_)), 0, dims_[a] - 1);
    }
    const Vec3 hi = origin_m_ + dims_.cast<float>() * cell_m_;
    const float outside_m = (origin_m_ - p).cwiseMax(p - hi).cwiseMax(0.0f).norm();
    const int max_ring = dims_.maxCoeff();
    for (int r = 0; r <= max_ring; ++r) {
        // Every cell of ring r is at least r - 1 cells from p (p lies inside its own cell), and at least as far
        // as the grid's box when p lies outside it (then it was clamped onto the nearest cell).
        const float ring_min_m = std::max(outside_m, static_cast<float>(r - 1) * cell_m_);
        if (r > 0 && ring_min_m > 0 && ring_min_m * ring_min_m > best_sq) break;
        const int z0 = std::max(0, c.z() - r), z1 = std::min(dims_.z() - 1, c.z() + r);
        const int y0 = std::max(0, c.y() - r), y1 = std::min(dims_.y() - 1, c.y() + r);
        const int x0 = std::max(0, c.x() - r), x1 = std::min(dims_.x() - 1, c.x() + r);
        for (int z = z0; z <= z1; ++z) {
            for (int y = y0; y <= y1; ++y) {
                const bool shell_zy = std::abs(z - c.z()) == r || std::abs(y - c.y()) == r;
                // Inside the shell only the two x ends belong to ring r.
                const int step = shell_zy ? 1 : std::max(1, x1 - x0);
                for (int x = x0; x <= x1; x += step) {
                    if (!shell_zy && std::abs(x - c.x()) != r) continue;
                    const size_t cell = (static_cast<size_t>(z) * dims_.y() + y) * dims_.x() + x;
                    if (cell_start_[cell] == cell_start_[cell + 1]) continue;
                    // A cell's triangles are no nearer than its box (grown a little against rounding; the outer
                    // cells open outwards, as the grid clamps onto them): a point on the surface has its answer
                    // from one or two cells, not from all 27 around it.
                    const Eigen::Vector3i at(x, y, z);
                    float gap_sq = 0;
                    for (int a = 0; a < 3; ++a) {
                        const float cell_lo = origin_m_[a] + (static_cast<float>(at[a]) - kCellPad) * cell_m_;
                        const float cell_hi = origin_m_[a] + (static_cast<float>(at[a]) + 1 + kCellPad) * cell_m_;
                        const float gap = at[a] > 0 && p[a] < cell_lo              ? cell_lo - p[a]
                                          : at[a] + 1 < dims_[a] && p[a] > cell_hi ? p[a] - cell_hi
                                                                                   : 0.0f;
                        gap_sq += gap * gap;
                    }
                    if (gap_sq > best_sq) continue;
                    for (uint32_t k = cell_start_[cell]; k < cell_start_[cell + 1]; ++k) {
                        const Triangle& t = triangles_[cell_triangles_[k]];
                        const Vec3 q =
                            closestPointOnTriangle(p, positions_m_[t[0]], positions_m_[t[1]], positions_m_[t[2]]);
                        best_sq = std::min(best_sq, (q - p).squaredNorm());
                    }
                }
            }
        }
    }
    return std::sqrt(best_sq);
}

DistanceFigures vertexToSurfaceDistance(const IndexedMesh& from, const IndexedMesh& to, size_t max_samples) {
    DistanceFigures out;
    const TriangleGrid grid(to);
    if (grid.empty() || from.positions_m.empty()) return out;
    const size_t n = from.positions_m.size();
    const size_t stride = max_samples > 0 ? (n + max_samples - 1) / max_samples : 1;
    std::vector<float> d((n + stride - 1) / stride);
    parallelFor(0, static_cast<int>(d.size()), [&](int lo, int hi) {
        for (int i = lo; i < hi; ++i) {
            d[static_cast<size_t>(i)] = grid.distance(from.positions_m[static_cast<size_t>(i) * stride]);
        }
    });
    double sum = 0;
    for (const float v : d) sum += v;
    out.samples = d.size();
    out.mean_mm = 1e3 * sum / static_cast<double>(d.size());
    const size_t k99 = std::min(d.size() - 1, static_cast<size_t>(std::ceil(0.99 * static_cast<double>(d.size()))) - 1);
    std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(k99), d.end());
    out.p99_mm = 1e3 * d[k99];
    out.max_mm = 1e3 * *std::max_element(d.begin(), d.end());
    return out;
}

}  // namespace facescan::recon
