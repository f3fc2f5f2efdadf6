// Draco mesh codec: recon::Mesh (OpenMesh) <-> Draco edgebreaker bytes, with the count checks that Draco's decoder
// lacks for hostile input done here first.
#include "wire/mesh_codec.hpp"

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

namespace facescan::wire {
namespace {

// Draco bitstream 2.2 (what Draco 1.5 writes): "DRACO" major minor encoder_type method flags:u16.
constexpr size_t kDracoHeaderBytes = 11;
constexpr uint8_t kDracoMajor = 2;
constexpr uint8_t kDracoMinor = 2;
constexpr uint8_t kTriangularMesh = 1;

// Draco's varUI32: LEB128, at most 5 bytes.
bool readVarU32(const uint8_t* data, size_t size, size_t& pos, uint32_t& value) {
    uint64_t v = 0;
    for (int i = 0; i < 5; ++i) {
        if (pos >= size) return false;
        const uint8_t b = data[pos++];
        v |= uint64_t(b & 0x7fu) << (7 * i);
        if (!(b & 0x80u)) {
            if (v > std::numeric_limits<uint32_t>::max()) return false;
            value = static_cast<uint32_t>(v);
            return true;
        }
    }
    return false;
}

std::string num(size_t v) { return std::to_string(v); }

}  // namespace

Status MeshCodecParams::validate() const {
    if (!(max_position_error_m > 0.0f) || !std::isfinite(max_position_error_m)) {
        return invalidArgument("MeshCodecParams: max_position_error_m must be > 0");
    }
    if (position_bits < 0 || position_bits > 30)
        return invalidArgument("MeshCodecParams: position_bits outside [0, 30]");
    if (normal_bits < 0 || normal_bits > 30) return invalidArgument("MeshCodecParams: normal_bits outside [0, 30]");
    if (speed < 0 || speed > 10) return invalidArgument("MeshCodecParams: speed outside [0, 10]");
    return Status::ok();
}

int positionBitsFor(float extent_m, float max_error_m) {
    if (!(extent_m > 0.0f) || !(max_error_m > 0.0f)) return 8;
    // Draco's quantiser: step = extent / (2^bits - 1), rounding to nearest => per-axis error <= step / 2 and
    // Euclidean error <= sqrt(3) * step / 2.
    const double budget_m = 0.95 * double(max_error_m);
    for (int bits = 1; bits <= 30; ++bits) {
        const double worst_m = std::sqrt(3.0) * double(extent_m) / double((1u << bits) - 1u) / 2.0;
        if (worst_m <= budget_m) return bits;
    }
    return 30;
}

Status encodeMeshDraco(const recon::Mesh& mesh, const MeshCodecParams& params, std::vector<uint8_t>& out) {
    RETURN_IF_ERROR(params.validate());
    if (mesh.n_faces() == 0) return invalidArgument("Draco encoder: mesh has no faces");
    // OpenMesh may hold deleted elements until garbage collection: number the live vertices densely.
    std::vector<uint32_t> index_of(mesh.n_vertices(), std::numeric_limits<uint32_t>::max());
    uint32_t nv = 0;
    OpenMesh::Vec3f lo(std::numeric_limits<float>::max());
    OpenMesh::Vec3f hi(std::numeric_limits<float>::lowest());
    for (const auto vh : mesh.vertices()) {
        const auto& p = mesh.point(vh);
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
            return invalidArgument("Draco encoder: vertex " + num(vh.idx()) + " is not finite");
        }
        lo.minimize(p);
        hi.maximize(p);
        index_of[vh.idx()] = nv++;
    }
    size_t nf = 0;
    for (const auto fh : mesh.faces()) nf += (mesh.valence(fh) == 3) ? 1 : 0;
    if (nf == 0) return invalidArgument("Draco encoder: mesh has no triangles");

    draco::Mesh dm;
    dm.set_num_points(nv);
    dm.SetNumFaces(nf);
    size_t fi = 0;
    for (const auto fh : mesh.faces()) {
        if (mesh.valence(fh) != 3) continue;
        draco::Mesh::Face face;
        int k = 0;
        for (const auto vh : mesh.fv_range(fh)) face[k++] = draco::PointIndex(index_of[vh.idx()]);
        dm.SetFace(draco::FaceIndex(static_cast<uint32_t>(fi++)), face);
    }

