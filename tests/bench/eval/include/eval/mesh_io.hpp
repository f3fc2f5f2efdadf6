// Mesh files through OpenMesh (PLY, OBJ, OFF, STL), in metres, with vertex colours and normals when present.
#pragma once

#include <filesystem>

#include "recon/mesh.hpp"
#include "recon/status.hpp"

namespace facescan::eval {

// Reads a mesh; vertex normals are computed when the file has none. NotFound / DataLoss on failure.
StatusOr<recon::Mesh> readMesh(const std::filesystem::path& path);
// Writes a mesh with vertex normals and colours (binary PLY when the extension is .ply).
Status writeMesh(const recon::Mesh& mesh, const std::filesystem::path& path);

}  // namespace facescan::eval
