// The whole product over real DDS, no mocks: facescan-server and facescan-agent (synthetic Kinect filming the
// built-in head) run as child processes on the loopback profile in a private domain; the facescan client watches
// the scan, finishes it, fetches the mesh in every format, the preview and the trajectory; the mesh is measured
// against the subject's ground truth; and the server-side error path (unknown session) gives exit code 1.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <thread>

#include "child_process.hpp"
#include "eval/accuracy.hpp"
#include "recon/indexed_mesh.hpp"
#include "run_command.hpp"
#include "synth/kinect_simulator.hpp"
#include "test_domain.hpp"
#include "wire/mesh_codec.hpp"

namespace {

using namespace facescan;
namespace fs = std::filesystem;
using namespace std::chrono_literals;

using CliRun = facescan::testing::CommandRun;

// The real `facescan` binary with these arguments.
CliRun runCli(const std::string& args) { return facescan::testing::runCommand(std::string(FACESCAN_CLI) + " " + args); }

using facescan::testing::ChildProcess;
using facescan::testing::readText;

bool contains(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

// One test's private DDS domain (and the CLI's flags for it), its session name and an empty scratch folder.
struct Scratch {
    std::string domain, session, dds;
    fs::path dir;
};
Scratch makeScratch(uint32_t salt, const std::string& name) {
    Scratch s;
    s.domain = std::to_string(facescan::testing::privateDomain(salt));
    s.session = name + "-" + std::to_string(::getpid());
    s.dds = " --profile loopback --domain " + s.domain;
    s.dir = fs::temp_directory_path() / ("facescan_" + s.session);
    fs::remove_all(s.dir);
    fs::create_directories(s.dir);
    return s;
}

TEST(EndToEnd, ScanWatchFinishFetchEveryFormatAndMeasure) {
    const auto [domain, session, dds, dir] = makeScratch(5, "e2e");
    constexpr int kFrames = 40;

    ChildProcess server({FACESCAN_SERVER_BIN, "--profile", "loopback", "--domain", domain, "--data-dir",
                         (dir / "data").string(), "--snapshot-hz", "2"},
                        dir / "server.log");
    // A recording (--rate max): every frame is processed, so the result does not depend on the machine's speed.
    ChildProcess agent({FACESCAN_AGENT_BIN, "--profile", "loopback", "--domain", domain, "--session", session,
                        "--source", "synthetic:frames=" + std::to_string(kFrames) + ",subject=builtin,seed=1", "--rate",
                        "max", "--wait-for-server", "30"},
                       dir / "agent.log");

    // watch follows the scan until the server has processed the agent's end of stream.
    const CliRun watch = runCli("watch " + session + " --save " + (dir / "snaps").string() + dds + " --timeout 30");
    ASSERT_EQ(watch.exit_code, 0) << watch.out << "\nserver:\n"
                                  << readText(dir / "server.log") << "\nagent:\n"
                                  << readText(dir / "agent.log");
    EXPECT_TRUE(contains(watch.out, "scan " + session + " finished")) << watch.out;
    EXPECT_TRUE(contains(watch.out, "integrated")) << watch.out;
    EXPECT_EQ(agent.wait(30s), 0) << readText(dir / "agent.log");

    const CliRun sessions = runCli("sessions" + dds);
    EXPECT_EQ(sessions.exit_code, 0) << sessions.out;
    EXPECT_TRUE(contains(sessions.out, session)) << sessions.out;
    EXPECT_TRUE(contains(sessions.out, "FINISHED")) << sessions.out;

    const CliRun status = runCli("status " + session + dds);
    EXPECT_EQ(status.exit_code, 0) << status.out;
    EXPECT_TRUE(contains(status.out, "FINISHED")) << status.out;

    // The vertex-coloured files (--vertex-colours), which must agree with each other and with the Draco bytes;
    // texture_end_to_end_test fetches the textured ones.
    const CliRun ply =
        runCli("mesh " + session + " -o " + (dir / "face.ply").string() + " --finish --vertex-colours" + dds);
    ASSERT_EQ(ply.exit_code, 0) << ply.out << "\nserver:\n" << readText(dir / "server.log");
    recon::Mesh mesh;
    OpenMesh::IO::Options opts = OpenMesh::IO::Options::VertexColor;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(mesh, (dir / "face.ply").string(), opts));
    ASSERT_GT(mesh.n_faces(), 1000u);
    EXPECT_TRUE(opts.check(OpenMesh::IO::Options::VertexColor)) << "the agent sends colour: the mesh has colours";

    // What a client fetches is clean, in every format, after the Draco round trip. Each file is read
    // back by OpenMesh (an independent reader) and checked by position: no zero-area or duplicate triangle, no
    // unreferenced vertex. Non-manifold edges and vertices are reported, not forbidden (a scan's rim can pinch).
    auto expectClean = [](const recon::Mesh& read_back, const std::string& what) {
        const recon::MeshDefects d = recon::countDefects(recon::fromOpenMesh(read_back));
        EXPECT_TRUE(d.clean()) << what << ": " << d.zero_area_triangles << " zero-area triangles, "
                               << d.duplicate_triangles << " duplicate triangles, " << d.unreferenced_vertices
                               << " unreferenced vertices";
        std::printf("%s: %zu triangles; %zu non-manifold edges, %zu non-manifold vertices\n", what.c_str(),
                    read_back.n_faces(), d.non_manifold_edges, d.non_manifold_vertices);
    };
    expectClean(mesh, "face.ply");
    // Every other format: the same vertex and face counts read back through OpenMesh (Draco: the codec).
    for (const char* ext : {"obj", "stl", "off"}) {
        const fs::path path = dir / (std::string("face.") + ext);
        const CliRun run = runCli("mesh " + session + " -o " + path.string() + " --vertex-colours" + dds);
        ASSERT_EQ(run.exit_code, 0) << run.out;
        recon::Mesh back;
        ASSERT_TRUE(OpenMesh::IO::read_mesh(back, path.string())) << ext;
        expectClean(back, path.filename().string());
        EXPECT_EQ(back.n_faces(), mesh.n_faces()) << ext;
        // STL stores corners, not a vertex list: OpenMesh's reader merges equal corners, which joins the copies
        // Draco makes of a non-manifold vertex. Every other format keeps the vertex list exactly.
        if (std::string(ext) == "stl") {
            EXPECT_LE(back.n_vertices(), mesh.n_vertices());
        } else {
            EXPECT_EQ(back.n_vertices(), mesh.n_vertices()) << ext;
        }
    }
    const CliRun drc = runCli("mesh " + session + " -o " + (dir / "face.drc").string() + dds);
    ASSERT_EQ(drc.exit_code, 0) << drc.out;
    const std::string drc_bytes = readText(dir / "face.drc");
    auto decoded = wire::decodeIndexedMesh(reinterpret_cast<const uint8_t*>(drc_bytes.data()), drc_bytes.size());
    ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
    EXPECT_EQ(decoded->vertexCount(), mesh.n_vertices());
    EXPECT_EQ(decoded->triangleCount(), mesh.n_faces());
    EXPECT_TRUE(recon::countDefects(*decoded).clean());

    // Finished here (recon/finishing.hpp): a triangle budget and closed holes, in PLY and in Draco (whose bytes
    // must then be the finished model's, not the server's); clean, coloured, within the budget, and the report
    // says how far the result lies from the full mesh.
    const CliRun small =
        runCli("mesh " + session + " -o " + (dir / "small.ply").string() + " --max-triangles 2000 --close holes" + dds);
    ASSERT_EQ(small.exit_code, 0) << small.out;
    EXPECT_TRUE(contains(small.out, "finished here: ")) << small.out;
    EXPECT_TRUE(contains(small.out, "distance to the full mesh mean ")) << small.out;
    recon::Mesh small_mesh;
    OpenMesh::IO::Options small_opts = OpenMesh::IO::Options::VertexColor;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(small_mesh, (dir / "small.ply").string(), small_opts));
    EXPECT_LE(small_mesh.n_faces(), 2000u);
    EXPECT_GT(small_mesh.n_faces(), 1500u);
    EXPECT_TRUE(small_opts.check(OpenMesh::IO::Options::VertexColor));
    expectClean(small_mesh, "small.ply");
    const CliRun small_drc =
        runCli("mesh " + session + " -o " + (dir / "small.drc").string() + " --max-triangles 2000" + dds);
    ASSERT_EQ(small_drc.exit_code, 0) << small_drc.out;
    const std::string small_bytes = readText(dir / "small.drc");
    auto small_decoded =
        wire::decodeIndexedMesh(reinterpret_cast<const uint8_t*>(small_bytes.data()), small_bytes.size());
    ASSERT_TRUE(small_decoded.isOk()) << small_decoded.status().toString();
    EXPECT_LE(small_decoded->triangleCount(), 2000u);
    const CliRun too_few =
        runCli("mesh " + session + " -o " + (dir / "tiny.ply").string() + " --max-triangles 100" + dds);
    EXPECT_EQ(too_few.exit_code, 2) << too_few.out;
    EXPECT_TRUE(contains(too_few.out, "at least 500")) << too_few.out;

