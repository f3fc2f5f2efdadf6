// The bytes of the common mesh files, textured or not, from an IndexedMesh, without a half-edge structure: OpenMesh's
// PLY, STL and OFF writers read the arrays through an exporter (OpenMesh::IO::BaseExporter), OBJ is written here
// (OpenMesh's OBJ writer keeps colours only as per-face materials in a separate .mtl file). Bytes only: the caller
// writes the file (the recon core does no I/O).
#pragma once

#include <string>

#include "recon/indexed_mesh.hpp"
#include "recon/status.hpp"
#include "recon/texture_atlas.hpp"

namespace facescan::recon {

enum class MeshFileFormat { kPly, kObj, kStl, kOff };

// Binary PLY with normals and 8-bit colours; OBJ and OFF (text) with normals and colours; binary STL (face normals,
// no colours). Vertex normals come from the triangles when the mesh has none. Positions keep every float bit
// (9 significant digits). InvalidArgument for a mesh without triangles; Internal if OpenMesh's writer fails.
StatusOr<std::string> meshFileBytes(const IndexedMesh& mesh, MeshFileFormat format);

// A textured mesh (texture_atlas.hpp) as OBJ + MTL + PNG: the OBJ holds v (with the vertex colours, as above),
// vt, vn and faces v/vt/vn, and names `stem`.mtl, whose one material maps `stem`.png (the atlas, PNG bytes).
struct TexturedObjFiles {
    std::string obj, mtl, png;
};
// InvalidArgument for a mesh without triangles or uv, or a stem that is not a plain file name; Internal when
// OpenCV cannot encode the PNG.
StatusOr<TexturedObjFiles> texturedObjFiles(const TexturedMesh& mesh, const std::string& stem);
// Binary PLY with normals, colours and per-vertex texture coordinates (properties u, v; v up, as MeshLab and
// Blender read them), naming its image in a `comment TextureFile` header line (MeshLab's convention).
StatusOr<std::string> texturedPlyBytes(const TexturedMesh& mesh, const std::string& texture_file);
// The atlas as PNG bytes.
StatusOr<std::string> atlasPngBytes(const TexturedMesh& mesh);

}  // namespace facescan::recon
