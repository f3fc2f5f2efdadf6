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
    if (uv_bits < 1 || uv_bits > 30) return invalidArgument("MeshCodecParams: uv_bits outside [1, 30]");
    if (!(lattice_step_m >= 0.0f) || !std::isfinite(lattice_step_m) || !lattice_origin_m.allFinite()) {
        return invalidArgument("MeshCodecParams: lattice_step_m must be >= 0 and the lattice finite");
    }
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

namespace {

// Draco's quantiser (AttributeQuantizationTransform + Quantizer, float arithmetic): per axis the minimum, one
// range for all axes (the largest extent), max = 2^bits - 1 steps, q = floor((v - min) * max / range + 0.5),
// decoded v' = q * (range / max) + min. Reproduced here so that the encoder sees the positions the receiver will
// get, and cleans the mesh on them (without it, close vertices collapsed and left zero-area triangles).
struct DracoGrid {
    float min[3] = {0, 0, 0};
    float inverse_delta = 1.0f;
    float delta = 1.0f;
    float snap(float v, int axis) const {
        const int32_t q = static_cast<int32_t>(std::floor((v - min[axis]) * inverse_delta + 0.5f));
        return static_cast<float>(q) * delta + min[axis];
    }
};

// What both encoders check of their input (triangles, every index in range, finite positions and texture
// coordinates) and the positions' box: per-axis minimum and maximum, and the largest extent (Draco's range).
Status checkedBounds(const recon::IndexedMesh& mesh, const std::vector<Eigen::Vector2f>* uv, float lo[3], float hi[3],
                     float& range) {
    if (mesh.triangles.empty()) return invalidArgument("Draco encoder: mesh has no triangles");
    const size_t nv = mesh.vertexCount();
    for (const recon::Triangle& t : mesh.triangles) {
        if (t[0] >= nv || t[1] >= nv || t[2] >= nv) {
            return invalidArgument("Draco encoder: a triangle indexes past the " + num(nv) + " vertices");
        }
    }
    for (int a = 0; a < 3; ++a) lo[a] = std::numeric_limits<float>::max(), hi[a] = std::numeric_limits<float>::lowest();
    for (size_t i = 0; i < nv; ++i) {
        const Eigen::Vector3f& p = mesh.positions_m[i];
        if (!p.allFinite() || (uv && !(*uv)[i].allFinite())) {
            return invalidArgument("Draco encoder: vertex " + num(i) + " is not finite");
        }
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
    }
    range = 0.0f;
    for (int a = 0; a < 3; ++a) range = std::max(range, hi[a] - lo[a]);
    if (range == 0.0f) range = 1.0f;  // Draco's own choice for a single point
    return Status::ok();
}

// The per-vertex attributes a Draco mesh is built from; those left null are not sent. Normals must be finite.
struct DracoAttributes {
    const std::vector<Eigen::Vector3f>* positions_m = nullptr;
    const std::vector<Eigen::Vector3f>* normals = nullptr;
    const std::vector<recon::Rgb8>* colours_rgb = nullptr;
    const std::vector<Eigen::Vector2f>* uv = nullptr;
};

// The mesh with Edgebreaker into `out`: positions at position_bits, on the explicit grid (grid_min, grid_range)
// when grid_min is given, else on the one Draco takes from the vertices.
Status encodeDracoBytes(const std::vector<recon::Triangle>& triangles, const DracoAttributes& attributes,
                        const MeshCodecParams& params, int position_bits, const float* grid_min, float grid_range,
                        std::vector<uint8_t>& out) {
    const auto nv = static_cast<uint32_t>(attributes.positions_m->size());
    draco::Mesh dm;
    dm.set_num_points(nv);
    dm.SetNumFaces(triangles.size());
    for (size_t f = 0; f < triangles.size(); ++f) {
        const recon::Triangle& t = triangles[f];
        dm.SetFace(draco::FaceIndex(static_cast<uint32_t>(f)),
                   {draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
    }
    auto addAttribute = [&](draco::GeometryAttribute::Type type, int components, draco::DataType dt, bool normalized,
                            int bytes, const void* values) {
        draco::GeometryAttribute ga;
        ga.Init(type, nullptr, static_cast<uint8_t>(components), dt, normalized, components * bytes, 0);
        draco::PointAttribute* att = dm.attribute(dm.AddAttribute(ga, true, nv));
        att->buffer()->Write(0, values, size_t(nv) * size_t(components) * size_t(bytes));
    };
    static_assert(sizeof(Eigen::Vector3f) == 12 && sizeof(Eigen::Vector2f) == 8 && sizeof(recon::Rgb8) == 3);
    addAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, 4, attributes.positions_m->data());
    if (attributes.normals) {
        addAttribute(draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32, false, 4, attributes.normals->data());
    }
    if (attributes.colours_rgb) {
        addAttribute(draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8, true, 1, attributes.colours_rgb->data());
    }
    if (attributes.uv) {
        addAttribute(draco::GeometryAttribute::TEX_COORD, 2, draco::DT_FLOAT32, false, 4, attributes.uv->data());
    }

    draco::Encoder encoder;
    encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
    encoder.SetSpeedOptions(params.speed, params.speed);
    if (grid_min) {
        encoder.SetAttributeExplicitQuantization(draco::GeometryAttribute::POSITION, position_bits, 3, grid_min,
                                                 grid_range);
    } else {
        encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, position_bits);
    }
    if (attributes.normals) encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, params.normal_bits);
    if (attributes.uv) encoder.SetAttributeQuantization(draco::GeometryAttribute::TEX_COORD, params.uv_bits);
    draco::EncoderBuffer buffer;
    const draco::Status st = encoder.EncodeMeshToBuffer(dm, &buffer);
    if (!st.ok()) return internalError("Draco encoding failed: " + st.error_msg_string());
    out.assign(reinterpret_cast<const uint8_t*>(buffer.data()),
               reinterpret_cast<const uint8_t*>(buffer.data()) + buffer.size());
    return Status::ok();
}

}  // namespace

