// Mesh files of the client: every format read back through OpenMesh (and .drc through the Draco codec) with the
// same vertex and face counts, colours where the format has them, atomic writes, and unwritable paths.
#include "client/mesh_file.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <tiny_gltf.h>
#include <unistd.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "client/gltf_mesh.hpp"
#include "client/textured_mesh_file.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::client {
namespace {
namespace fs = std::filesystem;

// A face-sized curved patch (a 24 x 20 grid on a sphere of 9 cm radius, 0.7 m from the camera), with a colour
// gradient: every vertex distinct, every vertex used, so all formats must keep the counts exactly.
recon::Mesh testMesh() {
    recon::Mesh mesh;
    constexpr int kCols = 24, kRows = 20;
    std::vector<recon::Mesh::VertexHandle> v;
    for (int r = 0; r < kRows; ++r) {
        for (int c = 0; c < kCols; ++c) {
            const float yaw = (static_cast<float>(c) / (kCols - 1) - 0.5f) * 1.6f;
            const float pitch = (static_cast<float>(r) / (kRows - 1) - 0.5f) * 1.4f;
            const float radius_m = 0.09f;
            const auto vh = mesh.add_vertex(recon::Mesh::Point(radius_m * std::sin(yaw) * std::cos(pitch),
                                                               radius_m * std::sin(pitch),
                                                               0.7f - radius_m * std::cos(yaw) * std::cos(pitch)));
            mesh.set_color(
                vh, recon::Mesh::Color(static_cast<unsigned char>(10 * c), static_cast<unsigned char>(12 * r), 200));
            v.push_back(vh);
        }
    }
    for (int r = 0; r + 1 < kRows; ++r) {
        for (int c = 0; c + 1 < kCols; ++c) {
            const auto a = v[r * kCols + c], b = v[r * kCols + c + 1], d = v[(r + 1) * kCols + c],
                       e = v[(r + 1) * kCols + c + 1];
            mesh.add_face(a, d, b);
            mesh.add_face(b, d, e);
        }
    }
    mesh.update_normals();
    return mesh;
}

class MeshFileTest : public ::testing::Test {
 protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("facescan_mesh_file_test_" + std::to_string(::getpid()));
        fs::create_directories(dir_);
    }
    void TearDown() override {
        std::error_code ec;
        fs::permissions(dir_, fs::perms::owner_all, ec);
        fs::remove_all(dir_, ec);
    }
    // Only the target itself: no temporary left beside it.
    void expectOnlyFile(const fs::path& path) {
        int files = 0;
        for (const auto& entry : fs::directory_iterator(dir_)) {
            ++files;
            EXPECT_EQ(entry.path(), path) << "left behind: " << entry.path();
        }
        EXPECT_EQ(files, 1);
    }
    fs::path dir_;
};

TEST_F(MeshFileTest, FormatsByExtension) {
    EXPECT_EQ(meshFormatFor("a.ply").value(), MeshFormat::kPly);
    EXPECT_EQ(meshFormatFor("a.OBJ").value(), MeshFormat::kObj);
    EXPECT_EQ(meshFormatFor("x/a.stl").value(), MeshFormat::kStl);
    EXPECT_EQ(meshFormatFor("a.off").value(), MeshFormat::kOff);
    EXPECT_EQ(meshFormatFor("a.drc").value(), MeshFormat::kDrc);
    EXPECT_EQ(meshFormatFor("a.GLB").value(), MeshFormat::kGlb);
    EXPECT_TRUE(formatHasColours(MeshFormat::kGlb));
    EXPECT_FALSE(meshFormatFor("a.png").isOk());
    EXPECT_FALSE(formatHasColours(MeshFormat::kStl));
    EXPECT_TRUE(formatHasColours(MeshFormat::kPly));
}

