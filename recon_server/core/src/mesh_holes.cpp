// The finishing stage's closing of holes (finishing.hpp). OpenMesh 9 has no hole filler, so this is ours: the
// boundary loops of the mesh, and a fan of new triangles around each small loop's centroid. Only triangles and one
// vertex per hole are added: the surface that was seen keeps every vertex where it was.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <unordered_map>

#include "recon/finishing.hpp"

namespace facescan::recon {
namespace {

uint64_t edgeKey(uint32_t a, uint32_t b) { return (static_cast<uint64_t>(a) << 32) | b; }

struct Loop {
    std::vector<uint32_t> vertices;  // in the order of the boundary half-edges (a -> b as a triangle has them)
    bool simple = true;              // no vertex with two boundary edges leaving it
    double perimeter_m = 0;
};

std::vector<Loop> boundaryLoops(const IndexedMesh& mesh) {
    std::unordered_map<uint64_t, uint32_t> directed;  // half-edge -> how many triangles have it
    directed.reserve(mesh.triangleCount() * 3);
    for (const Triangle& t : mesh.triangles) {
        for (int k = 0; k < 3; ++k) ++directed[edgeKey(t[k], t[(k + 1) % 3])];
    }
    std::unordered_multimap<uint32_t, uint32_t> next;  // boundary half-edges a -> b
    std::vector<uint8_t> out_degree(mesh.vertexCount(), 0);
    for (const auto& [key, count] : directed) {
        const auto a = static_cast<uint32_t>(key >> 32), b = static_cast<uint32_t>(key & 0xffffffffu);
        if (count == 1 && !directed.count(edgeKey(b, a))) {
            next.emplace(a, b);
            if (out_degree[a] < 255) ++out_degree[a];
        }
    }
    std::vector<Loop> loops;
    std::unordered_map<uint64_t, bool> used;
    for (const auto& [start_a, start_b] : next) {
        if (used.count(edgeKey(start_a, start_b))) continue;
        Loop loop;
        uint32_t a = start_a, b = start_b;
        for (size_t steps = 0; steps <= next.size(); ++steps) {
            used[edgeKey(a, b)] = true;
            loop.vertices.push_back(a);
            loop.perimeter_m += (mesh.positions_m[b] - mesh.positions_m[a]).norm();
            if (out_degree[a] > 1) loop.simple = false;
            if (b == start_a) break;
            // At a pinched vertex the walk takes any unused boundary edge; such a loop is not filled anyway.
            uint32_t c = b;
            auto range = next.equal_range(b);
            bool found = false;
            for (auto it = range.first; it != range.second; ++it) {
                if (!used.count(edgeKey(b, it->second))) {
                    c = it->second;
                    found = true;
                    break;
                }
            }
            if (!found) {
                loop.simple = false;
                break;
            }
            a = b;
            b = c;
        }
        loops.push_back(std::move(loop));
    }
    return loops;
}

}  // namespace

void fillHoles(IndexedMesh& mesh, float max_hole_m, FinishReport& report) {
    std::vector<Loop> loops = boundaryLoops(mesh);
    if (loops.empty()) return;
    // The longest loop is the scan's rim (where the sensor's view ended): `holes` never closes it.
    const auto rim = std::max_element(loops.begin(), loops.end(),
                                      [](const Loop& x, const Loop& y) { return x.perimeter_m < y.perimeter_m; });
    const bool colours = mesh.hasColours();
    const size_t triangles_before = mesh.triangleCount();
    size_t too_large = 0, slits = 0;
    std::vector<Triangle> fill;
    for (auto it = loops.begin(); it != loops.end(); ++it) {
        const Loop& loop = *it;
        if (it == rim || !loop.simple || loop.vertices.size() < 3) {
            ++report.holes_left;
            continue;
        }
        Eigen::Vector3d centre = Eigen::Vector3d::Zero();
        Eigen::Vector3d colour = Eigen::Vector3d::Zero();
        for (const uint32_t v : loop.vertices) {
            centre += mesh.positions_m[v].cast<double>();
            if (colours)
                colour += Eigen::Vector3d(mesh.colours_rgb[v][0], mesh.colours_rgb[v][1], mesh.colours_rgb[v][2]);
        }
        const double n = static_cast<double>(loop.vertices.size());
        const Eigen::Vector3f c = (centre / n).cast<float>();
        float radius_m = 0;
        for (const uint32_t v : loop.vertices) radius_m = std::max(radius_m, (mesh.positions_m[v] - c).norm());
        if (2 * radius_m > max_hole_m) {
            ++report.holes_left;
            ++too_large;
            continue;
        }
        // The fill: one triangle for a three-edge hole, else a fan around the centroid. A hole whose fill would
        // hold a zero-area triangle (a slit: its rim runs straight through the centroid) stays as it is: such a
        // triangle is a defect that the service promises not to deliver (indexed_mesh.hpp).
        const auto centre_index = static_cast<uint32_t>(mesh.positions_m.size());
        fill.clear();
        if (loop.vertices.size() == 3) {
            fill.push_back({loop.vertices[2], loop.vertices[1], loop.vertices[0]});
        } else {
            // Boundary half-edge a -> b belongs to a triangle; the fill triangle has b -> a (same orientation).
            for (size_t i = 0; i < loop.vertices.size(); ++i) {
                const uint32_t a = loop.vertices[i], b = loop.vertices[(i + 1) % loop.vertices.size()];
                fill.push_back({b, a, centre_index});
            }
        }
        auto position = [&](uint32_t v) -> Eigen::Vector3f { return v == centre_index ? c : mesh.positions_m[v]; };
        const bool degenerate = std::any_of(fill.begin(), fill.end(), [&](const Triangle& t) {
            const Eigen::Vector3d p0 = position(t[0]).cast<double>();
            const double area_m2 =
                0.5 * (position(t[1]).cast<double>() - p0).cross(position(t[2]).cast<double>() - p0).norm();
            return area_m2 <= 10 * kZeroAreaM2;
        });
        if (degenerate) {
            ++report.holes_left;
            ++slits;
            continue;
        }
        if (loop.vertices.size() > 3) {
            mesh.positions_m.push_back(c);
            if (colours) {
                colour /= n;
                mesh.colours_rgb.push_back({static_cast<uint8_t>(std::lround(colour.x())),
                                            static_cast<uint8_t>(std::lround(colour.y())),
                                            static_cast<uint8_t>(std::lround(colour.z()))});
            }
            if (!mesh.normals.empty()) mesh.normals.emplace_back(Eigen::Vector3f::Zero());
        }
        mesh.triangles.insert(mesh.triangles.end(), fill.begin(), fill.end());
        ++report.holes_filled;
    }
    report.triangles_added += mesh.triangleCount() - triangles_before;
    if (too_large > 0) {
        char buf[160];
        std::snprintf(buf, sizeof buf, "%zu hole%s wider than %.0f mm left open", too_large, too_large == 1 ? "" : "s",
                      static_cast<double>(max_hole_m) * 1e3);
        report.notes.emplace_back(buf);
    }
    if (slits > 0) {
        report.notes.push_back(std::to_string(slits) + " slit" + (slits == 1 ? "" : "s") +
                               " (holes without area) left as they were");
    }
    if (mesh.triangleCount() != triangles_before) computeVertexNormals(mesh);
}

}  // namespace facescan::recon
