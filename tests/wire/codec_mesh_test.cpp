// Draco mesh codec: round trips keep counts, faces, colours and positions within 0.05 mm; the decoder refuses
// truncated, corrupt and lying input with a Status.
#include <gtest/gtest.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include "test_data.hpp"
#include "wire/codecs.hpp"

namespace facescan::wire {
namespace {

// Vertex colours are lossless in the codec, so a test can give every vertex a unique colour (its index) and find
// each decoded vertex's original even though Draco reorders vertices.
OpenMesh::Vec3uc idColour(uint32_t id) {
    return {static_cast<uint8_t>(id), static_cast<uint8_t>(id >> 8), static_cast<uint8_t>(id >> 16)};
}
uint32_t colourId(const OpenMesh::Vec3uc& c) { return uint32_t{c[0]} | uint32_t{c[1]} << 8 | uint32_t{c[2]} << 16; }

void paintIds(recon::Mesh& mesh) {
    for (const auto vh : mesh.vertices()) mesh.set_color(vh, idColour(static_cast<uint32_t>(vh.idx())));
}

// A face-sized height field: side_m wide, a nose-like bump and a curved cheek surface.
recon::Mesh bumpGrid(int n, float side_m) {
    recon::Mesh mesh;
    std::vector<recon::Mesh::VertexHandle> vh(static_cast<size_t>(n) * n);
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const float x = side_m * (float(i) / float(n - 1) - 0.5f);
            const float y = side_m * (float(j) / float(n - 1) - 0.5f);
            const float z =
                0.7f - 0.04f * std::exp(-(x * x + y * y) / (0.02f * side_m * side_m)) + 0.3f * (x * x + y * y) / side_m;
            vh[size_t(j) * n + i] = mesh.add_vertex({x, y, z});
        }
    }
    for (int j = 0; j + 1 < n; ++j) {
        for (int i = 0; i + 1 < n; ++i) {
            const auto a = vh[size_t(j) * n + i], b = vh[size_t(j) * n + i + 1];
            const auto c = vh[size_t(j + 1) * n + i], d = vh[size_t(j + 1) * n + i + 1];
            mesh.add_face(a, b, d);
            mesh.add_face(a, d, c);
        }
    }
    mesh.update_normals();
    paintIds(mesh);
    return mesh;
}

using Tri = std::array<uint32_t, 3>;
// Triangles as a sorted list of id triples, each rotated so its smallest id comes first (orientation kept).
std::vector<Tri> faceIds(const recon::IndexedMesh& mesh, const std::vector<uint32_t>& id_of_vertex) {
    std::vector<Tri> faces;
    for (const recon::Triangle& t : mesh.triangles) {
        Tri ids = {id_of_vertex[t[0]], id_of_vertex[t[1]], id_of_vertex[t[2]]};
        std::rotate(ids.begin(), std::min_element(ids.begin(), ids.end()), ids.end());
        faces.push_back(ids);
    }
    std::sort(faces.begin(), faces.end());
    return faces;
}
std::vector<uint32_t> colourIds(const recon::IndexedMesh& mesh) {
    std::vector<uint32_t> ids;
    for (const recon::Rgb8& c : mesh.colours_rgb) ids.push_back(colourId({c[0], c[1], c[2]}));
    return ids;
}

struct RoundTrip {
    size_t bytes = 0;
    double max_error_m = 0.0;
    double max_normal_deg = 0.0;
    recon::MeshDefects defects;
};

