// The finished model's texture from the server to the user, over real DDS: facescan-server and facescan-agent
// (synthetic Kinect with colour, a recording, so the scan finishes at its end) run as child processes on loopback
// in a private domain, and the real `facescan mesh` writes what the server sends. A finished scan with colour comes
// back textured (GLB, OBJ + MTL + PNG, PLY + PNG: texture coordinates present, the picture decodes, its size is
// the server's textured.png), from a retired session's files and from a restarted server's data dir, and at once
// after `facescan mesh --finish` from the session still in memory; --vertex-colours keeps one file; a scan without
// colour answers with the mesh alone. And a server finishing with --close watertight sends a closed model: every
// edge shared by two faces.
#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <regex>

#include "child_process.hpp"
#include "http_client.hpp"
#include "run_command.hpp"
#include "test_domain.hpp"
#include "wire/mesh_codec.hpp"

namespace {

using namespace facescan;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using facescan::testing::ChildProcess;
using facescan::testing::readText;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// A server (with extra flags) and a short recording with colour in one private domain, under one folder.
struct Scan {
    std::string domain, session;
    fs::path dir;
    std::vector<std::string> dds;
    std::unique_ptr<ChildProcess> server;

    Scan(int index, const std::string& name)
        : domain(std::to_string(facescan::testing::privateDomain(index))),
          session(name + "-" + std::to_string(::getpid())),
          dir(fs::temp_directory_path() / ("facescan_tex_e2e_" + name + "_" + std::to_string(::getpid()))) {
        fs::remove_all(dir);
        fs::create_directories(dir);
        dds = {"--profile", "loopback", "--domain", domain};
    }
    ~Scan() {
        if (server) server->stop();
        if (!::testing::Test::HasFailure()) fs::remove_all(dir);
    }
    std::vector<std::string> with(std::vector<std::string> args) const {
        args.insert(args.end(), dds.begin(), dds.end());
        return args;
    }
    void startServer(const std::vector<std::string>& extra = {}) {
        // One id: a restarted server answers for the scans its data dir records as its own.
        std::vector<std::string> args = {FACESCAN_SERVER_BIN, "--data-dir", (dir / "data").string(), "--server-id",
                                         "tex-e2e"};
        args.insert(args.end(), extra.begin(), extra.end());
        server = std::make_unique<ChildProcess>(with(args), dir / "server.log");
    }
    // The recording to its end: the server finishes it and writes its files.
    int record(int frames, const std::vector<std::string>& extra = {}) const {
        std::vector<std::string> args = {FACESCAN_AGENT_BIN,
                                         "--session",
                                         session,
                                         "--source",
                                         "synthetic:frames=" + std::to_string(frames) + ",subject=builtin,seed=3",
                                         "--rate",
                                         "max",
                                         "--wait-for-server",
                                         "30"};
        args.insert(args.end(), extra.begin(), extra.end());
        ChildProcess agent(with(args), dir / "agent.log");
        return agent.wait(90s);
    }
    bool waitForFiles() const {
        return facescan::testing::pollUntilTrue([&] { return fs::exists(dir / "data" / session / "summary.json"); },
                                                60s);
    }
    facescan::testing::CommandRun cli(const std::vector<std::string>& args) const {
        std::string line = FACESCAN_CLI;
        for (const std::string& a : with(args)) line += " '" + a + "'";
        return facescan::testing::runCommand(line + " --timeout 20");
    }
    std::string logs() const {
        return "\nserver:\n" + readText(dir / "server.log") + "\nagent:\n" + readText(dir / "agent.log");
    }
};

size_t countLines(const std::string& text, const std::string& prefix) {
    size_t n = 0;
    for (size_t at = 0; at < text.size();) {
        if (text.compare(at, prefix.size(), prefix) == 0) ++n;
        const size_t end = text.find('\n', at);
        if (end == std::string::npos) break;
        at = end + 1;
    }
    return n;
}

// The edges of a triangle mesh whose vertices are welded by position, and how many faces use each.
std::map<std::pair<uint32_t, uint32_t>, int> edgeUses(const recon::IndexedMesh& mesh) {
    std::map<std::array<float, 3>, uint32_t> ids;
    std::vector<uint32_t> welded(mesh.vertexCount());
    for (size_t i = 0; i < mesh.vertexCount(); ++i) {
        const Eigen::Vector3f& p = mesh.positions_m[i];
        welded[i] =
            ids.emplace(std::array<float, 3>{p.x(), p.y(), p.z()}, static_cast<uint32_t>(ids.size())).first->second;
    }
    std::map<std::pair<uint32_t, uint32_t>, int> uses;
    for (const recon::Triangle& t : mesh.triangles) {
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = welded[t[k]], b = welded[t[(k + 1) % 3]];
            ++uses[{std::min(a, b), std::max(a, b)}];
        }
    }
    return uses;
}