TEST_F(MeshFileTest, EveryOpenMeshFormatReadsBackWithTheSameCountsAndColours) {
    const recon::Mesh mesh = testMesh();
    for (const char* ext : {"ply", "obj", "stl", "off"}) {
        SCOPED_TRACE(ext);
        const fs::path path = dir_ / (std::string("face.") + ext);
        ASSERT_TRUE(writeMeshFile(mesh, path).isOk());
        expectOnlyFile(path);

        recon::Mesh back;
        OpenMesh::IO::Options opts = OpenMesh::IO::Options::VertexColor;
        ASSERT_TRUE(OpenMesh::IO::read_mesh(back, path.string(), opts));
        EXPECT_EQ(back.n_vertices(), mesh.n_vertices());
        EXPECT_EQ(back.n_faces(), mesh.n_faces());
        const bool colours = formatHasColours(meshFormatFor(path).value());
        if (colours) {
            EXPECT_TRUE(opts.check(OpenMesh::IO::Options::VertexColor));
        }
        // Positions survive to well under a micron (written with 9 significant digits or binary floats).
        float max_error_m = 0;
        if (std::string(ext) != "stl") {  // STL merges and reorders vertices
            for (const auto vh : mesh.vertices()) {
                const auto bh = back.vertex_handle(vh.idx());
                max_error_m = std::max(max_error_m, (mesh.point(vh) - back.point(bh)).norm());
                if (colours) {
                    EXPECT_EQ(back.color(bh), mesh.color(vh)) << "vertex " << vh.idx();
                }
            }
        }
        EXPECT_LT(max_error_m, 1e-6f);
        fs::remove(path);
    }
}

TEST_F(MeshFileTest, DracoFileDecodesWithTheSameCountsAndColours) {
    const recon::Mesh mesh = testMesh();
    const fs::path path = dir_ / "face.drc";
    ASSERT_TRUE(writeMeshFile(mesh, path).isOk());
    expectOnlyFile(path);
    std::ifstream in(path, std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    auto back = wire::decodeMeshDraco(bytes.data(), bytes.size());
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->n_vertices(), mesh.n_vertices());
    EXPECT_EQ(back->n_faces(), mesh.n_faces());
    ASSERT_TRUE(back->has_vertex_colors());
    // Draco reorders vertices: compare the colour histogram's extremes instead of vertex by vertex.
    int max_red = 0;
    for (const auto vh : back->vertices()) max_red = std::max<int>(max_red, back->color(vh)[0]);
    EXPECT_EQ(max_red, 230);
}