    auto addAttribute = [&](draco::GeometryAttribute::Type type, draco::DataType dt, bool normalized, int bytes) {
        draco::GeometryAttribute ga;
        ga.Init(type, nullptr, 3, dt, normalized, 3 * bytes, 0);
        return dm.attribute(dm.AddAttribute(ga, true, nv));
    };
    draco::PointAttribute* pos = addAttribute(draco::GeometryAttribute::POSITION, draco::DT_FLOAT32, false, 4);
    draco::PointAttribute* nrm = params.normal_bits > 0 && mesh.has_vertex_normals()
                                     ? addAttribute(draco::GeometryAttribute::NORMAL, draco::DT_FLOAT32, false, 4)
                                     : nullptr;
    draco::PointAttribute* col = params.colours && mesh.has_vertex_colors()
                                     ? addAttribute(draco::GeometryAttribute::COLOR, draco::DT_UINT8, true, 1)
                                     : nullptr;
    for (const auto vh : mesh.vertices()) {
        const draco::AttributeValueIndex i(index_of[vh.idx()]);
        pos->SetAttributeValue(i, mesh.point(vh).data());
        if (nrm) {
            OpenMesh::Vec3f n = mesh.normal(vh);
            if (!std::isfinite(n.sqrnorm())) n = OpenMesh::Vec3f(0, 0, 0);
            nrm->SetAttributeValue(i, n.data());
        }
        if (col) col->SetAttributeValue(i, mesh.color(vh).data());
    }

    const OpenMesh::Vec3f extent = hi - lo;
    const float extent_m = std::max({extent[0], extent[1], extent[2]});
    const int position_bits =
        params.position_bits > 0 ? params.position_bits : positionBitsFor(extent_m, params.max_position_error_m);

    draco::Encoder encoder;
    encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
    encoder.SetSpeedOptions(params.speed, params.speed);
    encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, position_bits);
    if (nrm) encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, params.normal_bits);
    draco::EncoderBuffer buffer;
    const draco::Status st = encoder.EncodeMeshToBuffer(dm, &buffer);
    if (!st.ok()) return internalError("Draco encoding failed: " + st.error_msg_string());
    out.assign(reinterpret_cast<const uint8_t*>(buffer.data()),
               reinterpret_cast<const uint8_t*>(buffer.data()) + buffer.size());
    return Status::ok();
}

StatusOr<DracoMeshInfo> inspectDracoMesh(const uint8_t* data, size_t size) {
    if (data == nullptr || size < kDracoHeaderBytes) {
        return dataLoss("Draco payload truncated (" + num(size) + " bytes)");
    }
    if (std::memcmp(data, "DRACO", 5) != 0) return dataLoss("Draco payload has no DRACO magic");
    if (data[5] != kDracoMajor || data[6] != kDracoMinor) {
        return dataLoss("Draco bitstream " + num(data[5]) + "." + num(data[6]) + " unsupported (2.2)");
    }
    if (data[7] != kTriangularMesh) return dataLoss("Draco payload is not a triangle mesh");
    const uint16_t flags = static_cast<uint16_t>(data[9] | data[10] << 8);
    if (flags != 0) return dataLoss("Draco payload has flags/metadata set (facescan never writes them)");
    DracoMeshInfo info;
    info.method = data[8];
    size_t pos = kDracoHeaderBytes;
    if (info.method == draco::MESH_SEQUENTIAL_ENCODING) {
        if (!readVarU32(data, size, pos, info.claimed_faces) || !readVarU32(data, size, pos, info.claimed_vertices)) {
            return dataLoss("Draco sequential connectivity header truncated");
        }
        return info;
    }
    if (info.method != draco::MESH_EDGEBREAKER_ENCODING) {
        return dataLoss("Draco encoding method " + num(info.method) + " unknown");
    }
    // Edgebreaker (Draco spec, ParseEdgebreakerConnectivityData): traversal type, encoded vertices, faces,
    // attribute data count, symbols, split symbols.
    uint32_t encoded_vertices = 0;
    uint32_t symbols = 0;
    uint32_t split_symbols = 0;
    if (pos + 1 > size) return dataLoss("Draco edgebreaker header truncated");
    ++pos;  // traversal type: Draco checks it
    if (!readVarU32(data, size, pos, encoded_vertices) || !readVarU32(data, size, pos, info.claimed_faces) ||
        pos + 1 > size) {
        return dataLoss("Draco edgebreaker header truncated");
    }
    ++pos;  // number of attribute data: Draco checks it
    if (!readVarU32(data, size, pos, symbols) || !readVarU32(data, size, pos, split_symbols)) {
        return dataLoss("Draco edgebreaker header truncated");
    }
    // Each symbol takes at least one bit of the payload and yields one face; Draco allows a third more faces
    // (interior faces closing holes). A claim beyond that cannot be honest.
    if (symbols > 8 * uint64_t(size)) {
        return dataLoss("Draco edgebreaker claims " + num(symbols) + " symbols in " + num(size) + " bytes");
    }
    if (info.claimed_faces < symbols || info.claimed_faces > uint64_t(symbols) + symbols / 3 ||
        split_symbols > symbols) {
        return dataLoss("Draco edgebreaker counts are inconsistent");
    }
    info.claimed_vertices = static_cast<uint32_t>(
        std::min<uint64_t>(uint64_t(encoded_vertices) + split_symbols, std::numeric_limits<uint32_t>::max()));
    if (info.claimed_vertices > 3 * uint64_t(info.claimed_faces) + 3) {
        return dataLoss("Draco edgebreaker claims more vertices than its faces can use");
    }
    return info;
}