// Encodes, decodes and compares: the decoded mesh is the encoder's cleaned mesh (same triangles, by the id
// colours), every vertex within the budget of its original, and it is clean.
RoundTrip expectRoundTrip(const recon::Mesh& openmesh, const MeshCodecParams& params = {}) {
    const recon::IndexedMesh mesh = recon::fromOpenMesh(openmesh);
    std::vector<uint8_t> bytes;
    recon::IndexedMesh encoded;
    const Status enc = encodeMeshDraco(mesh, params, bytes, &encoded);
    EXPECT_TRUE(enc.isOk()) << enc.toString();
    auto decoded = decodeIndexedMesh(bytes.data(), bytes.size());
    EXPECT_TRUE(decoded.isOk()) << decoded.status().toString();
    RoundTrip r;
    r.bytes = bytes.size();
    if (!decoded.isOk()) return r;
    EXPECT_EQ(decoded->triangleCount(), encoded.triangleCount());
    EXPECT_GE(decoded->vertexCount(), encoded.vertexCount());  // Draco may split a non-manifold vertex
    EXPECT_TRUE(decoded->hasNormals());
    const std::vector<uint32_t> ids = colourIds(*decoded);
    for (size_t i = 0; i < decoded->vertexCount(); ++i) {
        EXPECT_LT(ids[i], mesh.vertexCount());
        if (ids[i] >= mesh.vertexCount()) return r;
        r.max_error_m = std::max(r.max_error_m, double((decoded->positions_m[i] - mesh.positions_m[ids[i]]).norm()));
        const float cos_angle = std::clamp(decoded->normals[i].dot(mesh.normals[ids[i]]), -1.0f, 1.0f);
        r.max_normal_deg = std::max(r.max_normal_deg, std::acos(double(cos_angle)) * 180.0 / M_PI);
    }
    EXPECT_EQ(faceIds(*decoded, ids), faceIds(encoded, colourIds(encoded)));
    r.defects = recon::countDefects(*decoded);
    EXPECT_TRUE(r.defects.clean()) << r.defects.zero_area_triangles << " zero-area, " << r.defects.duplicate_triangles
                                   << " duplicate triangles, " << r.defects.unreferenced_vertices << " unreferenced";
    return r;
}

TEST(MeshDraco, PositionBitsHonourTheErrorBudget) {
    EXPECT_EQ(positionBitsFor(0.386f, 0.05e-3f), 13);  // the face volume: 47 um steps, <= 41 um error
    for (const float extent : {0.01f, 0.2f, 0.386f, 2.0f}) {
        const int bits = positionBitsFor(extent, 0.05e-3f);
        EXPECT_LE(std::sqrt(3.0) * extent / double((1u << bits) - 1) / 2.0, 0.05e-3);
        EXPECT_GT(std::sqrt(3.0) * extent / double((1u << (bits - 1)) - 1) / 2.0, 0.95 * 0.05e-3);  // fewest
    }
}

TEST(MeshDraco, RoundTripKeepsTopologyColoursAndPositionsWithinBudget) {
    // Spans the whole 0.386 m face volume, the largest extent a snapshot can have.
    const RoundTrip r = expectRoundTrip(bumpGrid(120, 0.386f));
    EXPECT_LT(r.max_error_m, 0.05e-3);
    EXPECT_LT(r.max_normal_deg, 5.0);  // no normals on the wire: recomputed from the decoded triangles
}

TEST(MeshDraco, TighterBudgetAndNormalsOnRequest) {
    MeshCodecParams params;
    params.max_position_error_m = 0.005e-3f;
    params.normal_bits = 10;  // old payloads carried normals; the decoder still takes them
    const recon::Mesh mesh = bumpGrid(40, 0.2f);
    const RoundTrip r = expectRoundTrip(mesh, params);
    EXPECT_LT(r.max_error_m, 0.005e-3);
    EXPECT_LT(r.max_normal_deg, 1.0);  // 10-bit octahedral normals: well under a degree
}

TEST(MeshDraco, ClosePointsAreWeldedOnTheGridNotLeftAsZeroAreaTriangles) {
    // A strip whose middle row is 10 um from the row below it: on the 0.05 mm grid the two rows meet. Draco alone
    // turned such triangles into zero-area ones (835 in a 114k-triangle final mesh).
    recon::Mesh mesh;
    std::vector<recon::Mesh::VertexHandle> v;
    for (int row = 0; row < 3; ++row) {
        const float y = row == 0 ? 0.0f : row == 1 ? 10e-6f : 0.02f;
        for (int i = 0; i < 50; ++i) v.push_back(mesh.add_vertex({0.002f * float(i), y, 0.5f}));
    }
    for (int row = 0; row < 2; ++row) {
        for (int i = 0; i + 1 < 50; ++i) {
            const auto a = v[size_t(row * 50 + i)], b = v[size_t(row * 50 + i + 1)];
            const auto c = v[size_t((row + 1) * 50 + i)], d = v[size_t((row + 1) * 50 + i + 1)];
            mesh.add_face(a, b, d);
            mesh.add_face(a, d, c);
        }
    }
    paintIds(mesh);
    const recon::IndexedMesh before = recon::fromOpenMesh(mesh);
    std::vector<uint8_t> bytes;
    recon::IndexedMesh encoded;
    ASSERT_TRUE(encodeMeshDraco(before, {}, bytes, &encoded).isOk());
    auto decoded = decodeIndexedMesh(bytes.data(), bytes.size());
    ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
    EXPECT_EQ(encoded.triangleCount(), 98u);  // the thin row's 98 triangles collapsed and were dropped
    EXPECT_EQ(decoded->triangleCount(), 98u);
    EXPECT_TRUE(recon::countDefects(*decoded).clean());
    EXPECT_TRUE(recon::countDefects(encoded).clean());
}

