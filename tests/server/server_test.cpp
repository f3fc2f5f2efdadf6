// facescan-server's service over real Cyclone DDS (loopback profile, a private domain per test): a test agent
// publishes synthetic Kinect frames through the wire layer, a test client sends commands and reads status,
// snapshots and replies. No mocks: the server runs the real detection, segmentation and recon core.
#include "service/server.hpp"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <sstream>
#include <thread>

#include "recon/indexed_mesh.hpp"
#include "scratch_dir.hpp"
#include "server_rig.hpp"
#include "server_session_fixtures.hpp"
#include "service/frame_load.hpp"
#include "test_agent.hpp"
#include "wire/audit_log.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::service {
namespace {

using namespace std::chrono_literals;
using testing::EncodedSequence;
using testing::privateDomain;
using testing::StatusCopy;
using testing::TestAgent;
using testing::TestClient;

std::string readFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// frames.tsv of a finished session: how many of its frames had each outcome (F, T, R, D), after checking that every
// line has six fields, that seqs rise and that the times are plausible.
std::map<char, uint32_t> frameOutcomes(const std::filesystem::path& dir) {
    std::map<char, uint32_t> n;
    std::istringstream in(readFile(dir / "frames.tsv"));
    std::string line;
    long last_seq = -1;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#') continue;
        std::istringstream fields(line);
        long seq = 0;
        float queued_ms = 0, processing_ms = 0, cpu_ms = 0;
        int step = -1;
        char outcome = 0;
        EXPECT_TRUE(fields >> seq >> queued_ms >> processing_ms >> cpu_ms >> step >> outcome) << line;
        EXPECT_GT(seq, last_seq) << line;
        EXPECT_GE(queued_ms, -1.0f) << line;  // the agent's clock is this machine's here
        EXPECT_GE(processing_ms, 0.0f) << line;
        EXPECT_GE(cpu_ms, 0.0f) << line;
        if (outcome == 'F') {
            EXPECT_GT(cpu_ms, 0.1f) << "a fused frame costs something: " << line;
        }
        EXPECT_TRUE(step >= 0 && step < FrameLoad::kEconomySteps) << line;
        last_seq = seq;
        ++n[outcome];
    }
    return n;
}

// The data dir of a finished session: every file complete, nothing temporary left behind.
void expectSessionWritten(const std::filesystem::path& dir, bool with_mesh) {
    ASSERT_TRUE(std::filesystem::exists(dir / "summary.json")) << dir;
    const std::string summary = readFile(dir / "summary.json");
    EXPECT_NE(summary.find("\"state\": \"finished\""), std::string::npos) << summary;
    EXPECT_NE(summary.find("\"integrated\": "), std::string::npos);
    EXPECT_EQ(summary.back(), '\n');
    EXPECT_TRUE(std::filesystem::exists(dir / "trajectory.txt"));
    EXPECT_TRUE(std::filesystem::exists(dir / "frames.tsv"));
    // A face is personal data: the folder and every file in it are the owner's only, whatever the test's umask.
    const auto mode = [](const std::filesystem::path& p) {
        struct stat st {};
        return ::stat(p.c_str(), &st) == 0 ? st.st_mode & 07777 : 0u;
    };
    EXPECT_EQ(mode(dir), 0700u) << dir;
    EXPECT_EQ(mode(dir.parent_path()), 0700u) << "the data dir " << dir.parent_path();
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
        EXPECT_EQ(entry.path().extension(), entry.path().extension() == ".tmp" ? ".none" : entry.path().extension())
            << "temporary file left: " << entry.path();
        if (entry.is_regular_file()) {
            EXPECT_EQ(mode(entry.path()), 0600u) << entry.path();
        }
    }
    if (!with_mesh) return;
    recon::Mesh ply;
    OpenMesh::IO::Options opts = OpenMesh::IO::Options::VertexColor | OpenMesh::IO::Options::VertexNormal;
    ply.request_vertex_colors();
    ASSERT_TRUE(OpenMesh::IO::read_mesh(ply, (dir / "mesh.ply").string(), opts));
    EXPECT_GT(ply.n_faces(), 1000u);
    EXPECT_TRUE(opts.check(OpenMesh::IO::Options::VertexColor));
    const std::string drc = readFile(dir / "mesh.drc");
    auto decoded = wire::decodeMeshDraco(reinterpret_cast<const uint8_t*>(drc.data()), drc.size());
    ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
    EXPECT_EQ(decoded->n_faces(), ply.n_faces());
    // mesh.ply is the mesh the Draco bytes hold (cleaned on Draco's grid), so it is clean too.
    EXPECT_TRUE(recon::countDefects(recon::fromOpenMesh(ply)).clean());
}