// The GLB read back with TinyGLTF's own reader: glTF 2.0, one triangle primitive whose accessors have the mesh's
// counts, positions turned into glTF's axes, the required POSITION bounds, and COLOR_0 with the mesh's colours.
TEST_F(MeshFileTest, GlbReadsBackWithTinyGltfWithColoursAndGltfAxes) {
    const recon::Mesh mesh = testMesh();
    const fs::path path = dir_ / "face.glb";
    ASSERT_TRUE(writeMeshFile(mesh, path).isOk());
    expectOnlyFile(path);

    tinygltf::Model model;
    tinygltf::TinyGLTF reader;
    std::string err, warn;
    ASSERT_TRUE(reader.LoadBinaryFromFile(&model, &err, &warn, path.string())) << err << warn;
    EXPECT_EQ(model.asset.version, "2.0");
    ASSERT_EQ(model.meshes.size(), 1u);
    ASSERT_EQ(model.meshes[0].primitives.size(), 1u);
    const tinygltf::Primitive& prim = model.meshes[0].primitives[0];
    EXPECT_EQ(prim.mode, TINYGLTF_MODE_TRIANGLES);
    ASSERT_TRUE(prim.attributes.count("POSITION") && prim.attributes.count("COLOR_0") &&
                prim.attributes.count("NORMAL"));

    // Reads element i of an accessor (tightly packed, as written).
    auto element = [&](int accessor_index, size_t i) {
        const tinygltf::Accessor& a = model.accessors[accessor_index];
        const tinygltf::BufferView& v = model.bufferViews[a.bufferView];
        const size_t size =
            tinygltf::GetComponentSizeInBytes(a.componentType) * tinygltf::GetNumComponentsInType(a.type);
        return model.buffers[v.buffer].data.data() + v.byteOffset + a.byteOffset + i * size;
    };
    const tinygltf::Accessor& pos = model.accessors[prim.attributes.at("POSITION")];
    ASSERT_EQ(pos.count, mesh.n_vertices());
    EXPECT_EQ(pos.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
    ASSERT_EQ(pos.minValues.size(), 3u);
    ASSERT_EQ(pos.maxValues.size(), 3u);
    const tinygltf::Accessor& idx = model.accessors[prim.indices];
    EXPECT_EQ(idx.count, 3 * mesh.n_faces());
    const tinygltf::Accessor& col = model.accessors[prim.attributes.at("COLOR_0")];
    EXPECT_EQ(col.count, mesh.n_vertices());
    EXPECT_EQ(col.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE);
    EXPECT_TRUE(col.normalized);

    // Vertex by vertex (the GLB keeps OpenMesh's order): (x, -y, -z) and the same colour.
    for (const auto vh : mesh.vertices()) {
        const size_t i = static_cast<size_t>(vh.idx());
        float p[3];
        std::memcpy(p, element(prim.attributes.at("POSITION"), i), sizeof(p));
        EXPECT_FLOAT_EQ(p[0], mesh.point(vh)[0]);
        EXPECT_FLOAT_EQ(p[1], -mesh.point(vh)[1]);
        EXPECT_FLOAT_EQ(p[2], -mesh.point(vh)[2]);
        for (int k = 0; k < 3; ++k) {
            EXPECT_GE(p[k], pos.minValues[k]);
            EXPECT_LE(p[k], pos.maxValues[k]);
        }
        const uint8_t* c = element(prim.attributes.at("COLOR_0"), i);
        EXPECT_EQ(c[0], mesh.color(vh)[0]);
        EXPECT_EQ(c[1], mesh.color(vh)[1]);
        EXPECT_EQ(c[2], mesh.color(vh)[2]);
        EXPECT_EQ(c[3], 255);
    }
    // A matte material (glTF's default is fully metallic and renders black without an environment).
    ASSERT_EQ(model.materials.size(), 1u);
    EXPECT_EQ(model.materials[0].pbrMetallicRoughness.metallicFactor, 0.0);
}

TEST_F(MeshFileTest, DracoPayloadIsWrittenAsItIs) {
    const std::vector<uint8_t> payload = {1, 2, 3, 4, 5};
    const fs::path path = dir_ / "server.drc";
    ASSERT_TRUE(writeMeshFile(recon::Mesh(), path, &payload).isOk());
    EXPECT_EQ(fs::file_size(path), payload.size());
}

TEST_F(MeshFileTest, ReplacesAnExistingFileAtomically) {
    const fs::path path = dir_ / "face.ply";
    { std::ofstream(path) << "old content"; }
    ASSERT_TRUE(writeMeshFile(testMesh(), path).isOk());
    expectOnlyFile(path);
    recon::Mesh back;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(back, path.string()));
    EXPECT_EQ(back.n_faces(), testMesh().n_faces());
}

TEST_F(MeshFileTest, UnwritablePathsAreUnavailableAndLeaveNothing) {
    const recon::Mesh mesh = testMesh();
    const Status missing = writeMeshFile(mesh, dir_ / "no" / "such" / "face.ply");
    EXPECT_EQ(missing.code(), StatusCode::kUnavailable);
    EXPECT_NE(missing.message().find("does not exist"), std::string::npos) << missing.message();

    const Status folder = writeFileAtomically(dir_, "x");
    EXPECT_EQ(folder.code(), StatusCode::kUnavailable);
    EXPECT_NE(folder.message().find("is a folder"), std::string::npos) << folder.message();

    if (::geteuid() != 0) {  // root writes anywhere
        const fs::path locked = dir_ / "locked";
        fs::create_directories(locked);
        fs::permissions(locked, fs::perms::owner_read | fs::perms::owner_exec);
        const Status denied = writeMeshFile(mesh, locked / "face.obj");
        EXPECT_EQ(denied.code(), StatusCode::kUnavailable);
        EXPECT_NE(denied.message().find("not writable"), std::string::npos) << denied.message();
        EXPECT_TRUE(fs::is_empty(locked));
        fs::permissions(locked, fs::perms::owner_all);
    }
}

TEST_F(MeshFileTest, EmptyMeshIsRefused) {
    for (const char* name : {"empty.ply", "empty.glb"}) {
        const Status s = writeMeshFile(recon::Mesh(), dir_ / name);
        EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << name;
        EXPECT_FALSE(fs::exists(dir_ / name));
    }
}

