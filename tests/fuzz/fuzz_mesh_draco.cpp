// libFuzzer target: decodeMeshDraco (our count checks, then Draco's decoder, then the OpenMesh build).
#include <OpenMesh/Core/System/omstream.hh>

#include "wire/mesh_codec.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan::wire;
    static const bool quiet = [] {
        omerr().disable();  // OpenMesh logs every rejected (non-manifold) face; the Status already says so
        return true;
    }();
    (void)quiet;
    constexpr size_t kMaxVertices = 200'000;
    static facescan::recon::Mesh mesh;
    const facescan::Status st = decodeMeshDraco(data, size, mesh, kMaxVertices);
    if (st.isOk() && mesh.n_vertices() > kMaxVertices) __builtin_trap();
    return 0;
}