    const CliRun preview = runCli("preview " + session + " -o " + (dir / "preview.png").string() + dds);
    EXPECT_EQ(preview.exit_code, 0) << preview.out;
    EXPECT_TRUE(readText(dir / "preview.png").starts_with("\x89PNG")) << preview.out;

    const CliRun trajectory = runCli("trajectory " + session + " -o " + (dir / "traj.txt").string() + dds);
    EXPECT_EQ(trajectory.exit_code, 0) << trajectory.out;
    int poses = 0;
    std::ifstream traj(dir / "traj.txt");
    for (std::string line; std::getline(traj, line);) {
        if (!line.empty() && line[0] != '#') ++poses;
    }
    EXPECT_GT(poses, kFrames / 2) << readText(dir / "traj.txt");
    EXPECT_LE(poses, kFrames);

    // Snapshots saved by watch --save: at least one, readable.
    int snaps = 0;
    for (const auto& entry : fs::directory_iterator(dir / "snaps")) {
        recon::Mesh snap;
        EXPECT_TRUE(OpenMesh::IO::read_mesh(snap, entry.path().string())) << entry.path();
        expectClean(snap, "snapshot " + entry.path().filename().string());
        ++snaps;
    }
    EXPECT_GE(snaps, 1);

    // The server-side error path: a session nobody owns.
    const CliRun unknown = runCli("status no-such-session" + dds + " --timeout 5");
    EXPECT_EQ(unknown.exit_code, 1) << unknown.out;
    EXPECT_TRUE(contains(unknown.out, "facescan: error: unknown session 'no-such-session'")) << unknown.out;
    const CliRun unknown_mesh = runCli("mesh no-such-session -o " + (dir / "x.ply").string() + dds);
    EXPECT_EQ(unknown_mesh.exit_code, 1) << unknown_mesh.out;
    EXPECT_FALSE(fs::exists(dir / "x.ply"));

