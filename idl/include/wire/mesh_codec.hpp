// Mesh codec for MeshSnapshot.draco and ScanReply.payload: Draco (edgebreaker) with positions in metres and 8-bit
// vertex colours; no normals (receivers recompute them from the triangles, as three.js does). Positions
// are quantised on a grid derived from the mesh's bounding box and the allowed error (default 0.05 mm, well under
// the 1.51 mm voxel of docs/design.md section 1). The encoder cleans the mesh on that grid before encoding, so the
// decoded mesh has no zero-area or duplicate triangle and no unreferenced vertex (recon::MeshDefects::clean).
//
// Draco's own decoder sizes its tables from counts in the bitstream; decodeMeshDraco reads and caps those counts
// (and the header fields) itself before Draco sees the bytes, so a lying header cannot make it over-allocate.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "recon/indexed_mesh.hpp"
#include "recon/mesh.hpp"
#include "recon/status.hpp"
#include "recon/texture_atlas.hpp"

namespace facescan::wire {

// A face mesh from a 256^3 volume has a few 100k vertices; ten times that is still a face, more is an attack.
inline constexpr size_t kMaxMeshVertices = 4'000'000;

struct MeshCodecParams {
    float max_position_error_m = 0.05e-3f;  // metres, Euclidean; quantisation keeps every vertex within this
    int position_bits = 0;  // [0, 30] bits per coordinate; 0 = the fewest that honour max_position_error_m
    // metres; > 0: the positions lie on the lines of a cubic lattice of this spacing through lattice_origin_m (the
    // TSDF voxel grid, for marching-cubes meshes): the quantisation grid is aligned with it (see encodeMeshDraco)
    float lattice_step_m = 0.0f;
    Eigen::Vector3f lattice_origin_m = Eigen::Vector3f::Zero();  // metres
    int normal_bits = 0;  // [0, 30] octahedral normal bits; 0 = leave normals out (the receiver recomputes them)
    bool colours = true;  // send the 8-bit vertex colours (lossless)
    // Draco encode/decode speed [0, 10]: without normals 8 is smaller and faster than 7 (facescan-bench mesh
    // --sweep: 143 vs 151 KB, 21 vs 22 ms); 0-1 save 8 % more at 3x the time.
    int speed = 8;
    // [1, 30] bits per texture coordinate (encodeTexturedMeshDraco): 16 put a coordinate within 1/131070 of the
    // atlas, an eighth of a texel of the largest atlas (8192 texels a side)
    int uv_bits = 16;

    Status validate() const;
};

// Bits per coordinate so that the worst Euclidean error, sqrt(3) * extent / (2^bits - 1) / 2, stays below
// max_error_m with a 5% margin for float rounding in Draco's dequantisation. extent_m: the bounding box's largest
// side. A face volume of 0.386 m at 0.05 mm gives 13 bits (47 um steps, at most 41 um error).
int positionBitsFor(float extent_m, float max_error_m);

// Encodes positions (+ colours, normals per params) after moving them onto Draco's quantisation grid and cleaning
// the mesh there: vertices that land on one grid point are welded, the triangles that become zero-area or
// duplicates are dropped, and so are the vertices left unused. `encoded`, when given, receives that cleaned mesh
// (what a receiver decodes, vertex order aside). INVALID_ARGUMENT for a mesh without triangles, with non-finite
// points or out-of-range indices. out is overwritten.
Status encodeMeshDraco(const recon::IndexedMesh& mesh, const MeshCodecParams& params, std::vector<uint8_t>& out,
                       recon::IndexedMesh* encoded = nullptr);
Status encodeMeshDraco(const recon::Mesh& mesh, const MeshCodecParams& params, std::vector<uint8_t>& out);

// The finished model with its texture (recon/texture_atlas.hpp) for ScanReply.payload: positions (quantised within
// max_position_error_m on a grid from the mesh's own bounding box), vertex colours, normals (when normal_bits > 0
// and the mesh has them: its vertices are split where charts meet, and normals computed from the triangles would
// differ on the two sides of a cut) and the texture coordinates as Draco's TEX_COORD (uv_bits each). The mesh is
// not cleaned on the grid as encodeMeshDraco does (welding would join the copies of a vertex on a cut): Draco keeps
// every vertex apart, so no face loses a vertex. INVALID_ARGUMENT for a mesh without triangles or texture
// coordinates, non-finite values or out-of-range indices.
Status encodeTexturedMeshDraco(const recon::TexturedMesh& mesh, const MeshCodecParams& params,
                               std::vector<uint8_t>& out);

// What the Draco header and connectivity prefix claim, read without Draco (see the file comment).
struct DracoMeshInfo {
    int method = 0;                 // 0 sequential, 1 edgebreaker
    uint32_t claimed_vertices = 0;  // sequential: num_points; edgebreaker: encoded vertices + split symbols
    uint32_t claimed_faces = 0;
};
StatusOr<DracoMeshInfo> inspectDracoMesh(const uint8_t* data, size_t size);

// Decodes a Draco triangle mesh of at most max_vertices vertices (and 4x as many faces) into `mesh` (replaced):
// flat arrays, ready to write (recon/mesh_writer.hpp), no half-edge structure. DATA_LOSS for corrupt or truncated
// bytes or a face with a repeated vertex, OUT_OF_RANGE for claims over the caps; never crashes or over-allocates.
// Normals are recomputed from the triangles (area-weighted) when the payload has none.
Status decodeMeshDraco(const uint8_t* data, size_t size, recon::IndexedMesh& mesh,
                       size_t max_vertices = kMaxMeshVertices);
StatusOr<recon::IndexedMesh> decodeIndexedMesh(const uint8_t* data, size_t size,
                                               size_t max_vertices = kMaxMeshVertices);
// The same, and the texture coordinates when the payload has them (TEX_COORD, two floats per vertex, glTF's
// convention: v down); `uv` is left empty when it has none. DATA_LOSS for a coordinate that is not finite.
Status decodeMeshDraco(const uint8_t* data, size_t size, recon::IndexedMesh& mesh, std::vector<Eigen::Vector2f>& uv,
                       size_t max_vertices = kMaxMeshVertices);
// The same as an OpenMesh mesh (recon::toOpenMesh: non-manifold faces get their own vertex copies).
Status decodeMeshDraco(const uint8_t* data, size_t size, recon::Mesh& mesh, size_t max_vertices = kMaxMeshVertices);
StatusOr<recon::Mesh> decodeMeshDraco(const uint8_t* data, size_t size, size_t max_vertices = kMaxMeshVertices);

}  // namespace facescan::wire
