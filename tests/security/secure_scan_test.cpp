// DDS Security with the real programs over real Cyclone DDS (loopback profile, private domains), each test with a
// fresh site made by deploy/security/site.sh: a secured scan is private and each role does only its job, with the
// accuracy of the same scan without security; identities of another site and revoked ones are rejected; a bad
// identity stops every program at start with one line. Each check is shown to be able to fail (the unsecured
// scan is heard and answered; the identity to be revoked is accepted before).
#include <gtest/gtest.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <regex>
#include <sstream>
#include <thread>

#include "child_process.hpp"
#include "eavesdropper.hpp"
#include "eval/accuracy.hpp"
#include "site_fixture.hpp"
#include "synth/kinect_simulator.hpp"
#include "test_domain.hpp"

namespace {

using namespace facescan;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
namespace ft = facescan::testing;
using ft::ChildProcess;
using ft::CommandRun;
using ft::readText;
using ft::TempSite;

constexpr int kFrames = 30;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

std::string ddsArgs(uint32_t domain, const fs::path& identity) {
    std::string args = " --profile loopback --domain " + std::to_string(domain);
    if (!identity.empty()) args += " --security " + identity.string();
    return args;
}
std::vector<std::string> ddsArgv(uint32_t domain, const fs::path& identity) {
    std::vector<std::string> args{"--profile", "loopback", "--domain", std::to_string(domain)};
    if (!identity.empty()) args.insert(args.end(), {"--security", identity.string()});
    return args;
}

CommandRun cli(const std::string& args) { return ft::runCommand(std::string(FACESCAN_CLI) + " " + args); }

ChildProcess startServer(uint32_t domain, const fs::path& identity, const fs::path& dir, const std::string& log) {
    std::vector<std::string> args{FACESCAN_SERVER_BIN, "--data-dir", (dir / "data").string(), "--snapshot-hz", "2"};
    for (std::string& a : ddsArgv(domain, identity)) args.push_back(std::move(a));
    return ChildProcess(args, dir / log);
}

// The synthetic Kinect filming the built-in head; a recording (--rate max): every frame is processed, so the
// result does not depend on the machine's speed, and the secured and unsecured scans see the same frames.
ChildProcess startAgent(uint32_t domain, const fs::path& identity, const std::string& session, int frames, int wait_s,
                        const fs::path& log) {
    std::vector<std::string> args{FACESCAN_AGENT_BIN,
                                  "--session",
                                  session,
                                  "--source",
                                  "synthetic:frames=" + std::to_string(frames) + ",subject=builtin,seed=1",
                                  "--rate",
                                  "max",
                                  "--wait-for-server",
                                  std::to_string(wait_s)};
    for (std::string& a : ddsArgv(domain, identity)) args.push_back(std::move(a));
    return ChildProcess(args, log);
}

// frames_integrated of SESSION in `facescan sessions --json` (-1 when it is not listed in that state).
int integratedFrames(const std::string& sessions_json, const std::string& session, const std::string& state) {
    const std::regex line("\\{\"session\":\"" + session + "\"[^\\n]*\"state\":\"" + state +
                          "\"[^\\n]*\"frames_integrated\":([0-9]+)");
    std::smatch m;
    return std::regex_search(sessions_json, m, line) ? std::stoi(m[1].str()) : -1;
}

struct ScanResult {
    double mean_mm = -1;
    double completeness = 0;
    int frames_integrated = -1;
};

// The mesh of SESSION fetched with --finish (as `client` when secured), measured against the subject's ground
// truth; and the frames it integrated.
ScanResult fetchAndMeasure(const std::string& session, const std::string& dds, const fs::path& mesh_path) {
    ScanResult result;
    const CommandRun mesh = cli("mesh " + session + " -o " + mesh_path.string() + " --finish" + dds);
    EXPECT_EQ(mesh.exit_code, 0) << mesh.out;
    const CommandRun sessions = cli("sessions --json" + dds);
    result.frames_integrated = integratedFrames(sessions.out, session, "FINISHED");
    recon::Mesh model;
    if (!OpenMesh::IO::read_mesh(model, mesh_path.string())) return result;
    const synth::KinectSimulator sim(synth::builtinHead(), [] {
        synth::SequenceParams p;
        p.seed = 1;
        return p;
    }());
    const recon::Mesh& gt = sim.head().mesh;
    auto report = eval::measureAccuracy(model, gt, eval::findNoseTip(gt), {}, sim.poseAt(0).inverse());
    EXPECT_TRUE(report.isOk()) << report.status().toString();
    if (report.isOk()) {
        result.mean_mm = report->mean_mm;
        result.completeness = report->completeness;
    }
    return result;
}

TEST(SecureScan, IsPrivateEachRoleDoesOnlyItsJobAndTheAccuracyIsThatOfAnUnsecuredScan) {
    TempSite site("scan");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const fs::path dir = site.root();
    const uint32_t plain_domain = ft::privateDomain(1), secure_domain = ft::privateDomain(2);

    // 1. The same scan without DDS Security: an unauthenticated participant hears frames, status and meshes, and
    //    its command is answered (so the checks of the secured scan below can fail).
    ScanResult plain;
    {
        const std::string session = "plain-" + std::to_string(::getpid());
        const std::string dds = ddsArgs(plain_domain, {});
        auto eve = ft::Eavesdropper::join(plain_domain);
        ASSERT_TRUE(eve.isOk()) << eve.status().toString();
        ChildProcess server = startServer(plain_domain, {}, dir, "plain_server.log");
        ChildProcess agent = startAgent(plain_domain, {}, session, kFrames, 30, dir / "plain_agent.log");
        const ft::Heard heard = (*eve)->listen(20s, "", /*until_all_heard=*/true);
        EXPECT_GT(heard.frames, 0) << heard.text();
        EXPECT_GT(heard.statuses, 0) << heard.text();
        EXPECT_GT(heard.snapshots, 0) << heard.text();
        EXPECT_EQ(agent.wait(60s), 0) << readText(dir / "plain_agent.log");
        const CommandRun watch = cli("watch " + session + dds + " --timeout 30");
        EXPECT_EQ(watch.exit_code, 0) << watch.out;
        EXPECT_TRUE((*eve)->answered(session, 5s)) << "without security anyone's command is answered";
        plain = fetchAndMeasure(session, dds, dir / "plain.ply");
    }
    ASSERT_GT(plain.frames_integrated, kFrames / 2);

    // 2. Secured: agent, server, client and viewer each with their identity of the site.
    const std::string session = "secure-" + std::to_string(::getpid());
    const std::string as_viewer = ddsArgs(secure_domain, site.identity("viewer"));
    const std::string as_client = ddsArgs(secure_domain, site.identity("client"));
    auto eve = ft::Eavesdropper::join(secure_domain);
    ASSERT_TRUE(eve.isOk()) << eve.status().toString();
    ChildProcess server = startServer(secure_domain, site.identity("server"), dir, "secure_server.log");
    // The unauthenticated participant listens for 5 s from before the scan starts, and meanwhile tries to reset
    // and finish the session and sends it frames of its own.
    ft::Heard heard;
    std::thread listener([&] { heard = (*eve)->listen(5s, session, /*until_all_heard=*/false); });
    // The viewer follows the scan from its start and saves the snapshots it reads.
    ChildProcess watch(
        {FACESCAN_CLI, "watch", session, "--save", (dir / "viewer_snaps").string(), "--profile", "loopback", "--domain",
         std::to_string(secure_domain), "--security", site.identity("viewer").string(), "--timeout", "60"},
        dir / "viewer_watch.log");
    ChildProcess agent =
        startAgent(secure_domain, site.identity("agent"), session, kFrames, 30, dir / "secure_agent.log");

    // The viewer reads the status; its reset and finish are refused by access control; the scan goes on.
    int integrated_seen = -1;
    for (int i = 0; i < 30 && integrated_seen < 0; ++i) {
        integrated_seen = integratedFrames(cli("sessions --json" + as_viewer).out, session, "[A-Z]+");
    }
    EXPECT_GE(integrated_seen, 0) << "the viewer never saw the scan's status\n"
                                  << readText(dir / "secure_server.log") << readText(dir / "secure_agent.log");
    for (const char* command : {"reset", "finish"}) {
        const CommandRun refused = cli(std::string(command) + " " + session + as_viewer);
        EXPECT_EQ(refused.exit_code, 6) << refused.out;
        EXPECT_TRUE(contains(refused.out, "DDS Security access control refused")) << refused.out;
        EXPECT_TRUE(contains(refused.out, "may not send commands")) << refused.out;
    }
    EXPECT_EQ(watch.wait(60s), 0) << readText(dir / "viewer_watch.log");
    EXPECT_TRUE(contains(readText(dir / "viewer_watch.log"), "scan " + session + " finished"))
        << readText(dir / "viewer_watch.log");
    int snapshots = 0;
    for (const auto& entry : fs::directory_iterator(dir / "viewer_snaps")) {
        recon::Mesh snap;
        EXPECT_TRUE(OpenMesh::IO::read_mesh(snap, entry.path().string())) << entry.path();
        ++snapshots;
    }
    EXPECT_GE(snapshots, 1) << "the viewer reads snapshots\n" << readText(dir / "viewer_watch.log");
    EXPECT_EQ(agent.wait(60s), 0) << readText(dir / "secure_agent.log");
    listener.join();

    // Nothing reached the unauthenticated participant, and nobody answered it.
    EXPECT_EQ(heard.total(), 0) << heard.text();
    EXPECT_FALSE((*eve)->answered(session, 2s)) << "a command without credentials was answered";

    // The client (commands allowed) fetches the final mesh: every frame integrated, as without security (the
    // eavesdropper's reset never arrived), with the same accuracy.
    const ScanResult secure = fetchAndMeasure(session, as_client, dir / "secure.ply");
    // The server's audit trail names the fetch's sender by the subject it authenticated with.
    bool fetch_on_record = false;
    std::istringstream audit(readText(dir / "data" / "audit.log"));
    for (std::string line; std::getline(audit, line);) {
        fetch_on_record = fetch_on_record || (contains(line, "\tget_mesh\t" + session + "\t") &&
                                              contains(line, "\tdds CN=client,OU=client,O=lab (client id client@"));
    }
    EXPECT_TRUE(fetch_on_record) << readText(dir / "data" / "audit.log");
    std::printf(
        "secured scan (%d frames): mean %.3f mm, completeness %.3f, %d integrated; unsecured: mean %.3f mm, "
        "completeness %.3f, %d integrated\n",
        kFrames, secure.mean_mm, secure.completeness, secure.frames_integrated, plain.mean_mm, plain.completeness,
        plain.frames_integrated);
    EXPECT_EQ(secure.frames_integrated, plain.frames_integrated);
    EXPECT_NEAR(secure.mean_mm, plain.mean_mm, 0.05);
    EXPECT_NEAR(secure.completeness, plain.completeness, 0.02);
    EXPECT_GT(secure.mean_mm, 0.0);
}

TEST(SecureScan, IdentitiesOfAnotherSiteAndRevokedOnesAreRejected) {
    TempSite site("reject");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    TempSite other("reject_other", "othersite");
    ASSERT_TRUE(other.ok()) << other.initOutput();
    const fs::path dir = site.root();
    const uint32_t domain = ft::privateDomain(3);
    ASSERT_EQ(site.add("agent", "pc-lost").exit_code, 0);
    // What the lost machine keeps: its identity folder as enrolled, revocation list included.
    fs::copy(site.identity("pc-lost"), dir / "kept", fs::copy_options::recursive);

    auto agentRun = [&](const fs::path& identity, const std::string& tag, int wait_s) {
        return startAgent(domain, identity, tag + "-" + std::to_string(::getpid()), 3, wait_s, dir / (tag + ".log"));
    };
    {
        ChildProcess server = startServer(domain, site.identity("server"), dir, "server1.log");
        ChildProcess before = agentRun(dir / "kept", "before", 20);
        EXPECT_EQ(before.wait(40s), 0) << "the identity is accepted before it is revoked\n"
                                       << readText(dir / "before.log");
        EXPECT_TRUE(contains(readText(dir / "before.log"), "server found")) << readText(dir / "before.log");
    }
    const CommandRun revoked = site.revoke("pc-lost");
    ASSERT_EQ(revoked.exit_code, 0) << revoked.out;

    // Its peers restart with the site's new revocation list (site.sh copied it into their folders).
    ChildProcess server = startServer(domain, site.identity("server"), dir, "server2.log");
    ChildProcess lost = agentRun(dir / "kept", "lost", 5);
    ChildProcess foreign = agentRun(other.identity("agent"), "foreign", 5);
    ChildProcess enrolled = agentRun(site.identity("agent"), "enrolled", 20);
    const CommandRun foreign_client = cli("sessions" + ddsArgs(domain, other.identity("client")) + " --timeout 5");
    for (const auto& [process, tag] : {std::pair{&lost, "lost"}, std::pair{&foreign, "foreign"}}) {
        EXPECT_EQ(process->wait(40s), 1) << tag << " was accepted:\n" << readText(dir / (std::string(tag) + ".log"));
        EXPECT_TRUE(contains(readText(dir / (std::string(tag) + ".log")), "no facescan-server appeared"))
            << readText(dir / (std::string(tag) + ".log"));
    }
    EXPECT_EQ(foreign_client.exit_code, 3) << foreign_client.out;
    EXPECT_TRUE(contains(foreign_client.out, "no server answered")) << foreign_client.out;
    EXPECT_EQ(enrolled.wait(40s), 0) << "the site's own agent still scans\n" << readText(dir / "enrolled.log");
}

TEST(SecurePrograms, ABadIdentityStopsEveryProgramAtStartWithOneLineNamingTheFile) {
    TempSite site("start");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const uint32_t domain = ft::privateDomain(4);
    for (const std::string role : {"agent", "server", "client"}) {
        ASSERT_EQ(site.add(role, "old-" + role, "--from 2020-01-01 --until 2021-01-01").exit_code, 0);
    }
    ASSERT_EQ(site.add("server", "mixed").exit_code, 0);
    fs::copy_file(site.identity("client") / "identity.key", site.identity("mixed") / "identity.key",
                  fs::copy_options::overwrite_existing);

    struct Case {
        std::string command;
        fs::path identity;
        int exit_code;
        std::string says;
    };
    const std::string agent = std::string(FACESCAN_AGENT_BIN) + " --source synthetic:frames=2,subject=builtin";
    const std::string server = std::string(FACESCAN_SERVER_BIN) + " --data-dir " + (site.root() / "data").string();
    const std::string client = std::string(FACESCAN_CLI) + " sessions";
    const std::vector<Case> cases = {
        {agent, site.identity("old-agent"), 1, "identity.pem: the certificate expired on 2021-01-01 00:00 UTC"},
        {server, site.identity("old-server"), 1, "identity.pem: the certificate expired on 2021-01-01 00:00 UTC"},
        {client, site.identity("old-client"), 6, "identity.pem: the certificate expired on 2021-01-01 00:00 UTC"},
        {server, site.identity("mixed"), 1, "identity.key: is not the private key of"},
        {agent, site.root() / "nowhere", 1, "nowhere: no such identity folder"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.command + " with " + c.identity.string());
        const CommandRun run = ft::runCommand(c.command + ddsArgs(domain, c.identity));
        EXPECT_EQ(run.exit_code, c.exit_code) << run.out;
        // One line names the file and says what is wrong; nothing of Cyclone's own (return codes, plugin logs).
        EXPECT_TRUE(contains(run.out, c.says)) << run.out;
        EXPECT_EQ(std::count(run.out.begin(), run.out.end(), '\n'), 1) << run.out;
        for (const char* cyclone : {"retcode", "-13", "Error occurred", "code:", "DDS_RETCODE"}) {
            EXPECT_FALSE(contains(run.out, cyclone)) << run.out;
        }
    }
}

}  // namespace