Status encodeMeshDraco(const recon::IndexedMesh& mesh, const MeshCodecParams& params, std::vector<uint8_t>& out,
                       recon::IndexedMesh* encoded) {
    RETURN_IF_ERROR(params.validate());
    float lo[3], hi[3], range = 0.0f;
    RETURN_IF_ERROR(checkedBounds(mesh, nullptr, lo, hi, range));
    const size_t nv_in = mesh.vertexCount();
    int position_bits =
        params.position_bits > 0 ? params.position_bits : positionBitsFor(range, params.max_position_error_m);
    DracoGrid grid;
    for (int a = 0; a < 3; ++a) grid.min[a] = lo[a];
    auto setGrid = [&](int bits, float grid_range) {
        position_bits = bits;
        range = grid_range;
        const float max_quantized = static_cast<float>((1u << bits) - 1u);
        grid.inverse_delta = max_quantized / range;
        grid.delta = range / max_quantized;
    };
    setGrid(position_bits, range);
    // The mesh as the receiver will see it: positions on Draco's grid (then welded and cleaned there, below).
    recon::IndexedMesh work;
    work.positions_m.resize(nv_in);
    auto snapAll = [&] {
        double worst_m = 0.0;
        for (size_t i = 0; i < nv_in; ++i) {
            for (int a = 0; a < 3; ++a) work.positions_m[i][a] = grid.snap(mesh.positions_m[i][a], a);
            worst_m = std::max(worst_m, double((work.positions_m[i] - mesh.positions_m[i]).norm()));
        }
        return worst_m;
    };
    bool snapped = false;
    if (params.lattice_step_m > 0.0f && params.position_bits == 0) {
        // Marching-cubes vertices lie on voxel lines: two of their three coordinates are multiples of the voxel.
        // A quantisation step that divides the voxel, from an origin on a voxel line, keeps those two exact, so
        // only the third carries error: the step may be twice the error bound instead of 2/sqrt(3) of it. And
        // Draco's parallelogram residuals on the exact axes are multiples of k, which its entropy coder stores in
        // a few bits (facescan-bench mesh: the final mesh's bytes against the unaligned grid). Every vertex is
        // checked; a mesh whose vertices are not on the lines gets the corner-safe step.
        const double lattice = params.lattice_step_m;
        const double budget_m = 0.95 * double(params.max_position_error_m);
        double origin[3];
        double extent = 0.0;
        for (int a = 0; a < 3; ++a) {
            const double o = params.lattice_origin_m[a];
            origin[a] = o + std::floor((double(lo[a]) - o) / lattice) * lattice;
            extent = std::max(extent, double(hi[a]) - origin[a]);
        }
        const float saved_min[3] = {grid.min[0], grid.min[1], grid.min[2]};
        const int saved_bits = position_bits;
        const float saved_range = range;
        for (const double max_step : {2.0 * budget_m, 2.0 * budget_m / std::sqrt(3.0)}) {
            const double step = lattice / std::ceil(lattice / max_step);
            int bits = 1;
            while (bits < 30 && double((1u << bits) - 1u) * step < extent + step) ++bits;
            if (bits >= 30) break;
            for (int a = 0; a < 3; ++a) grid.min[a] = static_cast<float>(origin[a]);
            setGrid(bits, static_cast<float>(step * double((1u << bits) - 1u)));
            if (snapAll() <= double(params.max_position_error_m)) {
                snapped = true;
                break;
            }
        }
        if (!snapped) {
            for (int a = 0; a < 3; ++a) grid.min[a] = saved_min[a];
            setGrid(saved_bits, saved_range);
        }
    }
    if (!snapped) (void)snapAll();
    // Draco quantises the snapped positions to the same grid again (set explicitly below), so what the receiver
    // decodes is the cleaned mesh below, vertex order aside.
    if (params.colours && mesh.hasColours()) work.colours_rgb = mesh.colours_rgb;
    const bool send_normals = params.normal_bits > 0 && mesh.hasNormals();
    if (send_normals) work.normals = mesh.normals;
    work.triangles = mesh.triangles;
    recon::removeDefects(work);
    if (work.triangles.empty()) return invalidArgument("Draco encoder: no triangle survives quantisation");
    if (send_normals) {
        for (Eigen::Vector3f& n : work.normals) {
            if (!n.allFinite()) n.setZero();
        }
    }
    DracoAttributes attributes;
    attributes.positions_m = &work.positions_m;
    attributes.normals = send_normals ? &work.normals : nullptr;
    attributes.colours_rgb = work.hasColours() ? &work.colours_rgb : nullptr;
    // The grid is given explicitly: Draco would otherwise take origin and range from the cleaned vertices, and a
    // dropped extreme vertex would move its grid off the one the mesh was cleaned on.
    RETURN_IF_ERROR(encodeDracoBytes(work.triangles, attributes, params, position_bits, grid.min, range, out));
    if (encoded) *encoded = std::move(work);
    return Status::ok();
}

