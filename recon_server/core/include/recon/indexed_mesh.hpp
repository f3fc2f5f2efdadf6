// A triangle mesh as flat arrays: what marching cubes emits, what the wire carries and what the mesh files hold.
// There is no half-edge structure: building OpenMesh's connectivity took 33 ms of a 59 ms decode, and
// writing PLY, OBJ, STL or OFF needs none. toOpenMesh() gives the half-edge mesh to code that walks neighbourhoods.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "recon/mesh.hpp"

namespace facescan::recon {

using Rgb8 = std::array<uint8_t, 3>;
using Triangle = std::array<uint32_t, 3>;  // vertex indices, counter-clockwise seen from outside

struct IndexedMesh {
    std::vector<Eigen::Vector3f> positions_m;  // metres
    std::vector<Eigen::Vector3f> normals;      // unit, one per vertex, or empty (recompute with computeVertexNormals)
    std::vector<Rgb8> colours_rgb;             // one per vertex, or empty
    std::vector<Triangle> triangles;

    size_t vertexCount() const { return positions_m.size(); }
    size_t triangleCount() const { return triangles.size(); }
    bool hasNormals() const { return !normals.empty() && normals.size() == positions_m.size(); }
    bool hasColours() const { return !colours_rgb.empty() && colours_rgb.size() == positions_m.size(); }
    void clear();
};

// Per-vertex normals as the area-weighted mean of the adjacent faces' normals (the sum of the unnormalised cross
// products), which is what receivers do now that normals are not on the wire (three.js computeVertexNormals does
// the same). A vertex without a non-degenerate face gets (0, 0, 0).
std::vector<Eigen::Vector3f> vertexNormals(const IndexedMesh& mesh);
inline void computeVertexNormals(IndexedMesh& mesh) { mesh.normals = vertexNormals(mesh); }

// A triangle is zero-area when two of its indices repeat or its area is at most this (1 um^2). Nothing legitimate
// is that small: a voxel is 1.51 mm, and the smallest triangle Draco's 0.05 mm grid can hold is ~1e-9 m^2.
inline constexpr double kZeroAreaM2 = 1e-12;

// What mesh tools choke on. Vertices with identical positions count as one (Draco splits non-manifold vertices
// into copies; a file reader welds them back), so duplicates and manifoldness are judged by position.
struct MeshDefects {
    size_t zero_area_triangles = 0;    // see kZeroAreaM2
    size_t duplicate_triangles = 0;    // same three positions as another triangle, in any order (extra copies)
    size_t unreferenced_vertices = 0;  // in no triangle
    size_t non_manifold_edges = 0;     // edges shared by more than two triangles
    size_t non_manifold_vertices = 0;  // vertices whose triangles form more than one fan (edge-connected piece)
    size_t boundary_edges = 0;         // edges of exactly one triangle (holes and the scan's rim: expected)
    // The service's promise: no zero-area, duplicate triangle or unreferenced vertex.
    bool clean() const { return zero_area_triangles == 0 && duplicate_triangles == 0 && unreferenced_vertices == 0; }
};
MeshDefects countDefects(const IndexedMesh& mesh);

// Welds vertices with identical positions (keeping the first's colour), then drops zero-area and duplicate
// triangles and the vertices no triangle uses. Normals, if any, are kept per surviving vertex. Afterwards
// countDefects(mesh).clean() holds.
void removeDefects(IndexedMesh& mesh);

// The half-edge mesh of the same triangles. OpenMesh refuses faces at non-manifold edges and vertices; such a face
// gets its own copies of its vertices, like OpenMesh's file readers do, so no triangle is lost. Normals are
// computed when `mesh` has none.
Mesh toOpenMesh(const IndexedMesh& mesh);
// The arrays of an OpenMesh mesh (deleted elements skipped; faces that are not triangles are fanned).
IndexedMesh fromOpenMesh(const Mesh& mesh);

}  // namespace facescan::recon
