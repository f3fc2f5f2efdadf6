// The bytes of the common mesh files from an IndexedMesh, without a half-edge structure: OpenMesh's PLY, STL and
// OFF writers read the arrays through an exporter (OpenMesh::IO::BaseExporter), OBJ is written here (OpenMesh's
// OBJ writer keeps colours only as per-face materials in a separate .mtl file). Bytes only: the caller writes
// the file (the recon core does no I/O).
#pragma once

#include <string>

#include "recon/indexed_mesh.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

enum class MeshFileFormat { kPly, kObj, kStl, kOff };

// Binary PLY with normals and 8-bit colours; OBJ and OFF (text) with normals and colours; binary STL (face normals,
// no colours). Vertex normals come from the triangles when the mesh has none. Positions keep every float bit
// (9 significant digits). InvalidArgument for a mesh without triangles; Internal if OpenMesh's writer fails.
StatusOr<std::string> meshFileBytes(const IndexedMesh& mesh, MeshFileFormat format);

}  // namespace facescan::recon
