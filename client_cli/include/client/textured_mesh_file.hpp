// The finished model with its texture on the client: decoded from a GET_MESH reply that carries it
// (CommandReply::texture, the payload then Draco with texture coordinates) and written as the files that keep a
// texture: GLB (the atlas inside, as the material's baseColorTexture), OBJ + MTL + PNG, PLY with texture coordinates
// + PNG. Every file is written atomically (mesh_file.hpp); the picture and the material first, the mesh file that
// names them last.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "client/mesh_file.hpp"
#include "recon/status.hpp"
#include "recon/texture_atlas.hpp"

namespace facescan::client {

// GLB, OBJ and PLY keep a texture; the other formats get the vertex colours.
bool formatHasTexture(MeshFormat format);

// DataLoss when the Draco bytes are corrupt or have no texture coordinates, or the picture is not an image (PNG,
// colour) that OpenCV decodes; the texture's size is capped (recon::TextureParams::max_atlas_px a side).
StatusOr<recon::TexturedMesh> decodeTexturedMesh(const std::vector<uint8_t>& draco, const std::vector<uint8_t>& png);

// The textured model at `path` (its extension: .glb, .obj or .ply) and the files beside it: .obj writes STEM.mtl
// and STEM.png too, .ply STEM.png (named in its header); STEM is the file's name without the extension, with
// spaces made underscores for the names inside the files. Returns every path written, the mesh file first.
// InvalidArgument for a format without a texture; Unavailable when a file cannot be written.
StatusOr<std::vector<std::filesystem::path>> writeTexturedMeshFiles(const recon::TexturedMesh& mesh,
                                                                    const std::filesystem::path& path);

// The bytes of the textured model as one file: GLB only (the others need a picture beside them).
StatusOr<std::string> texturedGlbBytes(const recon::TexturedMesh& mesh);

}  // namespace facescan::client