// Each of this process's threads by name (/proc/self/task/TID/comm), with its nice value (field 19 of its stat).
std::map<std::string, int> threadNices() {
    std::map<std::string, int> nices;
    for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
        std::string name = readFile(task.path() / "comm");
        if (!name.empty() && name.back() == '\n') name.pop_back();
        const std::string stat = readFile(task.path() / "stat");
        const size_t close = stat.rfind(')');  // the name in parentheses may hold spaces
        if (close == std::string::npos) continue;
        std::istringstream rest(stat.substr(close + 1));
        std::string field;
        for (int i = 3; i <= 19 && rest >> field; ++i) {
            if (i == 19) nices[name] = std::stoi(field);
        }
    }
    return nices;
}

TEST(ServerSession, LiveSessionIntegratesAndAnswersCommandsWithTheirRequestIds) {
    const uint32_t domain = privateDomain(11);
    const ServerParams params = testParams(domain, "live");
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto agent = makeAgent(domain, "live-1", /*every_frame=*/false);
    ASSERT_TRUE(agent);
    ASSERT_TRUE(agent->stream(sequence(), 45, 30.0f, /*end_of_stream=*/false).isOk());

    auto status = rig.client->waitForStatus(
        "live-1", [](const StatusCopy& s) { return s.frames_received == 45 && settled(s); }, 20s);
    ASSERT_TRUE(status) << "status never settled";
    EXPECT_FALSE(status->every_frame);
    // Throughput depends on the machine (live mode skips what it cannot process); correctness does not.
    EXPECT_GE(status->frames_integrated, 10u) << status->detail << "; rejected " << status->frames_rejected
                                              << ", skipped " << status->frames_skipped << ", fps " << status->fps;
    EXPECT_EQ(status->frames_dropped, 0u);
    EXPECT_GT(status->latency_p95_ms, 0.0f);
    // top -H says which thread serves what: the session's worker carries its id (cut to the kernel's 15
    // characters), and the server's own threads their job.
    const std::map<std::string, int> nices = threadNices();
    for (const char* name : {"fs-s live-1", "fs-intake", "fs-command", "fs-snapshot", "fs-status", "fs-replicate"}) {
        EXPECT_EQ(nices.count(name), 1u) << "no thread named '" << name << "'";
    }
    // Work that can wait (snapshots, replication) yields the cores to the sessions' frames.
    if (nices.count("fs-s live-1")) {
        const int worker = nices.at("fs-s live-1");
        for (const char* name : {"fs-snapshot", "fs-replicate"}) {
            if (nices.count(name)) {
                EXPECT_EQ(nices.at(name), worker + kBackgroundNice) << name;
            }
        }
    }

    auto snapshot = rig.client->waitForSnapshot("live-1", 5s);
    ASSERT_TRUE(snapshot) << "no MeshSnapshot";
    auto snap_mesh = wire::decodeMeshDraco(snapshot->draco.data(), snapshot->draco.size());
    ASSERT_TRUE(snap_mesh.isOk()) << snap_mesh.status().toString();
    EXPECT_EQ(snap_mesh->n_faces(), snapshot->triangle_count);
    // A live snapshot, as a client decodes it, is clean.
    auto snap_arrays = wire::decodeIndexedMesh(snapshot->draco.data(), snapshot->draco.size());
    ASSERT_TRUE(snap_arrays.isOk());
    EXPECT_TRUE(recon::countDefects(*snap_arrays).clean());

    auto traj = rig.client->command("live-1", facescan_wire_CMD_GET_TRAJECTORY);
    ASSERT_TRUE(traj.isOk()) << traj.status().toString();
    EXPECT_TRUE(traj->ok) << traj->error;
    EXPECT_EQ(traj->server_id, "test-server");
    EXPECT_EQ(traj->kind, static_cast<uint32_t>(facescan_wire_CMD_GET_TRAJECTORY));
    const std::string tum(traj->payload.begin(), traj->payload.end());
    EXPECT_EQ(static_cast<uint32_t>(std::count(tum.begin(), tum.end(), '\n')),
              status->frames_integrated + status->frames_tracked_only)
        << "a pose for every tracked frame, fused or not";

    auto mesh = rig.client->command("live-1", facescan_wire_CMD_GET_MESH);
    ASSERT_TRUE(mesh.isOk() && mesh->ok) << (mesh.isOk() ? mesh->error : mesh.status().toString());
    auto decoded = wire::decodeMeshDraco(mesh->payload.data(), mesh->payload.size());
    ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
    EXPECT_GT(decoded->n_faces(), 1000u);
    EXPECT_EQ(decoded->n_faces(), mesh->triangle_count);
    auto mesh_arrays = wire::decodeIndexedMesh(mesh->payload.data(), mesh->payload.size());
    ASSERT_TRUE(mesh_arrays.isOk());
    EXPECT_TRUE(recon::countDefects(*mesh_arrays).clean());
    // The full-resolution mesh has more detail than the coarse snapshot.
    EXPECT_GT(decoded->n_faces(), snap_mesh->n_faces());

    auto preview = rig.client->command("live-1", facescan_wire_CMD_GET_PREVIEW);
    ASSERT_TRUE(preview.isOk() && preview->ok);
    ASSERT_GT(preview->payload.size(), 8u);
    EXPECT_EQ(preview->payload[1], 'P');  // \x89PNG

    auto finish = rig.client->command("live-1", facescan_wire_CMD_FINISH);
    ASSERT_TRUE(finish.isOk() && finish->ok) << (finish.isOk() ? finish->error : finish.status().toString());
    EXPECT_EQ(finish->triangle_count, mesh->triangle_count);  // nothing integrated since GET_MESH
    expectSessionWritten(params.data_dir / "live-1", /*with_mesh=*/true);
    // Finished sessions stay answerable.
    auto again = rig.client->command("live-1", facescan_wire_CMD_GET_MESH);
    ASSERT_TRUE(again.isOk() && again->ok);
    EXPECT_EQ(again->triangle_count, finish->triangle_count);
    auto final_status = rig.client->waitForStatus(
        "live-1", [](const StatusCopy& s) { return s.state == facescan_wire_STATE_FINISHED; }, 5s);
    EXPECT_TRUE(final_status);
    // The audit trail: every command above, in order, with the client that sent it and the outcome.
    auto audit = wire::readAuditLog(params.data_dir / "audit.log");
    ASSERT_TRUE(audit.isOk()) << audit.status().toString();
    std::vector<std::string> actions;
    for (const wire::AuditRecord& r : *audit) {
        actions.push_back(r.action);
        EXPECT_EQ(r.session, "live-1");
        EXPECT_EQ(r.identity, "client server_test");
        EXPECT_EQ(r.outcome, "ok");
        EXPECT_EQ(r.recorder, "server test-server");
        EXPECT_GT(r.time_ns, 1'700'000'000'000'000'000);
    }
    EXPECT_EQ(actions, (std::vector<std::string>{"get_trajectory", "get_mesh", "get_preview", "finish", "get_mesh"}));
    struct stat st {};
    ASSERT_EQ(::stat((params.data_dir / "audit.log").c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777, 0600u);
}

TEST(ServerSession, UnknownSessionsAndBadRequestsGetErrorReplies) {
    const uint32_t domain = privateDomain(12);
    const ServerParams params = testParams(domain, "errors");
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto unknown = rig.client->command("nobody", facescan_wire_CMD_GET_MESH, 5s);
    ASSERT_TRUE(unknown.isOk()) << "silence instead of an error reply";
    EXPECT_FALSE(unknown->ok);
    EXPECT_EQ(unknown->error, "unknown session 'nobody'");
    auto audit = wire::readAuditLog(params.data_dir / "audit.log");
    ASSERT_TRUE(audit.isOk()) << audit.status().toString();
    ASSERT_FALSE(audit->empty());
    EXPECT_EQ(audit->front().action, "get_mesh");
    EXPECT_EQ(audit->front().session, "nobody");
    EXPECT_EQ(audit->front().outcome, "error: unknown session 'nobody'") << "refusals are recorded too";
    // An enum value outside CommandKind cannot even be serialised by DDS; an empty request id can be sent.
    const std::string empty;
    auto bad = rig.client->command("nobody", facescan_wire_CMD_GET_STATUS, 5s, &empty);
    ASSERT_TRUE(bad.isOk()) << "silence instead of an error reply";
    EXPECT_FALSE(bad->ok);
    EXPECT_NE(bad->error.find("bad request"), std::string::npos) << bad->error;
}

TEST(ServerSession, EveryFrameRecordingProcessesAllFramesAndFinishesAtEndOfStream) {
    const uint32_t domain = privateDomain(13);
    ServerParams params = testParams(domain, "every");
    params.queue_frames = 4;  // a small queue: the agent is back-pressured most of the time
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto agent = makeAgent(domain, "rec-1", /*every_frame=*/true);
    ASSERT_TRUE(agent);
    // Damaged frames in the middle: garbage bytes, then a valid payload of the wrong image size.
    const EncodedSequence& seq = sequence();
    std::vector<uint8_t> garbage(5000);
    for (size_t i = 0; i < garbage.size(); ++i) garbage[i] = static_cast<uint8_t>(i * 131 + 7);
    wire::EncodedFrame small;
    ASSERT_TRUE(wire::FrameEncoder().encode(cv::Mat(240, 320, CV_16UC1, cv::Scalar(700)), cv::Mat(), small).isOk());
    constexpr uint32_t kFrames = 40;
    for (uint32_t i = 0; i < kFrames; ++i) {
        Status s = i == 15   ? agent->sendRawDepth(i, garbage)
                   : i == 16 ? agent->sendRawDepth(i, small.depth)
                             : agent->sendFrame(i, seq.frames[i]);
        ASSERT_TRUE(s.isOk()) << s.toString();  // blocks while the server's queue is full (back-pressure)
    }
    ASSERT_TRUE(agent->sendEndOfStream(kFrames).isOk());

    auto status = rig.client->waitForStatus(
        "rec-1", [](const StatusCopy& s) { return s.state == facescan_wire_STATE_FINISHED; }, 30s);
    ASSERT_TRUE(status) << "the recording never finished";
    EXPECT_TRUE(status->every_frame);
    EXPECT_EQ(status->frames_received, kFrames);
    EXPECT_EQ(status->frames_skipped, 0u);
    EXPECT_EQ(status->frames_dropped, 2u) << "both damaged frames are counted";
    EXPECT_EQ(status->frames_integrated + status->frames_rejected, kFrames - 2);
    EXPECT_GE(status->frames_integrated, 30u) << "the damaged frames must not harm the session: " << status->detail;
    expectSessionWritten(params.data_dir / "rec-1", /*with_mesh=*/true);
    auto outcomes = frameOutcomes(params.data_dir / "rec-1");
    EXPECT_EQ(outcomes['D'], 2u) << "frames.tsv has the damaged frames too";
    EXPECT_EQ(outcomes['F'], status->frames_integrated);
    EXPECT_EQ(outcomes['R'], status->frames_rejected);
    EXPECT_NE(readFile(params.data_dir / "rec-1" / "summary.json").find("\"mode\": \"every_frame\""),
              std::string::npos);
}

// --max-triangles 2000 --close holes: mesh.ply holds the finished model, with colours, and summary.json says what
// finishing did and how far the result lies from the full mesh.
TEST(ServerSession, FinishDeliversTheFinishedModelWithinItsBudget) {
    const uint32_t domain = privateDomain(21);
    ServerParams params = testParams(domain, "budget");
    params.finish.max_triangles = 2000;
    params.finish.close = recon::ClosingMode::kHoles;
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto agent = makeAgent(domain, "budget-1", /*every_frame=*/true);
    ASSERT_TRUE(agent);
    constexpr uint32_t kFrames = 30;
    for (uint32_t i = 0; i < kFrames; ++i) ASSERT_TRUE(agent->sendFrame(i, sequence().frames[i]).isOk());
    ASSERT_TRUE(agent->sendEndOfStream(kFrames).isOk());
    auto status = rig.client->waitForStatus(
        "budget-1", [](const StatusCopy& s) { return s.state == facescan_wire_STATE_FINISHED; }, 30s);
    ASSERT_TRUE(status) << "the recording never finished";
    const std::filesystem::path dir = params.data_dir / "budget-1";
    recon::Mesh ply;
    OpenMesh::IO::Options opts = OpenMesh::IO::Options::VertexColor;
    ply.request_vertex_colors();
    ASSERT_TRUE(OpenMesh::IO::read_mesh(ply, (dir / "mesh.ply").string(), opts));
    EXPECT_LE(ply.n_faces(), 2000u);
    EXPECT_GT(ply.n_faces(), 1500u);
    EXPECT_TRUE(opts.check(OpenMesh::IO::Options::VertexColor));
    const std::string summary = readFile(dir / "summary.json");
    EXPECT_NE(summary.find("\"finish\": {\"triangles_in\": "), std::string::npos) << summary;
    EXPECT_NE(summary.find("\"budget_reached\": true"), std::string::npos) << summary;
    // 2,000 triangles of this 62k-triangle face lie 0.15 mm from it; a starved face (a fan from a locked rim): 6 mm.
    std::smatch mean;
    ASSERT_TRUE(std::regex_search(summary, mean, std::regex(R"("distance_mm": \{"mean": ([0-9.e+-]+))"))) << summary;
    EXPECT_LT(std::stod(mean[1].str()), 0.5) << summary;

    // The texture, baked from the colour keyframes kept during the scan: OBJ + MTL + PNG and a PLY with texture
    // coordinates, of the same finished model; summary.json says how it was made.
    EXPECT_NE(summary.find("\"texture\": {\"width\": "), std::string::npos) << summary;
    std::smatch used;
    ASSERT_TRUE(std::regex_search(summary, used, std::regex(R"("views_used": ([0-9]+))"))) << summary;
    EXPECT_GE(std::stoi(used[1].str()), 2) << "the head turns: more than one keyframe paints it; " << summary;
    EXPECT_NE(readFile(dir / "textured.mtl").find("map_Kd textured.png"), std::string::npos);
    EXPECT_NE(readFile(dir / "textured.obj").find("mtllib textured.mtl"), std::string::npos);
    const cv::Mat atlas = cv::imread((dir / "textured.png").string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(atlas.empty());
    EXPECT_GT(cv::mean(atlas)[2], 20.0) << "a skin-coloured face is not black";
    OpenMesh::TriMesh_ArrayKernelT<> textured;
    textured.request_vertex_texcoords2D();
    OpenMesh::IO::Options uv_opts = OpenMesh::IO::Options::VertexTexCoord;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(textured, (dir / "textured.ply").string(), uv_opts));
    EXPECT_TRUE(uv_opts.vertex_has_texcoord());
    // The same finished model (both are after Draco's grid; OpenMesh's reader may leave out a non-manifold triangle
    // of mesh.ply that the texture's cuts made manifold in textured.ply).
    EXPECT_NEAR(double(textured.n_faces()), double(ply.n_faces()), 0.02 * double(ply.n_faces()));
}

// A server told to fuse every other tracked frame (--set fuse_every=2, what the load's last economy step does):
// every frame is still tracked and posed, the status and the summary count the ones left out of the model apart
// from the fused ones, and the trajectory has a pose for each tracked frame.
TEST(ServerSession, ASessionThatFusesEveryOtherFramePosesAndCountsEveryTrackedFrame) {
    const uint32_t domain = privateDomain(20);
    ServerParams params = testParams(domain, "fuse2");
    params.recon.fuse_every = 2;
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto agent = makeAgent(domain, "fuse-1", /*every_frame=*/true);
    ASSERT_TRUE(agent);
    constexpr uint32_t kFrames = 30;
    ASSERT_TRUE(agent->stream(sequence(), kFrames, 30.0f, /*end_of_stream=*/true).isOk());
    auto status = rig.client->waitForStatus(
        "fuse-1", [](const StatusCopy& s) { return s.state == facescan_wire_STATE_FINISHED; }, 30s);
    ASSERT_TRUE(status) << "the recording never finished";
    EXPECT_EQ(status->frames_integrated + status->frames_tracked_only + status->frames_rejected, kFrames);
    EXPECT_GE(status->frames_tracked_only, 10u) << status->detail;
    EXPECT_LE(status->frames_tracked_only, status->frames_integrated) << "the first frames are always fused";
    expectSessionWritten(params.data_dir / "fuse-1", /*with_mesh=*/true);
    auto outcomes = frameOutcomes(params.data_dir / "fuse-1");
    EXPECT_EQ(outcomes['F'], status->frames_integrated);
    EXPECT_EQ(outcomes['T'], status->frames_tracked_only);
    EXPECT_EQ(outcomes['R'], status->frames_rejected);
    const std::string tum = readFile(params.data_dir / "fuse-1" / "trajectory.txt");
    EXPECT_EQ(static_cast<uint32_t>(std::count(tum.begin(), tum.end(), '\n')),
              status->frames_integrated + status->frames_tracked_only);
    EXPECT_NE(readFile(params.data_dir / "fuse-1" / "summary.json")
                  .find("\"tracked_only\": " + std::to_string(status->frames_tracked_only) + "}"),
              std::string::npos);
}

// Child process: an agent that streams a few frames and is then killed (no end of stream, no clean exit).
[[noreturn]] void killedAgent(uint32_t domain) {
    const EncodedSequence seq = testing::renderSequence(20);
    auto agent = TestAgent::create(domain, "killed-1", seq.intrinsics, /*every_frame=*/false);
    if (!agent.isOk()) _exit(10);
    if (!(*agent)->waitForServer(20s)) _exit(11);
    if (!(*agent)->sendCamera().isOk()) _exit(12);
    if (!(*agent)->waitForOwner(20s)) _exit(15);
    if (!(*agent)->stream(seq, 20, 30.0f, /*end_of_stream=*/false).isOk()) _exit(13);
    raise(SIGKILL);
    _exit(14);
}

TEST(ServerSession, KilledAgentLeavesTheSessionFinalisable) {
    const uint32_t domain = privateDomain(14);
    const pid_t child = fork();  // before this process starts any DDS threads
    ASSERT_GE(child, 0);
    if (child == 0) killedAgent(domain);
    const ServerParams params = testParams(domain, "killed");
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    int wstatus = 0;
    waitpid(child, &wstatus, 0);
    ASSERT_TRUE(WIFSIGNALED(wstatus) && WTERMSIG(wstatus) == SIGKILL) << "agent exit status " << wstatus;

    auto gone = rig.client->waitForStatus(
        "killed-1", [](const StatusCopy& s) { return s.detail == "agent gone"; }, 15s);
    ASSERT_TRUE(gone) << "the killed agent was never noticed";
    EXPECT_EQ(gone->state, static_cast<uint32_t>(facescan_wire_STATE_WAITING));
    EXPECT_GT(gone->frames_integrated, 0u);
    auto finish = rig.client->command("killed-1", facescan_wire_CMD_FINISH);
    ASSERT_TRUE(finish.isOk() && finish->ok) << (finish.isOk() ? finish->error : finish.status().toString());
    EXPECT_GT(finish->triangle_count, 0u);
    expectSessionWritten(params.data_dir / "killed-1", /*with_mesh=*/true);
}

TEST(ServerSession, ShutdownFinishesOpenSessionsToDisk) {
    const uint32_t domain = privateDomain(16);
    const ServerParams params = testParams(domain, "shutdown");
    Rig rig = makeRig(params);
    ASSERT_TRUE(rig.server && rig.client);
    auto agent = makeAgent(domain, "open-1", false);
    ASSERT_TRUE(agent);
    ASSERT_TRUE(agent->stream(sequence(), 20, 30.0f, /*end_of_stream=*/false).isOk());
    ASSERT_TRUE(rig.client->waitForStatus(
        "open-1", [](const StatusCopy& s) { return s.frames_integrated > 5; }, 10s));
    rig.server->shutdown();  // what Ctrl-C does
    EXPECT_EQ(rig.server->openSessions(), 0);
    expectSessionWritten(params.data_dir / "open-1", /*with_mesh=*/true);
}

}  // namespace
}  // namespace facescan::service
