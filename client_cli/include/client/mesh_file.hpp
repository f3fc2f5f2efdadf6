// Output files of the client: meshes as PLY, OBJ, STL, OFF (recon/mesh_writer.hpp: OpenMesh's writers over flat
// arrays, no half-edge structure), Draco (DRC) or TinyGLTF (GLB), chosen by extension, and plain byte files (PNG, TUM
// text). Every file is written atomically: a temporary file beside the target, flushed to disk, then renamed over it,
// so a reader never sees half a mesh and a failed write leaves nothing.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string_view>
#include <vector>

#include "recon/indexed_mesh.hpp"
#include "recon/mesh.hpp"
#include "recon/status.hpp"

namespace facescan::client {

enum class MeshFormat { kPly, kObj, kStl, kOff, kDrc, kGlb };

// The format of a path by its extension (case-insensitive). InvalidArgument for anything else.
StatusOr<MeshFormat> meshFormatFor(const std::filesystem::path& path);
// "ply", "obj", ... (the extension without the dot).
const char* meshFormatName(MeshFormat format);
// Whether the format keeps vertex colours (PLY, OBJ, OFF, DRC, GLB: yes; STL: no).
bool formatHasColours(MeshFormat format);

// Fails early (before any network work) when `path` cannot be written: a missing or read-only folder, or a
// folder in the way. Unavailable with the reason.
Status checkWritable(const std::filesystem::path& path);

// Writes `bytes` to `path` atomically (temporary file + fsync + rename). Unavailable with the reason.
Status writeFileAtomically(const std::filesystem::path& path, std::string_view bytes);

// The bytes of `mesh` in `format`: binary PLY with normals and colours, OBJ and OFF with normals and colours,
// binary STL, Draco (positions, colours), or glTF binary (client/gltf_mesh.hpp); normals are computed from the
// triangles when the mesh has none. For DRC, `draco_bytes` (the server's payload), when not null, is used as it is
// instead of encoding `mesh` again. InvalidArgument for a mesh without triangles.
StatusOr<std::string> encodeMeshFile(const recon::IndexedMesh& mesh, MeshFormat format,
                                     const std::vector<uint8_t>* draco_bytes = nullptr);
StatusOr<std::string> encodeMeshFile(const recon::Mesh& mesh, MeshFormat format,
                                     const std::vector<uint8_t>* draco_bytes = nullptr);
// The MIME type of a format's bytes (for the web viewer's downloads).
const char* meshMimeType(MeshFormat format);

// Writes encodeMeshFile(mesh, format of `path`'s extension) to `path` atomically.
Status writeMeshFile(const recon::IndexedMesh& mesh, const std::filesystem::path& path,
                     const std::vector<uint8_t>* draco_bytes = nullptr);
Status writeMeshFile(const recon::Mesh& mesh, const std::filesystem::path& path,
                     const std::vector<uint8_t>* draco_bytes = nullptr);

}  // namespace facescan::client