// A textured mesh's GLB: TEXCOORD_0 as given, the atlas as a PNG in the binary chunk (decoded back equal), the
// material's base colour texture pointing at it, and no COLOR_0 (glTF would multiply it into the texture).
TEST(TexturedGlb, CarriesTexcoordsAndTheAtlasAsBaseColourTexture) {
    recon::TexturedMesh t;
    t.mesh.positions_m = {{0, 0, 0.5f}, {0.1f, 0, 0.5f}, {0.1f, 0.1f, 0.5f}, {0, 0.1f, 0.5f}};
    t.mesh.colours_rgb = {{{10, 20, 30}}, {{10, 20, 30}}, {{10, 20, 30}}, {{10, 20, 30}}};
    t.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
    t.uv = {{0.1f, 0.1f}, {0.9f, 0.1f}, {0.9f, 0.9f}, {0.1f, 0.9f}};
    t.atlas_bgr = cv::Mat(8, 8, CV_8UC3);
    cv::randu(t.atlas_bgr, cv::Scalar::all(0), cv::Scalar::all(255));
    auto glb = meshToGlb(t);
    ASSERT_TRUE(glb.isOk()) << glb.status().toString();

    tinygltf::Model model;
    tinygltf::TinyGLTF reader;
    std::string err, warn;
    ASSERT_TRUE(reader.LoadBinaryFromMemory(&model, &err, &warn, reinterpret_cast<const unsigned char*>(glb->data()),
                                            static_cast<unsigned>(glb->size())))
        << err << warn;
    const tinygltf::Primitive& prim = model.meshes.at(0).primitives.at(0);
    EXPECT_EQ(prim.attributes.count("COLOR_0"), 0u);
    ASSERT_EQ(prim.attributes.count("TEXCOORD_0"), 1u);
    const tinygltf::Accessor& tc = model.accessors[prim.attributes.at("TEXCOORD_0")];
    ASSERT_EQ(tc.count, 4u);
    const tinygltf::BufferView& tv = model.bufferViews[tc.bufferView];
    for (size_t i = 0; i < 4; ++i) {
        float uv[2];
        std::memcpy(uv, model.buffers[0].data.data() + tv.byteOffset + tc.byteOffset + i * 8, sizeof uv);
        EXPECT_FLOAT_EQ(uv[0], t.uv[i].x());
        EXPECT_FLOAT_EQ(uv[1], t.uv[i].y());
    }
    ASSERT_EQ(model.materials.size(), 1u);
    const int texture = model.materials[0].pbrMetallicRoughness.baseColorTexture.index;
    ASSERT_EQ(texture, 0);
    const int source = model.textures.at(0).source;
    const tinygltf::Image& image = model.images.at(static_cast<size_t>(source));
    EXPECT_EQ(image.mimeType, "image/png");
    ASSERT_GE(image.bufferView, 0);
    const tinygltf::BufferView& iv = model.bufferViews[static_cast<size_t>(image.bufferView)];
    const std::vector<uint8_t> png(model.buffers[0].data.begin() + static_cast<long>(iv.byteOffset),
                                   model.buffers[0].data.begin() + static_cast<long>(iv.byteOffset + iv.byteLength));
    const cv::Mat decoded = cv::imdecode(png, cv::IMREAD_COLOR);
    ASSERT_EQ(decoded.size(), t.atlas_bgr.size());
    EXPECT_EQ(cv::norm(decoded, t.atlas_bgr, cv::NORM_INF), 0.0);

    recon::TexturedMesh untextured;
    untextured.mesh = t.mesh;
    EXPECT_FALSE(meshToGlb(untextured).isOk());
}

// A textured quad as a finished scan's GET_MESH reply carries it: Draco with texture coordinates and the PNG.
recon::TexturedMesh texturedQuad() {
    recon::TexturedMesh t;
    t.mesh.positions_m = {{0, 0, 0.5f}, {0.1f, 0, 0.5f}, {0.1f, 0.1f, 0.5f}, {0, 0.1f, 0.5f}};
    t.mesh.colours_rgb = {{{10, 20, 30}}, {{10, 20, 30}}, {{10, 20, 30}}, {{10, 20, 30}}};
    t.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
    t.uv = {{0.1f, 0.1f}, {0.9f, 0.1f}, {0.9f, 0.9f}, {0.1f, 0.9f}};
    t.atlas_bgr = cv::Mat(8, 16, CV_8UC3);
    cv::randu(t.atlas_bgr, cv::Scalar::all(0), cv::Scalar::all(255));
    return t;
}