TEST(TextureEndToEnd, AFinishedScansTextureReachesFacescanMeshAlsoFromARestartedServer) {
    Scan scan(16, "tex");
    scan.startServer();
    ASSERT_EQ(scan.record(24), 0) << scan.logs();
    ASSERT_TRUE(scan.waitForFiles()) << scan.logs();
    const fs::path data = scan.dir / "data" / scan.session;
    const cv::Mat server_atlas = cv::imread((data / "textured.png").string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(server_atlas.empty()) << "the synthetic scan has colour: the server bakes a texture" << scan.logs();
    ASSERT_TRUE(fs::exists(data / "textured.drc"));

    // OBJ + MTL + PNG beside it; the output names the three files.
    const fs::path obj = scan.dir / "face.obj";
    auto run = scan.cli({"mesh", scan.session, "-o", obj.string()});
    ASSERT_EQ(run.exit_code, 0) << run.out << scan.logs();
    EXPECT_TRUE(
        contains(run.out, "face.obj, " + (scan.dir / "face.mtl").string() + ", " + (scan.dir / "face.png").string()))
        << run.out;
    EXPECT_TRUE(contains(run.out, "textured (" + std::to_string(server_atlas.cols) + " x " +
                                      std::to_string(server_atlas.rows) + " texture, vertex colours kept)"))
        << run.out;
    const std::string obj_text = readText(obj);
    EXPECT_TRUE(contains(obj_text, "mtllib face.mtl"));
    EXPECT_EQ(countLines(obj_text, "vt "), countLines(obj_text, "v "));
    EXPECT_GT(countLines(obj_text, "f "), 1000u);
    EXPECT_TRUE(contains(readText(scan.dir / "face.mtl"), "map_Kd face.png"));
    const cv::Mat atlas = cv::imread((scan.dir / "face.png").string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(atlas.empty());
    EXPECT_EQ(atlas.size(), server_atlas.size());
    EXPECT_EQ(cv::norm(atlas, server_atlas, cv::NORM_INF), 0.0) << "the server's picture, losslessly";

    // GLB: texture coordinates and the picture as its base colour texture, of the same size.
    const fs::path glb = scan.dir / "face.glb";
    run = scan.cli({"mesh", scan.session, "-o", glb.string()});
    ASSERT_EQ(run.exit_code, 0) << run.out;
    tinygltf::Model model;
    tinygltf::TinyGLTF reader;
    std::string err, warn;
    ASSERT_TRUE(reader.LoadBinaryFromFile(&model, &err, &warn, glb.string())) << err;
    const auto& prim = model.meshes.at(0).primitives.at(0);
    ASSERT_TRUE(prim.attributes.count("TEXCOORD_0"));
    EXPECT_EQ(model.accessors[prim.attributes.at("TEXCOORD_0")].count,
              model.accessors[prim.attributes.at("POSITION")].count);
    ASSERT_EQ(model.materials.at(0).pbrMetallicRoughness.baseColorTexture.index, 0);
    const tinygltf::BufferView& iv = model.bufferViews.at(static_cast<size_t>(model.images.at(0).bufferView));
    const std::vector<uint8_t> png(model.buffers[0].data.begin() + static_cast<long>(iv.byteOffset),
                                   model.buffers[0].data.begin() + static_cast<long>(iv.byteOffset + iv.byteLength));
    EXPECT_EQ(cv::imdecode(png, cv::IMREAD_COLOR).size(), server_atlas.size());

    // --vertex-colours: one PLY, no texture, as while scanning.
    const fs::path plain = scan.dir / "plain.ply";
    run = scan.cli({"mesh", scan.session, "-o", plain.string(), "--vertex-colours"});
    ASSERT_EQ(run.exit_code, 0) << run.out;
    EXPECT_TRUE(contains(run.out, "with colours")) << run.out;
    EXPECT_FALSE(contains(readText(plain), "TextureFile"));
    EXPECT_FALSE(fs::exists(scan.dir / "plain.png"));

    // A restarted server answers from its data dir: the texture comes from there (PLY with u, v and its picture).
    scan.server->stop();
    scan.startServer();
    const fs::path ply = scan.dir / "again.ply";
    run = scan.cli({"mesh", scan.session, "-o", ply.string()});
    ASSERT_EQ(run.exit_code, 0) << run.out << scan.logs();
    EXPECT_TRUE(contains(run.out, "again.png")) << run.out;
    EXPECT_TRUE(contains(readText(ply), "comment TextureFile again.png"));
    OpenMesh::TriMesh_ArrayKernelT<> textured;
    textured.request_vertex_texcoords2D();
    OpenMesh::IO::Options opts = OpenMesh::IO::Options::VertexTexCoord;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(textured, ply.string(), opts));
    EXPECT_TRUE(opts.vertex_has_texcoord());
    EXPECT_EQ(cv::imread((scan.dir / "again.png").string(), cv::IMREAD_COLOR).size(), server_atlas.size());
}

// `facescan mesh --finish` during a live scan: the server finishes it and the texture comes at once, from the
// session still in the server's memory.
TEST(TextureEndToEnd, FinishingALiveScanFromTheClientBringsTheTexture) {
    Scan scan(19, "live");
    scan.startServer();
    ChildProcess agent(
        scan.with({FACESCAN_AGENT_BIN, "--session", scan.session, "--source",
                   "synthetic:frames=900,subject=builtin,seed=4", "--rate", "real", "--wait-for-server", "30"}),
        scan.dir / "agent.log");
    std::smatch integrated;
    const std::regex kIntegrated(R"(([0-9]+) integrated)");
    ASSERT_TRUE(facescan::testing::pollUntilTrue(
        [&] {
            const std::string out = scan.cli({"status", scan.session}).out;
            return contains(out, "SCANNING") && std::regex_search(out, integrated, kIntegrated) &&
                   std::stoi(integrated[1].str()) >= 20;
        },
        60s))
        << scan.cli({"status", scan.session}).out << scan.logs();
    const fs::path glb = scan.dir / "live.glb";
    const auto run = scan.cli({"mesh", scan.session, "-o", glb.string(), "--finish"});
    ASSERT_EQ(run.exit_code, 0) << run.out << scan.logs();
    EXPECT_TRUE(contains(run.out, "finished " + scan.session)) << run.out;
    EXPECT_TRUE(contains(run.out, "textured (")) << run.out;
    const cv::Mat server_atlas =
        cv::imread((scan.dir / "data" / scan.session / "textured.png").string(), cv::IMREAD_COLOR);
    EXPECT_TRUE(contains(run.out, std::to_string(server_atlas.cols) + " x " + std::to_string(server_atlas.rows)))
        << run.out;
    agent.stop();
}

// Depth only (agent --no-colour): no texture, and the same request gets the vertex-coloured mesh, as before.
TEST(TextureEndToEnd, AScanWithoutColourAnswersWithTheMeshAlone) {
    Scan scan(18, "nocolour");
    scan.startServer();
    ASSERT_EQ(scan.record(16, {"--no-colour"}), 0) << scan.logs();
    ASSERT_TRUE(scan.waitForFiles()) << scan.logs();
    EXPECT_FALSE(fs::exists(scan.dir / "data" / scan.session / "textured.drc"));
    const fs::path obj = scan.dir / "plain.obj";
    const auto run = scan.cli({"mesh", scan.session, "-o", obj.string()});
    ASSERT_EQ(run.exit_code, 0) << run.out << scan.logs();
    EXPECT_TRUE(contains(run.out, "wrote " + obj.string() + ": ")) << run.out;
    EXPECT_FALSE(contains(run.out, "textured")) << run.out;
    EXPECT_FALSE(fs::exists(scan.dir / "plain.mtl"));
    EXPECT_FALSE(fs::exists(scan.dir / "plain.png"));
    const std::string text = readText(obj);
    EXPECT_GT(countLines(text, "f "), 1000u);
    EXPECT_EQ(countLines(text, "vt "), 0u);
}

TEST(TextureEndToEnd, AWatertightFinishThroughTheServerComesBackClosed) {
    Scan scan(17, "closed");
    scan.startServer({"--close", "watertight"});
    ASSERT_EQ(scan.record(20), 0) << scan.logs();
    ASSERT_TRUE(scan.waitForFiles()) << scan.logs();
    const std::string summary = readText(scan.dir / "data" / scan.session / "summary.json");

    // The model as Draco, as the server sent it (no texture asked for with .drc): every edge shared by two faces.
    const fs::path drc = scan.dir / "closed.drc";
    auto run = scan.cli({"mesh", scan.session, "-o", drc.string()});
    ASSERT_EQ(run.exit_code, 0) << run.out << scan.logs();
    const std::string bytes = readText(drc);
    auto mesh = wire::decodeIndexedMesh(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
    ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
    EXPECT_GT(mesh->triangleCount(), 1000u);
    size_t open_edges = 0, non_manifold_edges = 0;
    for (const auto& [edge, uses] : edgeUses(*mesh)) {
        if (uses == 1) ++open_edges;
        if (uses > 2) ++non_manifold_edges;
    }
    EXPECT_EQ(open_edges, 0u) << summary;
    EXPECT_EQ(non_manifold_edges, 0u) << summary;

    // Its textured model is the same closed surface, cut only where the texture's charts meet: welded by position,
    // closed as well.
    const fs::path glb = scan.dir / "closed.glb";
    run = scan.cli({"mesh", scan.session, "-o", glb.string()});
    ASSERT_EQ(run.exit_code, 0) << run.out;
    ASSERT_TRUE(contains(run.out, "textured")) << run.out;
    const fs::path data = scan.dir / "data" / scan.session;
    const std::string textured_bytes = readText(data / "textured.drc");
    recon::IndexedMesh textured;
    std::vector<Eigen::Vector2f> uv;
    ASSERT_TRUE(wire::decodeMeshDraco(reinterpret_cast<const uint8_t*>(textured_bytes.data()), textured_bytes.size(),
                                      textured, uv)
                    .isOk());
    EXPECT_EQ(uv.size(), textured.vertexCount());
    size_t textured_open = 0;
    for (const auto& [edge, uses] : edgeUses(textured)) textured_open += uses != 2;
    EXPECT_EQ(textured_open, 0u);
}

}  // namespace