TEST(MeshDraco, RealHeadScanRoundTrip) {
    FACESCAN_REQUIRE_DATA(dir, "leeperrysmith");
    recon::Mesh mesh;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(mesh, (dir / "LeePerrySmith_converted.ply").string()));
    for (const auto vh : mesh.vertices()) mesh.set_point(vh, mesh.point(vh) * 0.049f);  // units -> metres
    mesh.update_normals();
    paintIds(mesh);
    const RoundTrip r = expectRoundTrip(mesh);
    EXPECT_LT(r.max_error_m, 0.05e-3);
    // Positions and 24-bit id colours (noise to Draco), no normals.
    EXPECT_LT(r.bytes, 20 * mesh.n_vertices());
}

TEST(MeshDraco, RejectsEveryTruncation) {
    const recon::Mesh mesh = bumpGrid(8, 0.1f);
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeMeshDraco(mesh, {}, bytes).isOk());
    recon::Mesh out;
    for (size_t len = 0; len < bytes.size(); ++len) {
        EXPECT_FALSE(decodeMeshDraco(bytes.data(), len, out).isOk()) << "prefix " << len << " of " << bytes.size();
    }
    EXPECT_TRUE(decodeMeshDraco(bytes.data(), bytes.size(), out).isOk());
}

TEST(MeshDraco, CorruptBytesNeverCrash) {
    const recon::Mesh mesh = bumpGrid(8, 0.1f);
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeMeshDraco(mesh, {}, bytes).isOk());
    recon::Mesh out;
    std::mt19937 rng(1);
    for (size_t i = 0; i < bytes.size(); ++i) {
        for (const uint8_t mask : {uint8_t{0x01}, uint8_t{0x10}, uint8_t{0xff}}) {
            std::vector<uint8_t> corrupt = bytes;
            corrupt[i] ^= mask;
            const Status st = decodeMeshDraco(corrupt.data(), corrupt.size(), out);
            if (i < 11) {  // magic, version, type, method, flags
                EXPECT_FALSE(st.isOk()) << "header byte " << i;
            }
            if (st.isOk()) {
                EXPECT_LE(out.n_vertices(), 4 * mesh.n_vertices());
            }
        }
    }
    std::vector<uint8_t> garbage(4096);
    for (auto& b : garbage) b = static_cast<uint8_t>(rng());
    EXPECT_FALSE(decodeMeshDraco(garbage.data(), garbage.size(), out).isOk());
    std::copy_n("DRACO\x02\x02\x01\x01\x00\x00", 11, garbage.begin());
    EXPECT_FALSE(decodeMeshDraco(garbage.data(), garbage.size(), out).isOk());
}

TEST(MeshDraco, RefusesLyingCountsBeforeDracoAllocates) {
    // Edgebreaker header claiming 2^32-1 vertices and faces in 20 bytes.
    const uint8_t lying[] = {'D',  'R',  'A',  'C',  'O',  2,    2,    1, 1,    0,    0,    0,    0xff, 0xff, 0xff,
                             0xff, 0x0f, 0xff, 0xff, 0xff, 0xff, 0x0f, 0, 0xff, 0xff, 0xff, 0xff, 0x0f, 0,    0};
    recon::Mesh out;
    EXPECT_EQ(decodeMeshDraco(lying, sizeof(lying), out).code(), StatusCode::kDataLoss);
    // An honest mesh over the caller's cap.
    const recon::Mesh mesh = bumpGrid(20, 0.1f);
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeMeshDraco(mesh, {}, bytes).isOk());
    const auto info = inspectDracoMesh(bytes.data(), bytes.size());
    ASSERT_TRUE(info.isOk());
    EXPECT_EQ(info->claimed_faces, mesh.n_faces());  // a clean grid loses nothing on Draco's grid
    EXPECT_GE(info->claimed_vertices, mesh.n_vertices());
    EXPECT_EQ(decodeMeshDraco(bytes.data(), bytes.size(), out, 100).code(), StatusCode::kOutOfRange);
}