Status decodeMeshDraco(const uint8_t* data, size_t size, recon::Mesh& mesh, size_t max_vertices) {
    ASSIGN_OR_RETURN(const DracoMeshInfo info, inspectDracoMesh(data, size));
    const size_t max_faces = 4 * max_vertices;
    if (info.claimed_vertices > max_vertices || info.claimed_faces > max_faces) {
        return outOfRange("Draco mesh claims " + num(info.claimed_vertices) + " vertices / " + num(info.claimed_faces) +
                          " faces, cap " + num(max_vertices) + " / " + num(max_faces));
    }
    draco::DecoderBuffer buffer;
    buffer.Init(reinterpret_cast<const char*>(data), size);
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
    if (!decoded.ok()) return dataLoss("Draco mesh corrupt: " + decoded.status().error_msg_string());
    const std::unique_ptr<draco::Mesh> dm = std::move(decoded).value();
    if (!dm) return dataLoss("Draco decoder returned no mesh");
    const size_t nv = dm->num_points();
    const size_t nf = dm->num_faces();
    if (nv > max_vertices || nf > max_faces) return outOfRange("decoded Draco mesh exceeds the caps");

    const draco::PointAttribute* pos = dm->GetNamedAttribute(draco::GeometryAttribute::POSITION);
    const draco::PointAttribute* nrm = dm->GetNamedAttribute(draco::GeometryAttribute::NORMAL);
    const draco::PointAttribute* col = dm->GetNamedAttribute(draco::GeometryAttribute::COLOR);
    // Draco does not bound-check a point's value index on access: check every attribute's mapping here. The data
    // type must be what our encoder writes (float positions/normals, uint8 colours): Draco's ConvertValue reads a
    // hostile DT_BOOL attribute's bytes as bool, which is undefined behaviour (found by fuzz_mesh_draco).
    auto usable = [nv](const draco::PointAttribute* a, draco::DataType type) {
        if (a == nullptr || a->num_components() != 3 || a->buffer() == nullptr || a->data_type() != type) return false;
        for (size_t i = 0; i < nv; ++i) {
            if (a->mapped_index(draco::PointIndex(static_cast<uint32_t>(i))).value() >= a->size()) return false;
        }
        return true;
    };
    if (!usable(pos, draco::DT_FLOAT32)) return dataLoss("Draco mesh has no usable 3D position attribute");
    if (nrm && !usable(nrm, draco::DT_FLOAT32)) nrm = nullptr;
    if (col && !usable(col, draco::DT_UINT8)) col = nullptr;

    mesh.clear();
    mesh.reserve(nv, 3 * nf / 2 + 3, nf);
    std::vector<recon::Mesh::VertexHandle> handles(nv);
    for (size_t i = 0; i < nv; ++i) {
        const draco::PointIndex pi(static_cast<uint32_t>(i));
        OpenMesh::Vec3f p;
        if (!pos->ConvertValue<float>(pos->mapped_index(pi), 3, p.data()) || !std::isfinite(p.sqrnorm())) {
            return dataLoss("Draco vertex " + num(i) + " has no finite position");
        }
        handles[i] = mesh.add_vertex(p);
        if (nrm) {
            OpenMesh::Vec3f n;
            if (nrm->ConvertValue<float>(nrm->mapped_index(pi), 3, n.data()) && std::isfinite(n.sqrnorm())) {
                mesh.set_normal(handles[i], n);
            }
        }
        if (col) {
            OpenMesh::Vec3uc c;
            if (col->ConvertValue<uint8_t>(col->mapped_index(pi), 3, c.data())) mesh.set_color(handles[i], c);
        }
    }
    size_t rejected = 0;
    for (size_t f = 0; f < nf; ++f) {
        const auto& face = dm->face(draco::FaceIndex(static_cast<uint32_t>(f)));
        const uint32_t a = face[0].value();
        const uint32_t b = face[1].value();
        const uint32_t c = face[2].value();
        if (a >= nv || b >= nv || c >= nv) return dataLoss("Draco face " + num(f) + " indexes past the vertices");
        if (a == b || b == c || a == c || !mesh.add_face(handles[a], handles[b], handles[c]).is_valid()) ++rejected;
    }
    if (rejected > 0) {
        return dataLoss("Draco mesh has " + num(rejected) + " degenerate or non-manifold faces of " + num(nf));
    }
    if (!nrm) {
        mesh.update_face_normals();
        mesh.update_vertex_normals();
    }
    return Status::ok();
}

StatusOr<recon::Mesh> decodeMeshDraco(const uint8_t* data, size_t size, size_t max_vertices) {
    recon::Mesh mesh;
    RETURN_IF_ERROR(decodeMeshDraco(data, size, mesh, max_vertices));
    return mesh;
}

}  // namespace facescan::wire