Status encodeMeshDraco(const recon::Mesh& mesh, const MeshCodecParams& params, std::vector<uint8_t>& out) {
    return encodeMeshDraco(recon::fromOpenMesh(mesh), params, out);
}

Status encodeTexturedMeshDraco(const recon::TexturedMesh& textured, const MeshCodecParams& params,
                               std::vector<uint8_t>& out) {
    RETURN_IF_ERROR(params.validate());
    const recon::IndexedMesh& mesh = textured.mesh;
    const size_t nv = mesh.vertexCount();
    if (textured.uv.size() != nv) {
        return invalidArgument("Draco encoder: " + num(textured.uv.size()) + " texture coordinates for " + num(nv) +
                               " vertices");
    }
    if (nv > std::numeric_limits<uint32_t>::max()) return invalidArgument("Draco encoder: too many vertices");
    float lo[3], hi[3], range = 0.0f;
    RETURN_IF_ERROR(checkedBounds(mesh, &textured.uv, lo, hi, range));
    const int position_bits =
        params.position_bits > 0 ? params.position_bits : positionBitsFor(range, params.max_position_error_m);
    DracoAttributes attributes;
    attributes.positions_m = &mesh.positions_m;
    std::vector<Eigen::Vector3f> normals;
    if (params.normal_bits > 0 && mesh.hasNormals()) {
        normals = mesh.normals;
        for (Eigen::Vector3f& n : normals) {
            if (!n.allFinite()) n.setZero();
        }
        attributes.normals = &normals;
    }
    attributes.colours_rgb = params.colours && mesh.hasColours() ? &mesh.colours_rgb : nullptr;
    attributes.uv = &textured.uv;
    return encodeDracoBytes(mesh.triangles, attributes, params, position_bits, nullptr, 0.0f, out);
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

namespace {

Status decodeDraco(const uint8_t* data, size_t size, recon::IndexedMesh& mesh, std::vector<Eigen::Vector2f>* uv,
                   size_t max_vertices) {
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
    // facescan's encoder refuses a mesh without triangles, so an empty one is not ours (found by fuzz_mesh_draco:
    // it decoded to a mesh with no normals, which every receiver assumes).
    if (nf == 0 || nv == 0) return dataLoss("Draco mesh has no triangles");

    const draco::PointAttribute* pos = dm->GetNamedAttribute(draco::GeometryAttribute::POSITION);
    const draco::PointAttribute* nrm = dm->GetNamedAttribute(draco::GeometryAttribute::NORMAL);
    const draco::PointAttribute* col = dm->GetNamedAttribute(draco::GeometryAttribute::COLOR);
    // Draco does not bound-check a point's value index on access: check every attribute's mapping here. The data
    // type must be what our encoder writes (float positions/normals, uint8 colours): Draco's ConvertValue reads a
    // hostile DT_BOOL attribute's bytes as bool, which is undefined behaviour (found by fuzz_mesh_draco).
    auto usable = [nv](const draco::PointAttribute* a, draco::DataType type, int components = 3) {
        if (a == nullptr || a->num_components() != components || a->buffer() == nullptr || a->data_type() != type) {
            return false;
        }
        for (size_t i = 0; i < nv; ++i) {
            if (a->mapped_index(draco::PointIndex(static_cast<uint32_t>(i))).value() >= a->size()) return false;
        }
        return true;
    };
    if (!usable(pos, draco::DT_FLOAT32)) return dataLoss("Draco mesh has no usable 3D position attribute");
    if (nrm && !usable(nrm, draco::DT_FLOAT32)) nrm = nullptr;
    if (col && !usable(col, draco::DT_UINT8)) col = nullptr;
    const draco::PointAttribute* tex = uv ? dm->GetNamedAttribute(draco::GeometryAttribute::TEX_COORD) : nullptr;
    if (tex && !usable(tex, draco::DT_FLOAT32, 2)) tex = nullptr;
    if (uv) uv->clear();

    mesh.clear();
    mesh.positions_m.resize(nv);
    if (nrm) mesh.normals.resize(nv);
    if (col) mesh.colours_rgb.resize(nv);
    for (size_t i = 0; i < nv; ++i) {
        const draco::PointIndex pi(static_cast<uint32_t>(i));
        Eigen::Vector3f& p = mesh.positions_m[i];
        pos->GetValue(pos->mapped_index(pi), p.data());
        if (!p.allFinite()) return dataLoss("Draco vertex " + num(i) + " has no finite position");
        if (nrm) {
            Eigen::Vector3f& n = mesh.normals[i];
            nrm->GetValue(nrm->mapped_index(pi), n.data());
            if (!n.allFinite()) n.setZero();
        }
        if (col) col->GetValue(col->mapped_index(pi), mesh.colours_rgb[i].data());
    }
    if (tex) {
        uv->resize(nv);
        for (size_t i = 0; i < nv; ++i) {
            Eigen::Vector2f& t = (*uv)[i];
            tex->GetValue(tex->mapped_index(draco::PointIndex(static_cast<uint32_t>(i))), t.data());
            if (!t.allFinite()) return dataLoss("Draco texture coordinate " + num(i) + " is not finite");
        }
    }
    mesh.triangles.resize(nf);
    size_t degenerate = 0;
    for (size_t f = 0; f < nf; ++f) {
        const auto& face = dm->face(draco::FaceIndex(static_cast<uint32_t>(f)));
        const recon::Triangle t = {face[0].value(), face[1].value(), face[2].value()};
        if (t[0] >= nv || t[1] >= nv || t[2] >= nv)
            return dataLoss("Draco face " + num(f) + " indexes past the vertices");
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) ++degenerate;
        mesh.triangles[f] = t;
    }
    // facescan's encoder never writes a face with a repeated vertex (it cleans the mesh on Draco's grid first).
    if (degenerate > 0) return dataLoss("Draco mesh has " + num(degenerate) + " degenerate faces of " + num(nf));
    if (!nrm) recon::computeVertexNormals(mesh);
    return Status::ok();
}

}  // namespace