TEST(MeshDraco, RejectsNonFloatPositionsFoundByTheFuzzer) {
    // fuzz_mesh_draco crash (UBSan): a Draco mesh whose POSITION attribute is DT_BOOL made Draco's ConvertValue
    // load arbitrary bytes as bool. Attributes of a type our encoder never writes are now refused.
    const uint8_t input[] = {
        0x44, 0x52, 0x41, 0x43, 0x4f, 0x02, 0x02, 0x01, 0x01, 0x00, 0x00, 0x00, 0x09, 0x08, 0x00, 0x08, 0x02, 0x00,
        0x03, 0x7f, 0xda, 0x07, 0xff, 0x01, 0x11, 0x01, 0xff, 0x00, 0x00, 0x02, 0x00, 0x0b, 0x03, 0x00, 0x00, 0x02,
        0x02, 0x02, 0x01, 0x00, 0x00, 0x00, 0x01, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9,
        0xa9, 0xa9, 0xa9, 0xa9, 0x03, 0x01, 0x01, 0x02, 0x01, 0x01, 0x01, 0x01, 0x00, 0x01, 0x09, 0x00, 0x00, 0x00,
        0x00, 0x02, 0x00, 0x09, 0x03, 0x00, 0x00, 0x02, 0x02, 0x02, 0x01, 0x00, 0x00, 0x00, 0x01, 0xa9, 0xa9, 0xa9,
        0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0xa9, 0x03, 0x01, 0x01, 0x02, 0x01, 0x01,
        0x01, 0x01, 0x00, 0x0a, 0x2b, 0xfb, 0x00, 0x00, 0x00, 0xff, 0xff, 0x56, 0xa7, 0xa9, 0xa9, 0xa9, 0xa9, 0x26,
        0x00, 0x08, 0x00, 0xaf, 0x00, 0x00, 0x0a, 0x2b, 0x00, 0x03, 0x1d, 0x07, 0x03, 0x34, 0x0e, 0x03, 0x55, 0x15,
        0x0b, 0x59, 0x15, 0x04, 0xe9, 0x1b, 0xdb, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84,
        0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84, 0x84};
    recon::Mesh out;
    EXPECT_FALSE(decodeMeshDraco(input, sizeof(input), out).isOk());
}

