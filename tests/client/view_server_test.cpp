// The web viewer's endpoints over a real socket (127.0.0.1, an ephemeral port): the page and three.js files, the
// JSON API, snapshots and meshes as the hub holds them, downloads in every format, WebSocket fan-out (latest
// snapshot first, a slow browser skipping to the newest), and every bad input: unknown session 404, malformed 400,
// wrong method 405, traversal attempts, garbage bytes, a foreign Origin. The DDS side is the real ViewHub fed with
// real Draco bytes here; tests/integration/view_end_to_end_test.cpp and the browser test run it over DDS.
#include "client/view_server.hpp"

#include <gtest/gtest.h>
#include <tiny_gltf.h>
#include <zlib.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "client/view_hub.hpp"
#include "glb_reader.hpp"
#include "http_client.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::client {
namespace {

using namespace std::chrono_literals;
using facescan::testing::httpRequest;
using facescan::testing::readGlb;
using facescan::testing::WsClient;

// A small coloured patch: a real mesh for the real codec.
recon::Mesh patch(float z_m) {
    recon::Mesh mesh;
    constexpr int kN = 12;
    std::vector<recon::Mesh::VertexHandle> v;
    for (int r = 0; r < kN; ++r) {
        for (int c = 0; c < kN; ++c) {
            const auto vh = mesh.add_vertex({0.01f * c, 0.01f * r, z_m + 0.002f * std::sin(0.5f * c)});
            mesh.set_color(vh, {static_cast<unsigned char>(20 * c), static_cast<unsigned char>(20 * r), 90});
            v.push_back(vh);
        }
    }
    for (int r = 0; r + 1 < kN; ++r) {
        for (int c = 0; c + 1 < kN; ++c) {
            mesh.add_face(v[r * kN + c], v[(r + 1) * kN + c], v[r * kN + c + 1]);
            mesh.add_face(v[r * kN + c + 1], v[(r + 1) * kN + c], v[(r + 1) * kN + c + 1]);
        }
    }
    mesh.update_normals();
    return mesh;
}

std::vector<uint8_t> draco(const recon::Mesh& mesh) {
    std::vector<uint8_t> bytes;
    EXPECT_TRUE(wire::encodeMeshDraco(mesh, {}, bytes).isOk());
    return bytes;
}

// The patch textured: each vertex mapped by its position onto a 32 x 16 picture, left half red, right half blue.
FetchedMesh texturedPatch() {
    recon::TexturedMesh t;
    t.mesh = recon::fromOpenMesh(patch(0.7f));
    for (const Eigen::Vector3f& p : t.mesh.positions_m) t.uv.emplace_back(p.x() / 0.11f, p.y() / 0.11f);
    t.atlas_bgr = cv::Mat(16, 32, CV_8UC3, cv::Scalar(0, 0, 255));
    t.atlas_bgr.colRange(16, 32).setTo(cv::Scalar(255, 0, 0));
    FetchedMesh fetched;
    EXPECT_TRUE(wire::encodeTexturedMeshDraco(t, {}, fetched.draco).isOk());
    EXPECT_TRUE(cv::imencode(".png", t.atlas_bgr, fetched.texture_png));
    return fetched;
}

MeshSnapshotData snapshotOf(const std::string& session, uint32_t seq) {
    MeshSnapshotData s;
    s.session_id = session;
    s.seq = seq;
    s.frames_integrated = 10 * seq;
    s.created_ns = 1'700'000'000'000'000'000 + int64_t(seq) * 1'000'000;
    const recon::Mesh mesh = patch(0.7f + 0.001f * static_cast<float>(seq));
    s.vertex_count = static_cast<uint32_t>(mesh.n_vertices());
    s.triangle_count = static_cast<uint32_t>(mesh.n_faces());
    s.draco = draco(mesh);
    return s;
}

SessionStatus statusOf(const std::string& session, facescan_wire_ScanState state) {
    SessionStatus s;
    s.session_id = session;
    s.server_id = "server-a";
    s.state = state;
    s.detail = "turn back toward the camera";
    s.frames_received = 12;
    s.frames_integrated = 10;
    s.fps = 29.5f;
    return s;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// One viewer for the suite (CivetWeb takes about 2 s to stop); the tests use sessions of their own.
class ViewServerTest : public ::testing::Test {
 protected:
    static void SetUpTestSuite() {
        auto root = findWebRoot();
        if (!root.isOk()) {
            skip_reason_ = new std::string(root.status().message());
            return;
        }
        hub_ = new ViewHub();
        hub_->updateStatuses({{"scan-1", statusOf("scan-1", facescan_wire_STATE_SCANNING)}});
        config_ = new ViewServerConfig();
        config_->port = 0;
        config_->web_root = *root;
        auto server = ViewServer::start(*config_, *hub_, fetch);
        if (!server.isOk()) {
            skip_reason_ = new std::string("cannot start: " + server.status().toString());
            return;
        }
        server_ = std::move(server).value().release();
        port_ = server_->port();
    }
    static void TearDownTestSuite() {
        delete server_;
        delete hub_;
        delete config_;
        delete skip_reason_;
        server_ = nullptr;
    }
    void SetUp() override {
        if (skip_reason_) GTEST_SKIP() << *skip_reason_;
    }

    // Stands in for the servers' GET_MESH (the real fetcher is ScanClient::request, run over DDS in the
    // integration tests): scan-1 has a mesh, "finished-1" a texture too (when asked for), "offline" has no server
    // answering, anything else is unknown.
    static StatusOr<FetchedMesh> fetch(const std::string& session, bool want_texture) {
        ++fetches_;
        if (session == "scan-1") return FetchedMesh{draco(patch(0.7f)), {}};
        if (session == "finished-1") return want_texture ? texturedPatch() : FetchedMesh{draco(patch(0.7f)), {}};
        if (session == "offline") return deadlineExceeded("no server answered on domain 7");
        return notFound("unknown session '" + session + "'");
    }

    static inline std::string* skip_reason_ = nullptr;
    static inline ViewServerConfig* config_ = nullptr;
    static inline ViewHub* hub_ = nullptr;
    static inline ViewServer* server_ = nullptr;
    static inline uint16_t port_ = 0;
    static inline std::atomic<int> fetches_{0};
};

TEST_F(ViewServerTest, ServesThePageAndEveryThreeJsFileWithItsType) {
    for (const WebAsset& asset : webAssets()) {
        SCOPED_TRACE(asset.url);
        const auto r = httpRequest(port_, asset.url);
        ASSERT_EQ(r.status, 200) << r.error;
        EXPECT_EQ(r.header("Content-Type"), asset.mime);
        std::ifstream file(config_->web_root / asset.path, std::ios::binary);
        const std::string expected((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
        EXPECT_EQ(r.body, expected);
    }
    EXPECT_TRUE(contains(httpRequest(port_, "/").body, "<script type=\"importmap\">"));
    EXPECT_EQ(httpRequest(port_, "/", "HEAD").body, "");
    EXPECT_EQ(httpRequest(port_, "/vendor/draco/draco_decoder.wasm").body.substr(0, 4), std::string("\0asm", 4));
}

// A browser that accepts gzip gets the compressed bytes (they inflate to the file), and a reload with the ETag
// it has gets 304 and no body.
TEST_F(ViewServerTest, AssetsAreGzippedForBrowsersAndRevalidatedByEtag) {
    const auto plain = httpRequest(port_, "/vendor/three.core.js");
    const auto packed = httpRequest(port_, "/vendor/three.core.js", "GET", "Accept-Encoding: gzip, deflate, br\r\n");
    ASSERT_EQ(packed.status, 200);
    EXPECT_EQ(packed.header("Content-Encoding"), "gzip");
    EXPECT_EQ(plain.header("Content-Encoding"), "");
    EXPECT_LT(packed.body.size() * 3, plain.body.size()) << "gzip should shrink three.js at least 3x";
    std::string inflated(plain.body.size() + 16, '\0');
    z_stream z{};
    ASSERT_EQ(inflateInit2(&z, 15 + 16), Z_OK);
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(packed.body.data()));
    z.avail_in = static_cast<uInt>(packed.body.size());
    z.next_out = reinterpret_cast<Bytef*>(inflated.data());
    z.avail_out = static_cast<uInt>(inflated.size());
    EXPECT_EQ(inflate(&z, Z_FINISH), Z_STREAM_END);
    inflated.resize(z.total_out);
    inflateEnd(&z);
    EXPECT_EQ(inflated, plain.body);

    const std::string etag = plain.header("ETag");
    ASSERT_FALSE(etag.empty());
    const auto again = httpRequest(port_, "/vendor/three.core.js", "GET", "If-None-Match: " + etag + "\r\n");
    EXPECT_EQ(again.status, 304);
    EXPECT_TRUE(again.body.empty());
    EXPECT_EQ(httpRequest(port_, "/vendor/three.core.js", "GET", "If-None-Match: \"stale\"\r\n").status, 200);
}

TEST_F(ViewServerTest, SessionsAndStatusAsJson) {
    const auto list = httpRequest(port_, "/api/sessions");
    ASSERT_EQ(list.status, 200);
    EXPECT_EQ(list.header("Content-Type"), "application/json");
    EXPECT_TRUE(contains(list.body, "\"type\":\"sessions\"")) << list.body;
    EXPECT_TRUE(contains(list.body, "\"session\":\"scan-1\"")) << list.body;
    const auto one = httpRequest(port_, "/api/sessions/scan-1");
    ASSERT_EQ(one.status, 200);
    EXPECT_TRUE(contains(one.body, "\"state\":\"SCANNING\"")) << one.body;
    EXPECT_TRUE(contains(one.body, "\"detail\":\"turn back toward the camera\"")) << one.body;
    EXPECT_TRUE(contains(one.body, "\"server\":\"server-a\"")) << one.body;
    EXPECT_TRUE(contains(one.body, "\"alive\":true")) << one.body;
}

TEST_F(ViewServerTest, SnapshotBytesAreTheDracoBytesAsReceived) {
    EXPECT_EQ(httpRequest(port_, "/api/sessions/scan-1/snapshot.drc").status, 404);  // none yet
    const MeshSnapshotData snap = snapshotOf("scan-1", 4);
    hub_->putSnapshot(frameSnapshot(snap));
    const auto r = httpRequest(port_, "/api/sessions/scan-1/snapshot.drc");
    ASSERT_EQ(r.status, 200);
    EXPECT_EQ(r.body, std::string(snap.draco.begin(), snap.draco.end()));
    EXPECT_EQ(r.header("X-Facescan-Seq"), "4");
    EXPECT_NEAR(std::stod(r.header("X-Facescan-Created-Ms")), snap.created_ns / 1e6, 1e-3);
}

TEST_F(ViewServerTest, DownloadsEveryFormatAsAnAttachment) {
    for (const char* ext : {"ply", "obj", "stl", "off", "drc", "glb"}) {
        SCOPED_TRACE(ext);
        const auto r = httpRequest(port_, std::string("/api/sessions/scan-1/mesh.") + ext);
        ASSERT_EQ(r.status, 200) << r.body;
        EXPECT_EQ(r.header("Content-Disposition"), std::string("attachment; filename=\"scan-1.") + ext + "\"");
        EXPECT_GT(r.body.size(), 100u);
    }
    const auto glb = httpRequest(port_, "/api/sessions/scan-1/mesh.glb");
    EXPECT_EQ(glb.header("Content-Type"), "model/gltf-binary");
    tinygltf::Model model;
    std::string err;
    ASSERT_TRUE(readGlb(glb.body, model, err)) << err;
    ASSERT_EQ(model.meshes.size(), 1u);
    EXPECT_EQ(model.accessors[model.meshes[0].primitives[0].attributes.at("POSITION")].count, 144u);
    EXPECT_TRUE(model.meshes[0].primitives[0].attributes.count("COLOR_0"));
}

TEST_F(ViewServerTest, AFinishedModelsTextureForThePageAndInTheGlb) {
    // The page's textured model: header, the PNG, then the Draco bytes with texture coordinates.
    const FetchedMesh expected = texturedPatch();
    const auto r = httpRequest(port_, "/api/sessions/finished-1/textured");
    ASSERT_EQ(r.status, 200) << r.body;
    ASSERT_GT(r.body.size(), 4u);
    uint32_t header_length = 0;
    for (int i = 0; i < 4; ++i) header_length |= uint32_t(uint8_t(r.body[i])) << (8 * i);
    ASSERT_LT(4 + header_length, r.body.size());
    const std::string header = r.body.substr(4, header_length);
    EXPECT_EQ(header, "{\"texture_bytes\": " + std::to_string(expected.texture_png.size()) + "}");
    const std::string png = r.body.substr(4 + header_length, expected.texture_png.size());
    EXPECT_EQ(png, std::string(expected.texture_png.begin(), expected.texture_png.end()));
    const std::string drc = r.body.substr(4 + header_length + expected.texture_png.size());
    recon::IndexedMesh mesh;
    std::vector<Eigen::Vector2f> uv;
    ASSERT_TRUE(wire::decodeMeshDraco(reinterpret_cast<const uint8_t*>(drc.data()), drc.size(), mesh, uv).isOk());
    EXPECT_EQ(uv.size(), 144u);
    // A model without a texture (still scanning, or no colour): 404 with the reason.
    const auto none = httpRequest(port_, "/api/sessions/scan-1/textured");
    EXPECT_EQ(none.status, 404);
    EXPECT_TRUE(contains(none.body, "has no texture")) << none.body;

    // The GLB download holds the texture; the other formats keep the vertex colours.
    const auto glb = httpRequest(port_, "/api/sessions/finished-1/mesh.glb");
    ASSERT_EQ(glb.status, 200) << glb.body;
    tinygltf::Model model;
    std::string err;
    ASSERT_TRUE(readGlb(glb.body, model, err)) << err;
    ASSERT_EQ(model.meshes.size(), 1u);
    EXPECT_TRUE(model.meshes[0].primitives[0].attributes.count("TEXCOORD_0"));
    ASSERT_EQ(model.images.size(), 1u);
    ASSERT_GE(model.images[0].bufferView, 0);
    const tinygltf::BufferView& iv = model.bufferViews[static_cast<size_t>(model.images[0].bufferView)];
    const std::vector<uint8_t> atlas(model.buffers[0].data.begin() + static_cast<long>(iv.byteOffset),
                                     model.buffers[0].data.begin() + static_cast<long>(iv.byteOffset + iv.byteLength));
    EXPECT_EQ(cv::imdecode(atlas, cv::IMREAD_COLOR).size(), cv::Size(32, 16));
    const auto ply = httpRequest(port_, "/api/sessions/finished-1/mesh.ply");
    ASSERT_EQ(ply.status, 200);
    EXPECT_FALSE(contains(ply.body, "TextureFile"));
}

TEST_F(ViewServerTest, UnknownSessionsAre404WithAMessage) {
    for (const char* path :
         {"/api/sessions/nobody", "/api/sessions/nobody/snapshot.drc", "/api/sessions/nobody/mesh.glb"}) {
        SCOPED_TRACE(path);
        const auto r = httpRequest(port_, path);
        EXPECT_EQ(r.status, 404);
        EXPECT_EQ(r.header("Content-Type"), "application/json");
        EXPECT_TRUE(contains(r.body, "{\"error\":\"unknown session 'nobody'\"}")) << r.body;
    }
    EXPECT_EQ(httpRequest(port_, "/no/such/page").status, 404);
    EXPECT_EQ(httpRequest(port_, "/api/sessions/scan-1/nothing").status, 404);
    const auto offline = httpRequest(port_, "/api/sessions/offline/mesh.ply");
    EXPECT_EQ(offline.status, 503);
    EXPECT_TRUE(contains(offline.body, "no server answered")) << offline.body;
}

TEST_F(ViewServerTest, MalformedRequestsAre400AndCrashNothing) {
    const int fetches_before = fetches_.load();
    const auto bad_id = httpRequest(port_, "/api/sessions/bad%20id!");
    EXPECT_EQ(bad_id.status, 400);
    EXPECT_TRUE(contains(bad_id.body, "bad session id")) << bad_id.body;
    const auto bad_format = httpRequest(port_, "/api/sessions/scan-1/mesh.exe");
    EXPECT_EQ(bad_format.status, 400);
    EXPECT_TRUE(contains(bad_format.body, "unknown mesh format")) << bad_format.body;
    EXPECT_EQ(fetches_.load(), fetches_before) << "a malformed request must not reach the servers";
    const auto post = httpRequest(port_, "/api/sessions", "POST", "Content-Length: 0\r\n");
    EXPECT_EQ(post.status, 405);
    EXPECT_EQ(post.header("Allow"), "GET, HEAD");
    // Attempts to leave the asset list: nothing but the listed files is ever served.
    for (const char* path : {"/../../etc/passwd", "/vendor/../../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd",
                             "/node_modules/three/package.json", "/vendor/three/package.json"}) {
        const auto r = httpRequest(port_, path);
        EXPECT_TRUE(r.status == 404 || r.status == 400) << path << " -> " << r.status;
        EXPECT_FALSE(contains(r.body, "root:")) << path;
    }
    // Bytes that are not HTTP: CivetWeb answers 400 (or closes), and the server goes on serving.
    const std::string garbage = facescan::testing::rawExchange(port_, "\x16\x03\x01garbage\r\n\r\n");
    EXPECT_TRUE(garbage.empty() || contains(garbage, " 400 ")) << garbage;
    EXPECT_TRUE(contains(facescan::testing::rawExchange(
                             port_, "GET / HTTP/1.1\r\nHost: x\r\nX: " + std::string(100000, 'a') + "\r\n\r\n"),
                         " 4"));
    EXPECT_EQ(httpRequest(port_, "/api/sessions").status, 200);
}

TEST_F(ViewServerTest, WebSocketSendsSessionsThenFollowedSnapshotsNewestFirst) {
    hub_->putSnapshot(frameSnapshot(snapshotOf("ws-1", 1)));
    WsClient ws(port_);
    ASSERT_TRUE(ws.connected()) << ws.error();
    ASSERT_TRUE(ws.waitFor([](const auto& m) { return !m.empty(); }, 5s));
    EXPECT_FALSE(ws.messages()[0].binary);
    EXPECT_TRUE(contains(ws.messages()[0].data, "\"session\":\"scan-1\""));

    ASSERT_TRUE(ws.send("follow ws-1"));
    auto binaries = [](const auto& m) { return std::count_if(m.begin(), m.end(), [](auto& x) { return x.binary; }); };
    ASSERT_TRUE(ws.waitFor([&](const auto& m) { return binaries(m) >= 1; }, 5s));
    const MeshSnapshotData second = snapshotOf("ws-1", 2);
    hub_->putSnapshot(frameSnapshot(second));
    hub_->putSnapshot(frameSnapshot(snapshotOf("ws-1", 1)));  // a late, older sample: ignored
    ASSERT_TRUE(ws.waitFor([&](const auto& m) { return binaries(m) >= 2; }, 5s));

    // The frame: [u32 header length][JSON header][Draco bytes as received].
    std::string last;
    for (const auto& m : ws.messages()) {
        if (m.binary) last = m.data;
    }
    ASSERT_GT(last.size(), 4u);
    const uint32_t header_bytes =
        uint8_t(last[0]) | uint8_t(last[1]) << 8 | uint8_t(last[2]) << 16 | uint8_t(last[3]) << 24;
    const std::string header = last.substr(4, header_bytes);
    EXPECT_TRUE(contains(header, "\"session\":\"ws-1\",\"seq\":2,")) << header;
    EXPECT_TRUE(contains(header, "\"created_ms\":1700000000002.000000")) << header;
    EXPECT_EQ(last.substr(4 + header_bytes), std::string(second.draco.begin(), second.draco.end()));
    std::this_thread::sleep_for(200ms);
    EXPECT_EQ(binaries(ws.messages()), 2) << "the older sample must not be sent";

    // Status changes reach the browser; bad messages get an error, and the connection lives on.
    hub_->updateStatuses({{"ws-1", statusOf("ws-1", facescan_wire_STATE_LOST)}});
    ASSERT_TRUE(ws.waitFor([](const auto& m) { return contains(m.back().data, "\"state\":\"LOST\""); }, 5s));
    ASSERT_TRUE(ws.send("follow ../etc"));
    ASSERT_TRUE(ws.waitFor([](const auto& m) { return contains(m.back().data, "bad session id"); }, 5s));
    ASSERT_TRUE(ws.send("gimme"));
    ASSERT_TRUE(ws.waitFor([](const auto& m) { return contains(m.back().data, "unknown message"); }, 5s));
    EXPECT_EQ(server_->browsers(), 1);
}

TEST_F(ViewServerTest, TenBrowsersGetEverySnapshotFromOneFrame) {
    std::vector<std::unique_ptr<WsClient>> browsers;
    for (int i = 0; i < 10; ++i) {
        browsers.push_back(std::make_unique<WsClient>(port_));
        ASSERT_TRUE(browsers.back()->connected());
        ASSERT_TRUE(browsers.back()->send("follow ten-1"));
    }
    ASSERT_TRUE(facescan::testing::pollUntilTrue([&] { return server_->browsers() >= 10; }, 5s));
    const auto framed = frameSnapshot(snapshotOf("ten-1", 7));
    hub_->putSnapshot(framed);
    for (auto& b : browsers) {
        ASSERT_TRUE(b->waitFor(
            [&](const auto& m) { return !m.empty() && m.back().binary && m.back().data == framed->message; }, 10s));
    }
    // Each client's close waits for its reader thread (CivetWeb's 2 s poll): close them side by side.
    std::vector<std::thread> closers;
    for (auto& b : browsers) closers.emplace_back([client = std::move(b)]() mutable { client.reset(); });
    for (auto& t : closers) t.join();
}

TEST_F(ViewServerTest, ForeignOriginIsRefused) {
    WsClient foreign(port_, "http://evil.example");
    EXPECT_FALSE(foreign.connected()) << "a page of another site must not open the viewer's WebSocket";
    WsClient other_port(port_, "http://127.0.0.1:1");
    EXPECT_FALSE(other_port.connected());
    // CivetWeb's client sends `Host: 127.0.0.1` (no port): the origin of a page on that host. Browsers send the port.
    WsClient ok(port_, "http://127.0.0.1");
    ASSERT_TRUE(ok.connected()) << ok.error();
}

TEST(ViewServerStopTest, StopClosesBrowsersAndStopsListening) {
    auto root = findWebRoot();
    if (!root.isOk()) GTEST_SKIP() << root.status().message();
    ViewHub hub;
    ViewServerConfig config;
    config.port = 0;
    config.web_root = *root;
    auto started = ViewServer::start(config, hub, nullptr);
    ASSERT_TRUE(started.isOk()) << started.status().toString();
    std::unique_ptr<ViewServer> server = std::move(started).value();
    const uint16_t port = server->port();

    WsClient ok(port, "http://127.0.0.1");
    ASSERT_TRUE(ok.connected()) << ok.error();
    ASSERT_TRUE(ok.waitFor([](const auto& m) { return !m.empty(); }, 5s));

    const auto t0 = std::chrono::steady_clock::now();
    server->stop();
    const double stop_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_TRUE(ok.waitClosed(5s));
    EXPECT_LT(stop_ms, 3000) << "stop with a browser connected";
    EXPECT_EQ(httpRequest(port, "/").status, 0) << "nothing listens after stop";
}

TEST(ViewServerConfigTest, BindNeedsAnAddressAndAMissingAssetFolderSaysWhatToRun) {
    ViewServerConfig config;
    EXPECT_TRUE(config.validate().isOk());
    config.bind = "my-laptop";
    EXPECT_EQ(config.validate().code(), StatusCode::kInvalidArgument);
    config.bind = "::1";
    EXPECT_TRUE(config.validate().isOk());
    const Status missing = checkWebRoot("/nonexistent");
    EXPECT_EQ(missing.code(), StatusCode::kNotFound);
    EXPECT_TRUE(contains(missing.message(), "deploy/install-deps.sh")) << missing.message();
}

TEST_F(ViewServerTest, APortInUseIsAnErrorNamingIt) {
    ViewHub hub;
    ViewServerConfig config = *config_;
    config.port = port_;
    auto second = ViewServer::start(config, hub, nullptr);
    ASSERT_FALSE(second.isOk());
    EXPECT_EQ(second.status().code(), StatusCode::kUnavailable);
    EXPECT_TRUE(contains(second.status().message(), "127.0.0.1:" + std::to_string(config.port)))
        << second.status().message();
}

}  // namespace
}  // namespace facescan::client