    // Accuracy against the ground truth: a loose bound for 40 frames (the real target is measured by the bench).
    const synth::KinectSimulator sim(synth::builtinHead(), [] {
        synth::SequenceParams p;
        p.seed = 1;
        return p;
    }());
    const recon::Mesh& gt = sim.head().mesh;
    auto report = eval::measureAccuracy(mesh, gt, eval::findNoseTip(gt), {}, sim.poseAt(0).inverse());
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    std::printf(
        "end-to-end accuracy (%d frames): mean %.2f mm (unaligned %.2f), median %.2f mm, p90 %.2f mm, "
        "completeness %.2f\n",
        kFrames, report->mean_mm, report->unaligned.mean_mm, report->median_mm, report->p90_mm, report->completeness);
    EXPECT_LT(report->median_mm, 2.0);
    EXPECT_GT(report->completeness, 0.3);

    server.stop();
    fs::remove_all(dir);
}

// Live: the subject walks out of view for a second and comes back turned by 20 deg. The server's status
// tells the person what to do while the face is lost, `facescan watch` shows it the moment the scan is lost, and
// the scan comes back by itself after the gap (re-acquisition), in real time at 30 Hz.
TEST(EndToEnd, WatchShowsTheAdviceWhileTheFaceIsLostAndTheScanComesBack) {
    const auto [domain, session, dds, dir] = makeScratch(6, "e2e-gap");
    // 1.5 s of tracking, 5 frames walking out, 30 out of view, 5 walking back, then 2 s to come back.
    ChildProcess server({FACESCAN_SERVER_BIN, "--profile", "loopback", "--domain", domain, "--data-dir",
                         (dir / "data").string(), "--set", "status_hz=10"},
                        dir / "server.log");
    ChildProcess agent({FACESCAN_AGENT_BIN, "--profile", "loopback", "--domain", domain, "--session", session,
                        "--source", "synthetic:scenario=gap,gap_start=45,frames=145,subject=builtin,seed=6", "--rate",
                        "real", "--wait-for-server", "30"},
                       dir / "agent.log");
    const CliRun watch = runCli("watch " + session + dds + " --timeout 30");
    ASSERT_EQ(watch.exit_code, 0) << watch.out << "\nserver:\n"
                                  << readText(dir / "server.log") << "\nagent:\n"
                                  << readText(dir / "agent.log");
    EXPECT_EQ(agent.wait(30s), 0) << readText(dir / "agent.log");
    std::printf("%s", watch.out.c_str());
    const size_t lost = watch.out.find(" LOST ");
    ASSERT_NE(lost, std::string::npos) << "the loss is not shown:\n" << watch.out;
    const size_t advice = watch.out.find("(face lost: come back in front of the camera", lost);
    EXPECT_NE(advice, std::string::npos) << "no advice with the loss:\n" << watch.out;
    EXPECT_NE(watch.out.find(" SCANNING ", lost), std::string::npos) << "the scan never came back:\n" << watch.out;
    server.stop();
    fs::remove_all(dir);
}

}  // namespace
