// `facescan view` over real DDS, no browser: facescan-server and facescan-agent (synthetic Kinect, a recording)
// and the real `facescan view` program run as child processes on loopback in a private domain; a WebSocket client
// follows the scan and decodes the snapshots it is pushed; the HTTP API answers with the session, its latest
// snapshot and its final mesh (GLB read back with TinyGLTF, textured, PLY with OpenMesh, vertex-coloured, one
// model), the page's textured model, 404 for a session
// no server knows, 400 for a malformed one; Ctrl-C stops the viewer cleanly. The browser test adds the page itself.
#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <filesystem>
#include <fstream>
#include <regex>

#include "child_process.hpp"
#include "client/web_assets.hpp"
#include "glb_reader.hpp"
#include "http_client.hpp"
#include "test_domain.hpp"
#include "wire/mesh_codec.hpp"

namespace {

using namespace facescan;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using facescan::testing::ChildProcess;
using facescan::testing::httpRequest;
using facescan::testing::readGlb;
using facescan::testing::readText;
using facescan::testing::WsClient;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(ViewEndToEnd, FollowsARealScanAndServesItsMeshes) {
    if (auto root = client::findWebRoot(); !root.isOk()) GTEST_SKIP() << root.status().message();
    const std::string domain = std::to_string(facescan::testing::privateDomain(15));
    const std::string session = "view-" + std::to_string(::getpid());
    const fs::path dir = fs::temp_directory_path() / ("facescan_view_e2e_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::vector<std::string> dds = {"--profile", "loopback", "--domain", domain};
    auto with = [&](std::vector<std::string> args) {
        args.insert(args.end(), dds.begin(), dds.end());
        return args;
    };

    ChildProcess viewer(with({FACESCAN_CLI, "view", "--port", "0"}), dir / "view.log");
    std::smatch match;
    const std::regex serving(R"(serving http://127\.0\.0\.1:(\d+)/)");
    ASSERT_TRUE(facescan::testing::pollUntilTrue(
        [&] {
            const std::string log = readText(dir / "view.log");
            return std::regex_search(log, match, serving);
        },
        15s))
        << readText(dir / "view.log");
    const uint16_t port = static_cast<uint16_t>(std::stoi(match[1].str()));
    WsClient ws(port);
    ASSERT_TRUE(ws.connected()) << ws.error();
    ASSERT_TRUE(ws.send("follow " + session));  // before the scan exists: snapshots come once it does

    ChildProcess server(with({FACESCAN_SERVER_BIN, "--data-dir", (dir / "data").string(), "--snapshot-hz", "4"}),
                        dir / "server.log");
    ChildProcess agent(with({FACESCAN_AGENT_BIN, "--session", session, "--source",
                             "synthetic:frames=40,subject=builtin,seed=2", "--rate", "max", "--wait-for-server", "30"}),
                       dir / "agent.log");

    auto logs = [&] {
        return "\nview:\n" + readText(dir / "view.log") + "\nserver:\n" + readText(dir / "server.log") + "\nagent:\n" +
               readText(dir / "agent.log");
    };
    // The snapshot as pushed: [u32 header length][JSON header][the server's Draco bytes], decodable as they are.
    ASSERT_TRUE(ws.waitFor(
        [](const auto& m) { return std::any_of(m.begin(), m.end(), [](const auto& x) { return x.binary; }); }, 60s))
        << logs();
    std::string frame;
    for (const auto& m : ws.messages()) {
        if (m.binary && frame.empty()) frame = m.data;
    }
    const uint32_t header_bytes =
        uint8_t(frame[0]) | uint8_t(frame[1]) << 8 | uint8_t(frame[2]) << 16 | uint32_t(uint8_t(frame[3])) << 24;
    ASSERT_LT(4 + header_bytes, frame.size());
    EXPECT_TRUE(contains(frame.substr(4, header_bytes), "\"session\":\"" + session + "\"")) << frame.substr(4, 200);
    const std::string drc = frame.substr(4 + header_bytes);
    auto snapshot = wire::decodeMeshDraco(reinterpret_cast<const uint8_t*>(drc.data()), drc.size());
    ASSERT_TRUE(snapshot.isOk()) << snapshot.status().toString();
    EXPECT_GT(snapshot->n_faces(), 100u);

    // The recording ends; the session's status says FINISHED once the server has processed the end of stream.
    EXPECT_EQ(agent.wait(60s), 0) << logs();
    ASSERT_TRUE(facescan::testing::pollUntilTrue(
        [&] { return contains(httpRequest(port, "/api/sessions/" + session).body, "\"state\":\"FINISHED\""); }, 30s))
        << httpRequest(port, "/api/sessions/" + session).body << logs();
    const auto list = httpRequest(port, "/api/sessions");
    EXPECT_TRUE(contains(list.body, "\"session\":\"" + session + "\"")) << list.body;
    const auto snap = httpRequest(port, "/api/sessions/" + session + "/snapshot.drc");
    ASSERT_EQ(snap.status, 200);
    EXPECT_TRUE(wire::decodeMeshDraco(reinterpret_cast<const uint8_t*>(snap.body.data()), snap.body.size()).isOk());

    // The final mesh from the server (GET_MESH over DDS), as GLB and PLY: the same mesh.
    const auto glb = httpRequest(port, "/api/sessions/" + session + "/mesh.glb");
    ASSERT_EQ(glb.status, 200) << glb.body << logs();
    tinygltf::Model model;
    std::string err;
    ASSERT_TRUE(readGlb(glb.body, model, err)) << err;
    const auto& prim = model.meshes.at(0).primitives.at(0);
    // The agent sends colour: the finished model has a texture, which the GLB holds (the PLY: vertex colours).
    ASSERT_TRUE(prim.attributes.count("TEXCOORD_0")) << "the agent sends colour: the GLB has the texture";
    EXPECT_EQ(model.images.size(), 1u);
    const auto ply = httpRequest(port, "/api/sessions/" + session + "/mesh.ply");
    ASSERT_EQ(ply.status, 200);
    { std::ofstream(dir / "face.ply", std::ios::binary) << ply.body; }
    recon::Mesh mesh;
    OpenMesh::IO::Options colour = OpenMesh::IO::Options::VertexColor;
    mesh.request_vertex_colors();
    ASSERT_TRUE(OpenMesh::IO::read_mesh(mesh, (dir / "face.ply").string(), colour));
    EXPECT_TRUE(colour.check(OpenMesh::IO::Options::VertexColor));
    EXPECT_GT(mesh.n_faces(), 1000u);
    // One model: the textured one is split where its charts meet, and is the finished model before Draco's grid
    // (the PLY is after it, which may drop a degenerate triangle, and OpenMesh's reader leaves out a non-manifold one).
    EXPECT_GE(model.accessors[prim.attributes.at("POSITION")].count, mesh.n_vertices());
    EXPECT_NEAR(double(model.accessors[prim.indices].count) / 3.0, double(mesh.n_faces()), 0.05 * mesh.n_faces());
    // The page's textured model: [u32 header length][{"texture_bytes": N}][PNG][Draco with texture coordinates].
    const auto textured = httpRequest(port, "/api/sessions/" + session + "/textured");
    ASSERT_EQ(textured.status, 200) << textured.body;
    const uint32_t texture_header = uint8_t(textured.body[0]) | uint8_t(textured.body[1]) << 8;
    std::smatch texture_bytes;
    const std::string texture_json = textured.body.substr(4, texture_header);
    ASSERT_TRUE(std::regex_search(texture_json, texture_bytes, std::regex(R"("texture_bytes": (\d+))")))
        << texture_json;
    const std::string textured_drc = textured.body.substr(4 + texture_header + std::stoul(texture_bytes[1].str()));
    recon::IndexedMesh textured_mesh;
    std::vector<Eigen::Vector2f> uv;
    ASSERT_TRUE(wire::decodeMeshDraco(reinterpret_cast<const uint8_t*>(textured_drc.data()), textured_drc.size(),
                                      textured_mesh, uv)
                    .isOk());
    EXPECT_EQ(uv.size(), textured_mesh.vertexCount());

    // Bad input reaches no crash: a session no server knows (the servers' own answer) and a malformed one.
    const auto unknown = httpRequest(port, "/api/sessions/no-such-scan/mesh.glb");
    EXPECT_EQ(unknown.status, 404) << unknown.body;
    EXPECT_TRUE(contains(unknown.body, "unknown session 'no-such-scan'")) << unknown.body;
    EXPECT_EQ(httpRequest(port, "/api/sessions/bad%20id!/mesh.glb").status, 400);
    EXPECT_EQ(httpRequest(port, "/api/sessions").status, 200);

    // Ctrl-C: the viewer closes the browsers' sockets and exits 0.
    viewer.signal(SIGINT);
    EXPECT_EQ(viewer.wait(10s), 0) << logs();
    EXPECT_TRUE(ws.waitClosed(5s));
    EXPECT_TRUE(contains(readText(dir / "view.log"), "facescan view: stopped")) << logs();
    server.stop();
    fs::remove_all(dir);
}

}  // namespace
