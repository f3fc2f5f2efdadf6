// Marching cubes (thesis section 4.2.2, Lorensen and Cline): the zero level set of D(x) as an indexed triangle
// mesh with shared vertices, in metres in the world frame (the first frame's camera), with vertex normals from the
// gradient of D and vertex colours from the voxels. Small disconnected fragments are removed.
#pragma once

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
    Status validate() const;
};

// Extracts the mesh from a grid (a TsdfVolume's or a snapshot). Never fails: an empty grid gives an empty mesh.
Mesh extractMesh(const VoxelBlockGrid& grid, const MeshParams& p = {});

}  // namespace facescan::recon