TEST(MeshDraco, RejectsAMeshWithoutTrianglesFoundByTheFuzzer) {
    // fuzz_mesh_draco (CI, 2026-11-23): a valid Draco mesh with no points and no faces decoded as OK into a mesh
    // without normals. Our encoder refuses a mesh without triangles, so the decoder now does too.
    const uint8_t input[] = {
        0x44, 0x52, 0x41, 0x43, 0x4f, 0x02, 0x02, 0x01, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00,
        0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x09, 0x08, 0x00, 0x08, 0x06, 0x00, 0x13, 0x7f, 0xda, 0x07, 0xff, 0x01,
        0x31, 0x01, 0xff, 0x00, 0x00, 0x02, 0x00, 0x09, 0x03, 0x00, 0x00, 0x02, 0x02, 0x01, 0x01, 0x00, 0x00, 0x00,
        0x22, 0x02, 0xff, 0xff, 0xff, 0xff, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x1f, 0x00, 0x00, 0x00,
        0x00, 0x02, 0x00, 0x09, 0x03, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00, 0x00, 0x07, 0x07, 0xe5, 0x36, 0x00, 0x02,
        0x02, 0x03, 0x01, 0x01, 0x02, 0x01, 0x3b, 0x01, 0x17, 0xff, 0x03, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xaa,
        0x02, 0x00, 0x00, 0x38, 0x07, 0x09, 0x08, 0x00, 0xff, 0x01, 0xff, 0x00, 0x00, 0x02, 0x00, 0x09, 0x03, 0x00,
        0x00, 0x12, 0x02, 0x01, 0x01, 0x00, 0x00, 0x00, 0x22, 0x02, 0x01, 0x00, 0x00, 0x00, 0x44, 0x52, 0x41, 0x43,
        0xb1, 0x00, 0x00, 0x05, 0x00, 0x00, 0x00, 0x0c, 0x00, 0x00, 0x00, 0x21, 0x00, 0x00, 0x00, 0x00, 0x00, 0x07,
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x0a, 0xa3, 0x3c, 0x09};
    recon::IndexedMesh out;
    const Status st = decodeMeshDraco(input, sizeof(input), out, 200'000);
    EXPECT_EQ(st.code(), StatusCode::kDataLoss) << st.message();
}

TEST(MeshDraco, EncoderRejectsBadInput) {
    std::vector<uint8_t> bytes;
    EXPECT_EQ(encodeMeshDraco(recon::Mesh(), {}, bytes).code(), StatusCode::kInvalidArgument);
    recon::Mesh mesh = bumpGrid(4, 0.1f);
    mesh.set_point(recon::Mesh::VertexHandle(0), {NAN, 0, 0});
    EXPECT_EQ(encodeMeshDraco(mesh, {}, bytes).code(), StatusCode::kInvalidArgument);
    MeshCodecParams params;
    params.speed = 11;
    EXPECT_EQ(encodeMeshDraco(bumpGrid(4, 0.1f), params, bytes).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace facescan::wire

namespace facescan::wire {
namespace {

TEST(MeshDraco, GridAlignedWithTheVoxelLinesKeepsTheBudgetAndSavesBytes) {
    // Vertices on a 1.5 mm lattice in x and y (like marching cubes' on voxel lines), z anywhere.
    const float voxel_m = 1.5e-3f;
    const int n = 80;
    const recon::Mesh mesh = bumpGrid(n, voxel_m * float(n - 1));
    MeshCodecParams aligned;
    aligned.lattice_step_m = voxel_m;
    aligned.lattice_origin_m = Eigen::Vector3f(-0.5f * voxel_m * float(n - 1), -0.5f * voxel_m * float(n - 1), 0.0f);
    const RoundTrip a = expectRoundTrip(mesh, aligned);
    const RoundTrip u = expectRoundTrip(mesh, {});
    EXPECT_LT(a.max_error_m, 0.05e-3);
    EXPECT_LT(a.bytes, u.bytes);
    MeshCodecParams bad;
    bad.lattice_step_m = -1.0f;
    std::vector<uint8_t> bytes;
    EXPECT_EQ(encodeMeshDraco(mesh, bad, bytes).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace facescan::wire

namespace facescan::wire {
namespace {

// The bump grid as a textured mesh cut down the middle: the middle column's vertices have one copy per side, the
// left half maps to the left of the atlas and the right half to the right, with a gap between (two charts).
// Every vertex (copies included) has its own id colour.
recon::TexturedMesh twoCharts(int n, float side_m) {
    const recon::IndexedMesh grid = recon::fromOpenMesh(bumpGrid(n, side_m));
    recon::TexturedMesh t;
    const int cut = n / 2;
    std::vector<uint32_t> copy(grid.vertexCount(), UINT32_MAX);  // the right side's copy of a middle vertex
    auto addVertex = [&](uint32_t v, bool right) {
        const int i = static_cast<int>(v) % n, j = static_cast<int>(v) / n;
        t.mesh.positions_m.push_back(grid.positions_m[v]);
        t.mesh.normals.push_back(grid.normals[v]);
        const float u = float(i) / float(n - 1);
        t.uv.emplace_back(right ? 0.1f + u * 0.9f : u * 0.9f, float(j) / float(n - 1));
        t.source_vertex.push_back(v);
        return static_cast<uint32_t>(t.mesh.positions_m.size() - 1);
    };
    for (uint32_t v = 0; v < grid.vertexCount(); ++v) addVertex(v, static_cast<int>(v) % n > cut);
    for (const recon::Triangle& tri : grid.triangles) {
        const bool right =
            static_cast<int>(tri[0]) % n + static_cast<int>(tri[1]) % n + static_cast<int>(tri[2]) % n > 3 * cut;
        recon::Triangle out = tri;
        for (uint32_t& v : out) {
            if (right && static_cast<int>(v) % n == cut) {
                if (copy[v] == UINT32_MAX) copy[v] = addVertex(v, true);
                v = copy[v];
            }
        }
        t.mesh.triangles.push_back(out);
    }
    for (uint32_t v = 0; v < t.mesh.vertexCount(); ++v) {
        const OpenMesh::Vec3uc c = idColour(v);
        t.mesh.colours_rgb.push_back({c[0], c[1], c[2]});
    }
    t.atlas_bgr = cv::Mat(64, 64, CV_8UC3, cv::Scalar(10, 20, 30));
    return t;
}

TEST(MeshDraco, TexturedMeshKeepsItsCoordinatesAndTheCopiesOnACut) {
    const recon::TexturedMesh t = twoCharts(41, 0.2f);
    ASSERT_TRUE(t.valid());
    ASSERT_GT(t.mesh.vertexCount(), 41u * 41u);  // the cut's copies
    MeshCodecParams params;
    params.normal_bits = 10;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeTexturedMeshDraco(t, params, bytes).isOk());
    recon::IndexedMesh decoded;
    std::vector<Eigen::Vector2f> uv;
    const Status s = decodeMeshDraco(bytes.data(), bytes.size(), decoded, uv);
    ASSERT_TRUE(s.isOk()) << s.toString();
    ASSERT_EQ(uv.size(), decoded.vertexCount());
    EXPECT_EQ(decoded.triangleCount(), t.mesh.triangleCount());
    EXPECT_EQ(decoded.vertexCount(), t.mesh.vertexCount());  // no copy welded away
    const std::vector<uint32_t> ids = colourIds(decoded);
    double max_error_m = 0.0, max_uv_error = 0.0;
    for (size_t i = 0; i < decoded.vertexCount(); ++i) {
        ASSERT_LT(ids[i], t.mesh.vertexCount());
        max_error_m = std::max(max_error_m, double((decoded.positions_m[i] - t.mesh.positions_m[ids[i]]).norm()));
        max_uv_error = std::max(max_uv_error, double((uv[i] - t.uv[ids[i]]).cwiseAbs().maxCoeff()));
    }
    EXPECT_LT(max_error_m, 0.05e-3);
    EXPECT_LT(max_uv_error, 1.0 / 65535.0);  // 16 bits over the coordinates' range (at most 1)
    EXPECT_EQ(faceIds(decoded, ids), faceIds(t.mesh, colourIds(t.mesh)));

    // A receiver that does not ask for texture coordinates (and an older one) decodes the same mesh without them.
    auto plain = decodeIndexedMesh(bytes.data(), bytes.size());
    ASSERT_TRUE(plain.isOk()) << plain.status().toString();
    EXPECT_EQ(plain->vertexCount(), decoded.vertexCount());
    // And a payload without coordinates leaves uv empty.
    std::vector<uint8_t> untextured;
    ASSERT_TRUE(encodeMeshDraco(t.mesh, {}, untextured).isOk());
    ASSERT_TRUE(decodeMeshDraco(untextured.data(), untextured.size(), decoded, uv).isOk());
    EXPECT_TRUE(uv.empty());
}

TEST(MeshDraco, TexturedEncoderRejectsBadInput) {
    std::vector<uint8_t> bytes;
    recon::TexturedMesh t = twoCharts(6, 0.1f);
    t.uv.pop_back();
    EXPECT_EQ(encodeTexturedMeshDraco(t, {}, bytes).code(), StatusCode::kInvalidArgument);
    t = twoCharts(6, 0.1f);
    t.uv[3].x() = NAN;
    EXPECT_EQ(encodeTexturedMeshDraco(t, {}, bytes).code(), StatusCode::kInvalidArgument);
    t = twoCharts(6, 0.1f);
    MeshCodecParams params;
    params.uv_bits = 0;
    EXPECT_EQ(encodeTexturedMeshDraco(t, params, bytes).code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(encodeTexturedMeshDraco(recon::TexturedMesh{}, {}, bytes).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace facescan::wire