TEST(TexturedFiles, DecodingChecksTheCoordinatesAndThePicture) {
    const recon::TexturedMesh t = texturedQuad();
    std::vector<uint8_t> draco, png, plain;
    ASSERT_TRUE(wire::encodeTexturedMeshDraco(t, {}, draco).isOk());
    ASSERT_TRUE(cv::imencode(".png", t.atlas_bgr, png));
    auto decoded = decodeTexturedMesh(draco, png);
    ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
    EXPECT_EQ(decoded->uv.size(), decoded->mesh.vertexCount());
    EXPECT_EQ(decoded->mesh.triangleCount(), 2u);
    EXPECT_EQ(cv::norm(decoded->atlas_bgr, t.atlas_bgr, cv::NORM_INF), 0.0);

    const std::vector<uint8_t> not_png(100, 7);
    EXPECT_EQ(decodeTexturedMesh(draco, not_png).status().code(), StatusCode::kDataLoss);
    std::vector<uint8_t> huge = png;  // the IHDR's width and height (big-endian) at 16 and 20
    huge[16] = 0x7f;
    const auto refused = decodeTexturedMesh(draco, huge);
    EXPECT_EQ(refused.status().code(), StatusCode::kDataLoss);
    EXPECT_NE(refused.status().message().find("claims"), std::string::npos) << refused.status().message();
    ASSERT_TRUE(wire::encodeMeshDraco(t.mesh, {}, plain).isOk());
    EXPECT_EQ(decodeTexturedMesh(plain, png).status().code(), StatusCode::kDataLoss);
    EXPECT_EQ(decodeTexturedMesh(std::vector<uint8_t>(draco.begin(), draco.begin() + 20), png).status().code(),
              StatusCode::kDataLoss);
}

TEST(TexturedFiles, ObjWithMtlAndPngPlyWithPngGlbAlone) {
    const recon::TexturedMesh t = texturedQuad();
    const fs::path dir = fs::temp_directory_path() / ("facescan_textured_files_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    auto read = [](const fs::path& p) {
        std::ifstream in(p, std::ios::binary);
        return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    };
    // A name with a space: the names inside the files are plain (an OBJ's mtllib ends at a space).
    auto obj = writeTexturedMeshFiles(t, dir / "my face.obj");
    ASSERT_TRUE(obj.isOk()) << obj.status().toString();
    ASSERT_EQ(obj->size(), 3u);
    EXPECT_EQ((*obj)[0], dir / "my face.obj");
    EXPECT_EQ((*obj)[1], dir / "my_face.mtl");
    EXPECT_EQ((*obj)[2], dir / "my_face.png");
    EXPECT_NE(read(dir / "my face.obj").find("mtllib my_face.mtl"), std::string::npos);
    EXPECT_NE(read(dir / "my_face.mtl").find("map_Kd my_face.png"), std::string::npos);
    const cv::Mat png = cv::imread((dir / "my_face.png").string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(png.empty());
    EXPECT_EQ(cv::norm(png, t.atlas_bgr, cv::NORM_INF), 0.0);

    auto ply = writeTexturedMeshFiles(t, dir / "face.PLY");
    ASSERT_TRUE(ply.isOk()) << ply.status().toString();
    EXPECT_EQ(*ply, (std::vector<fs::path>{dir / "face.PLY", dir / "face.png"}));
    EXPECT_NE(read(dir / "face.PLY").find("comment TextureFile face.png"), std::string::npos);

    auto glb = writeTexturedMeshFiles(t, dir / "face.glb");
    ASSERT_TRUE(glb.isOk());
    EXPECT_EQ(*glb, std::vector<fs::path>{dir / "face.glb"});
    EXPECT_EQ(read(dir / "face.glb").substr(0, 4), "glTF");

    EXPECT_EQ(writeTexturedMeshFiles(t, dir / "face.stl").status().code(), StatusCode::kInvalidArgument);
    EXPECT_FALSE(fs::exists(dir / "face.stl"));
    EXPECT_EQ(writeTexturedMeshFiles(t, dir / "missing" / "face.obj").status().code(), StatusCode::kUnavailable);
    fs::remove_all(dir);
}

}  // namespace
}  // namespace facescan::client
