// libFuzzer target: decodeMeshDraco into the flat arrays a client writes files from (our count checks, then
// Draco's decoder, then the arrays and their recomputed normals), then what the client does with a decoded mesh:
// the PLY/STL bytes (recon/mesh_writer.hpp) and the defect count; with texture coordinates (a finished model's
// TEX_COORD), the textured OBJ and PLY.
#include "recon/mesh_writer.hpp"
#include "wire/mesh_codec.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan;
    constexpr size_t kMaxVertices = 200'000;
    static recon::TexturedMesh textured;
    recon::IndexedMesh& mesh = textured.mesh;
    const Status st = wire::decodeMeshDraco(data, size, mesh, textured.uv, kMaxVertices);
    if (!st.isOk()) return 0;
    if (mesh.vertexCount() > kMaxVertices || !mesh.hasNormals()) __builtin_trap();
    for (const recon::Triangle& t : mesh.triangles) {
        for (const uint32_t v : t) {
            if (v >= mesh.vertexCount()) __builtin_trap();
        }
    }
    (void)recon::countDefects(mesh);
    (void)recon::meshFileBytes(mesh, recon::MeshFileFormat::kPly);
    (void)recon::meshFileBytes(mesh, recon::MeshFileFormat::kStl);
    if (textured.uv.empty()) return 0;
    if (textured.uv.size() != mesh.vertexCount()) __builtin_trap();
    for (const Eigen::Vector2f& t : textured.uv) {
        if (!t.allFinite()) __builtin_trap();
    }
    if (textured.atlas_bgr.empty()) textured.atlas_bgr = cv::Mat(2, 2, CV_8UC3, cv::Scalar::all(0));
    (void)recon::texturedObjFiles(textured, "fuzz");
    (void)recon::texturedPlyBytes(textured, "fuzz.png");
    return 0;
}
