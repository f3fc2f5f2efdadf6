// Marching cubes (thesis section 4.2.2, Lorensen and Cline): the zero level set of D(x) as an indexed triangle
// mesh with shared vertices, in metres in the world frame (the first frame's camera), with vertex colours from the
// voxels (and, on request, vertex normals from the gradient of D). Small disconnected fragments are removed.
// The volume is meshed block by block (8^3 voxels); IncrementalMesher keeps each block's triangles between calls
// and re-meshes only the blocks whose voxels changed, which is what makes 1 Hz live snapshots cheap.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "recon/indexed_mesh.hpp"
#include "recon/mesh.hpp"
#include "recon/status.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

struct MeshParams {
    int stride_vox = 1;                // voxels; 1 = full resolution, 2 = a coarser preview (cubes of 2 voxels)
    float min_weight = 0.0f;           // cubes with a corner of weight <= this are skipped (unobserved space)
    float min_fragment_share = 0.05f;  // ratio; connected pieces with fewer triangles than this share of the
                                       // largest piece are removed (0 keeps everything)
    bool colours = true;               // interpolate vertex colours from the voxels
    // ratio of a cube edge; a zero crossing is kept at least this far from the edge's corners (0: where D says).
    // A closed solid needs it: crossings at a corner's micrometres give triangles that a mesh's cleaning or the
    // wire's 0.05 mm grid collapse, which opens the surface there.
    float min_crossing = 0.0f;
    bool gradient_normals = false;  // vertex normals from the gradient of D (eq. 4.30); off: no normals (the
                                    // wire and the files recompute them from the triangles)
    Status validate() const;
};

// Extracts the mesh from a grid (a TsdfVolume's or a snapshot). Never fails: an empty grid gives an empty mesh.
IndexedMesh extractTriangles(const VoxelBlockGrid& grid, const MeshParams& p = {});
// The same as an OpenMesh mesh, always with gradient normals (for code that walks neighbourhoods).
Mesh extractMesh(const VoxelBlockGrid& grid, const MeshParams& p = {});

// One block's share of the mesh: the cubes whose lowest corner lies in the block. A cube also reads the first
// voxel layer of the +x/+y/+z neighbours, so a block is stale when it or one of those 7 neighbours changed.
struct BlockMesh {
    std::vector<int64_t> keys;                      // per vertex: the grid edge it lies on (welds across blocks)
    std::vector<Eigen::Vector3f> positions_vox;     // per vertex, voxel coordinates
    std::vector<Rgb8> colours_rgb;                  // per vertex
    std::vector<Triangle> triangles;                // local vertex indices
    std::unordered_map<int64_t, uint32_t> scratch;  // edge key -> local vertex while meshing (capacity reused)
    void clear();
};

class IncrementalMesher {
 public:
    explicit IncrementalMesher(const MeshParams& p) : params_(p) {}

    // The mesh of `grid`, equal to extractTriangles(grid, params): blocks whose voxels (and +x/+y/+z neighbours'
    // voxels) are byte-identical to the previous call's grid keep their triangles; the rest are meshed again.
    // `grid` is swapped with the mesher's copy of the previous grid (no copy is made): afterwards it holds stale
    // voxels, ready to be overwritten by the next VoxelBlockGrid::copyTo. A grid that was reset, moved or
    // resized starts over.
    IndexedMesh update(VoxelBlockGrid& grid);
    void reset();

    struct Stats {
        int blocks = 0;           // allocated blocks in the last grid
        int blocks_changed = 0;   // of which new or with changed voxels
        int blocks_remeshed = 0;  // changed, or next to a changed one
    };
    const Stats& lastStats() const { return stats_; }

 private:
    MeshParams params_;
    VoxelBlockGrid previous_;
    std::vector<BlockMesh> cache_;  // by pool index of previous_
    Stats stats_;
};

}  // namespace facescan::recon
