// glTF 2.0 binary (.glb) of a facescan mesh, through TinyGLTF (Debian's libtinygltf-dev): one triangle mesh with
// POSITION, NORMAL (the mesh's, or computed from its triangles) and COLOR_0 (8-bit RGBA, normalised), uint32 indices,
// and a matte double-sided material, so that any glTF viewer (Blender, three.js, Windows 3D Viewer) shows the colours.
#pragma once

#include <string>

#include "recon/indexed_mesh.hpp"
#include "recon/mesh.hpp"
#include "recon/status.hpp"
#include "recon/texture_atlas.hpp"

namespace facescan::client {

// glTF's axes are +Y up with the viewer on +Z; our meshes are in the first camera's frame (x right, y down, z away
// from the camera). The GLB holds the mesh rotated 180 degrees about x, (x, y, z) -> (x, -y, -z), so the face is
// upright and faces a glTF viewer's default camera. Units stay metres, glTF's own unit.
// InvalidArgument for a mesh without triangles or with non-finite points; Internal when TinyGLTF refuses it.
StatusOr<std::string> meshToGlb(const recon::IndexedMesh& mesh);
StatusOr<std::string> meshToGlb(const recon::Mesh& mesh);
// A textured mesh (recon/texture_atlas.hpp): TEXCOORD_0 and the atlas as PNG, in the binary chunk, as the material's
// baseColorTexture. glTF multiplies COLOR_0 into that texture, so the vertex colours are left out here.
StatusOr<std::string> meshToGlb(const recon::TexturedMesh& mesh);

}  // namespace facescan::client
