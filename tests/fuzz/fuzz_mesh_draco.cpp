// libFuzzer target: decodeMeshDraco into the flat arrays a client writes files from (our count checks, then
// Draco's decoder, then the arrays and their recomputed normals), then what the client does with a decoded mesh:
// the PLY/STL bytes (recon/mesh_writer.hpp) and the defect count.
#include "recon/mesh_writer.hpp"
#include "wire/mesh_codec.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan;
    constexpr size_t kMaxVertices = 200'000;
    static recon::IndexedMesh mesh;
    const Status st = wire::decodeMeshDraco(data, size, mesh, kMaxVertices);
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
    return 0;
}
