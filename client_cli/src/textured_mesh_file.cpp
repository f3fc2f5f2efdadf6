// The finished model's texture on the client (client/textured_mesh_file.hpp).
#include "client/textured_mesh_file.hpp"

#include <opencv2/imgcodecs.hpp>

#include "client/gltf_mesh.hpp"
#include "recon/mesh_writer.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::client {
namespace fs = std::filesystem;

bool formatHasTexture(MeshFormat format) {
    return format == MeshFormat::kGlb || format == MeshFormat::kObj || format == MeshFormat::kPly;
}

StatusOr<recon::TexturedMesh> decodeTexturedMesh(const std::vector<uint8_t>& draco, const std::vector<uint8_t>& png) {
    recon::TexturedMesh out;
    RETURN_IF_ERROR(wire::decodeMeshDraco(draco.data(), draco.size(), out.mesh, out.uv));
    if (out.uv.empty()) return dataLoss("the textured mesh has no texture coordinates");
    // The header's size first: a hostile picture must not make OpenCV allocate gigabytes.
    if (png.size() < 24 || png[0] != 0x89 || png[1] != 'P' || png[2] != 'N' || png[3] != 'G') {
        return dataLoss("the texture is not a PNG picture (" + std::to_string(png.size()) + " bytes)");
    }
    const auto be32 = [&](size_t at) {
        return uint32_t{png[at]} << 24 | uint32_t{png[at + 1]} << 16 | uint32_t{png[at + 2]} << 8 | png[at + 3];
    };
    const uint32_t width = be32(16), height = be32(20);
    // Any server's setting (texture.max_atlas_px), not this build's default.
    const auto max_px = static_cast<uint32_t>(recon::kMaxAtlasPxLimit);
    if (width == 0 || height == 0 || width > max_px || height > max_px) {
        return dataLoss("the texture claims " + std::to_string(width) + " x " + std::to_string(height) +
                        " pixels (at most " + std::to_string(max_px) + " a side)");
    }
    out.atlas_bgr = cv::imdecode(png, cv::IMREAD_COLOR);
    if (out.atlas_bgr.empty()) return dataLoss("the texture's PNG cannot be decoded");
    return out;
}

StatusOr<std::string> texturedGlbBytes(const recon::TexturedMesh& mesh) { return meshToGlb(mesh); }

StatusOr<std::vector<fs::path>> writeTexturedMeshFiles(const recon::TexturedMesh& mesh, const fs::path& path) {
    ASSIGN_OR_RETURN(const MeshFormat format, meshFormatFor(path));
    if (!formatHasTexture(format)) {
        return invalidArgument(std::string("a .") + meshFormatName(format) +
                               " file keeps no texture: use .glb, .obj or .ply");
    }
    std::vector<fs::path> written;
    if (format == MeshFormat::kGlb) {
        ASSIGN_OR_RETURN(const std::string glb, meshToGlb(mesh));
        RETURN_IF_ERROR(writeFileAtomically(path, glb));
        written.push_back(path);
        return written;
    }
    // The names inside the files are plain names (an OBJ's mtllib and a PLY's TextureFile end at a space).
    std::string stem = path.stem().string();
    for (char& c : stem) {
        if (c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\\') c = '_';
    }
    const fs::path folder = path.parent_path();
    const fs::path png_path = folder / (stem + ".png");
    if (format == MeshFormat::kObj) {
        ASSIGN_OR_RETURN(const recon::TexturedObjFiles files, recon::texturedObjFiles(mesh, stem));
        const fs::path mtl_path = folder / (stem + ".mtl");
        RETURN_IF_ERROR(writeFileAtomically(png_path, files.png));
        RETURN_IF_ERROR(writeFileAtomically(mtl_path, files.mtl));
        RETURN_IF_ERROR(writeFileAtomically(path, files.obj));
        written = {path, mtl_path, png_path};
        return written;
    }
    ASSIGN_OR_RETURN(const std::string png, recon::atlasPngBytes(mesh));
    ASSIGN_OR_RETURN(const std::string ply, recon::texturedPlyBytes(mesh, stem + ".png"));
    RETURN_IF_ERROR(writeFileAtomically(png_path, png));
    RETURN_IF_ERROR(writeFileAtomically(path, ply));
    written = {path, png_path};
    return written;
}

}  // namespace facescan::client
