// Output files of the client: meshes through OpenMesh (PLY, OBJ, STL, OFF) or Draco (DRC), chosen by extension,
// and plain byte files (PNG, TUM text). Every file is written atomically: a temporary file beside the target,
// flushed to disk, then renamed over it, so a reader never sees half a mesh and a failed write leaves nothing.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string_view>
#include <vector>

#include "recon/mesh.hpp"
#include "recon/status.hpp"

namespace facescan::client {

enum class MeshFormat { kPly, kObj, kStl, kOff, kDrc };

// The format of a path by its extension (case-insensitive). InvalidArgument for anything else.
StatusOr<MeshFormat> meshFormatFor(const std::filesystem::path& path);
// "ply", "obj", ... (the extension without the dot).
const char* meshFormatName(MeshFormat format);
// Whether the format keeps vertex colours (PLY, OBJ, OFF, DRC: yes; STL: no).
bool formatHasColours(MeshFormat format);

// Fails early (before any network work) when `path` cannot be written: a missing or read-only folder, or a
// folder in the way. Unavailable with the reason.
Status checkWritable(const std::filesystem::path& path);

// Writes `bytes` to `path` atomically (temporary file + fsync + rename). Unavailable with the reason.
Status writeFileAtomically(const std::filesystem::path& path, std::string_view bytes);

// Writes `mesh` in the format of `path`'s extension, atomically: binary PLY with normals and colours, OBJ and
// OFF with normals and colours, binary STL, or Draco (positions, normals, colours). For .drc, `draco_bytes`
// (the server's payload), when not null, is written as it is instead of encoding `mesh` again.
Status writeMeshFile(const recon::Mesh& mesh, const std::filesystem::path& path,
                     const std::vector<uint8_t>* draco_bytes = nullptr);

}  // namespace facescan::client