Status decodeMeshDraco(const uint8_t* data, size_t size, recon::IndexedMesh& mesh, size_t max_vertices) {
    return decodeDraco(data, size, mesh, nullptr, max_vertices);
}

Status decodeMeshDraco(const uint8_t* data, size_t size, recon::IndexedMesh& mesh, std::vector<Eigen::Vector2f>& uv,
                       size_t max_vertices) {
    return decodeDraco(data, size, mesh, &uv, max_vertices);
}

StatusOr<recon::IndexedMesh> decodeIndexedMesh(const uint8_t* data, size_t size, size_t max_vertices) {
    recon::IndexedMesh mesh;
    RETURN_IF_ERROR(decodeMeshDraco(data, size, mesh, max_vertices));
    return mesh;
}

Status decodeMeshDraco(const uint8_t* data, size_t size, recon::Mesh& mesh, size_t max_vertices) {
    recon::IndexedMesh arrays;
    RETURN_IF_ERROR(decodeMeshDraco(data, size, arrays, max_vertices));
    mesh = recon::toOpenMesh(arrays);
    return Status::ok();
}

StatusOr<recon::Mesh> decodeMeshDraco(const uint8_t* data, size_t size, size_t max_vertices) {
    recon::Mesh mesh;
    RETURN_IF_ERROR(decodeMeshDraco(data, size, mesh, max_vertices));
    return mesh;
}

}  // namespace facescan::wire
