// The real `facescan` binary on its error paths: each gives its message on stderr and its exit code
// (notes/protocol.md: 1 server refused, 2 usage, 3 no server, 4 cannot write, 5 view cannot serve). The
// unknown-session path needs a real server and is covered by tests/integration.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <thread>

#include "child_process.hpp"
#include "client/web_assets.hpp"
#include "run_command.hpp"
#include "test_domain.hpp"
#include "wire/audit_log.hpp"
namespace {

using CliRun = facescan::testing::CommandRun;

// The real `facescan` binary with these arguments.
CliRun runCli(const std::string& args) { return facescan::testing::runCommand(std::string(FACESCAN_CLI) + " " + args); }

std::string privateDomain() { return std::to_string(facescan::testing::privateDomain()); }

bool contains(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

TEST(CliErrors, HelpOnEveryCommandExitsZero) {
    for (const char* cmd :
         {"", "sessions ", "watch ", "status ", "mesh ", "preview ", "trajectory ", "finish ", "reset ", "view "}) {
        const CliRun run = runCli(std::string(cmd) + "--help");
        EXPECT_EQ(run.exit_code, 0) << cmd << run.out;
        EXPECT_TRUE(contains(run.out, "Usage: facescan")) << cmd;
        EXPECT_TRUE(contains(run.out, "--profile")) << cmd;
    }
}

TEST(CliErrors, UsageErrorsExitTwoAndPointToHelp) {
    const CliRun none = runCli("");
    EXPECT_EQ(none.exit_code, 2);
    EXPECT_TRUE(contains(none.out, "no command given")) << none.out;
    const CliRun format = runCli("mesh s1 -o face.xyz");
    EXPECT_EQ(format.exit_code, 2);
    EXPECT_TRUE(contains(format.out, "unknown mesh format '.xyz'")) << format.out;
    EXPECT_TRUE(contains(format.out, "facescan mesh --help")) << format.out;
    const CliRun profile = runCli("status s1 --profile nosuch --timeout 1");
    EXPECT_EQ(profile.exit_code, 2);
    EXPECT_TRUE(contains(profile.out, "unknown DDS profile 'nosuch'")) << profile.out;
}

// `facescan view` that cannot serve exits 5 and says why: its web files missing (what to run), or its port taken.
TEST(CliErrors, ViewWithoutItsFilesOrItsPortExitsFive) {
    const std::string dds = " --profile loopback --domain " + privateDomain();
    const CliRun missing = facescan::testing::runCommand("FACESCAN_WEB_DIR=/nonexistent " + std::string(FACESCAN_CLI) +
                                                         " view --port 0" + dds);
    EXPECT_EQ(missing.exit_code, 5) << missing.out;
    EXPECT_TRUE(contains(missing.out,
                         "facescan: error: the viewer's file '/nonexistent/index.html' is missing: run "
                         "deploy/install-deps.sh"))
        << missing.out;

    // With its files found, the port is what stops it; an offline machine without the npm packages (no
    // three.js) stops at the files first, so that half needs them.
    if (!facescan::client::findWebRoot().isOk())
        GTEST_SKIP() << "the viewer's npm packages are missing (deploy/install-deps.sh)";
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);  // a port in use on 127.0.0.1
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    ASSERT_EQ(::listen(fd, 1), 0);
    socklen_t len = sizeof(addr);
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
    const std::string port = std::to_string(ntohs(addr.sin_port));
    const CliRun taken = runCli("view --port " + port + dds);
    ::close(fd);
    EXPECT_EQ(taken.exit_code, 5) << taken.out;
    EXPECT_TRUE(contains(taken.out, "facescan: error: cannot serve on 127.0.0.1:" + port)) << taken.out;
    EXPECT_TRUE(contains(taken.out, "--port")) << taken.out;
}

// A viewer that other machines reach over plain HTTP hands every scan (a face) to anyone on the network: refused,
// with the safe way to reach it, unless the user says --insecure-http, and then it warns at every start.
TEST(CliErrors, ViewOnTheNetworkInPlainHttpIsRefusedUnlessInsecureHttpWhichWarns) {
    const std::string dds = " --profile loopback --domain " + privateDomain();
    for (const std::string bind : {"0.0.0.0", "::", "192.168.1.20"}) {
        const CliRun refused = runCli("view --port 0 --bind " + bind + dds);
        EXPECT_EQ(refused.exit_code, 2) << bind << ": " << refused.out;
        EXPECT_TRUE(contains(refused.out, "--bind " + bind + " would serve every scan")) << refused.out;
        EXPECT_TRUE(contains(refused.out, "ssh -L 8080:127.0.0.1:8080")) << refused.out;
        EXPECT_TRUE(contains(refused.out, "--tls SITE/NAME")) << refused.out;
        EXPECT_TRUE(contains(refused.out, "--insecure-http")) << refused.out;
        EXPECT_FALSE(contains(refused.out, "serving http")) << refused.out;
    }
    if (!facescan::client::findWebRoot().isOk())
        GTEST_SKIP() << "the viewer's npm packages are missing (deploy/install-deps.sh)";
    for (const std::string bind : {"0.0.0.0", "127.0.0.1"}) {
        // A log of its own per run: the first run's lines must not stand in for the second's.
        const auto log = std::filesystem::temp_directory_path() /
                         ("facescan_cli_insecure_" + std::to_string(::getpid()) + "_" + bind + ".log");
        const auto text = [&] {
            std::ifstream in(log);
            return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        };
        facescan::testing::ChildProcess view({FACESCAN_CLI, "view", "--port", "0", "--bind", bind, "--insecure-http",
                                              "--profile", "loopback", "--domain", privateDomain()},
                                             log);
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
        while (!contains(text(), "serving http://") && std::chrono::steady_clock::now() < deadline && view.running()) {
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
        const std::string out = text();
        EXPECT_TRUE(contains(out, "serving http://")) << out;
        EXPECT_TRUE(contains(out, "WARNING: --insecure-http: plain HTTP without a login")) << bind << ": " << out;
        EXPECT_EQ(contains(out, "on this machine only, for now"), bind == "127.0.0.1") << out;
        view.signal(SIGINT);
        EXPECT_EQ(view.wait(std::chrono::seconds(20)), 0) << text();
        std::filesystem::remove(log);
    }
}

// --tls names the viewer's identity folder: without its certificate the viewer does not start, and says what to run.
TEST(CliErrors, ViewWithTlsButNoCertificateSaysWhatToRun) {
    if (!facescan::client::findWebRoot().isOk())
        GTEST_SKIP() << "the viewer's npm packages are missing (deploy/install-deps.sh)";
    const CliRun run =
        runCli("view --port 0 --bind 0.0.0.0 --tls /nonexistent/viewer --profile loopback --domain " + privateDomain());
    EXPECT_EQ(run.exit_code, 5) << run.out;
    EXPECT_TRUE(contains(run.out, "/nonexistent/viewer/web.pem")) << run.out;
    EXPECT_TRUE(contains(run.out, "facescan-site web SITE NAME --host THIS-HOST")) << run.out;
}

// `facescan audit` reads the trails a server and a viewer wrote, oldest first, one session's with --session.
TEST(CliErrors, AuditPrintsTheTrailsOfServersAndViewers) {
    const auto dir = std::filesystem::temp_directory_path() / ("facescan_cli_audit_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir / "data");
    {
        auto server = facescan::wire::AuditLog::open(dir / "data" / "audit.log");
        auto viewer = facescan::wire::AuditLog::open(dir / "view.log");
        ASSERT_TRUE(server.isOk() && viewer.isOk());
        ASSERT_TRUE((*server)
                        ->append({2'000'000'000'000'000'000, "reset", "s1", "client ana@pc:1:2", "ok", "server a"})
                        .isOk());
        ASSERT_TRUE(
            (*viewer)->append({1'000'000'000'000'000'000, "download ply", "s1", "login bob", "ok", "viewer v"}).isOk());
        ASSERT_TRUE((*server)
                        ->append({3'000'000'000'000'000'000, "get_mesh", "s2", "client ana@pc:1:2",
                                  "error: unknown session 's2'", "server a"})
                        .isOk());
    }
    const CliRun all = runCli("audit " + (dir / "data").string() + " " + (dir / "view.log").string());
    EXPECT_EQ(all.exit_code, 0) << all.out;
    const size_t download = all.out.find("download ply"), reset = all.out.find("reset"), get = all.out.find("get_mesh");
    ASSERT_NE(download, std::string::npos) << all.out;
    EXPECT_LT(download, reset) << "oldest first, across files: " << all.out;
    EXPECT_LT(reset, get) << all.out;
    EXPECT_TRUE(contains(all.out, "login bob")) << all.out;
    EXPECT_TRUE(contains(all.out, "client ana@pc:1:2")) << all.out;
    EXPECT_TRUE(contains(all.out, "2001-09-09T01:46:40.000Z")) << all.out;
    const CliRun one =
        runCli("audit " + (dir / "data").string() + " " + (dir / "view.log").string() + " --session s2 --json");
    EXPECT_EQ(one.exit_code, 0) << one.out;
    EXPECT_EQ(one.out,
              "{\"time\":\"2065-01-24T05:20:00.000Z\",\"action\":\"get_mesh\",\"session\":\"s2\",\"identity\":"
              "\"client ana@pc:1:2\",\"outcome\":\"error: unknown session 's2'\",\"recorder\":\"server a\"}\n");
    const CliRun missing = runCli("audit " + (dir / "nothing").string());
    EXPECT_EQ(missing.exit_code, 2) << missing.out;
    EXPECT_TRUE(contains(missing.out, "no audit trail at")) << missing.out;
    std::filesystem::remove_all(dir);
}

TEST(CliErrors, NoServerExitsThreeAfterTheTimeout) {
    const std::string domain = privateDomain();
    const auto tmp = std::filesystem::temp_directory_path() / ("facescan_cli_errors_" + std::to_string(::getpid()));
    std::filesystem::create_directories(tmp);
    for (const std::string& args : {"mesh s1 -o " + (tmp / "face.ply").string(), std::string("status s1"),
                                    std::string("sessions"), "trajectory s1 -o " + (tmp / "t.txt").string()}) {
        const CliRun run = runCli(args + " --profile loopback --domain " + domain + " --timeout 1");
        EXPECT_EQ(run.exit_code, 3) << args << ": " << run.out;
        EXPECT_TRUE(contains(run.out, "facescan: error: no server answered on domain " + domain +
                                          " (profile loopback): is facescan-server running?"))
            << run.out;
    }
    EXPECT_TRUE(std::filesystem::is_empty(tmp)) << "a failed fetch must not leave files";
    std::filesystem::remove_all(tmp);
}

TEST(CliErrors, UnwritableOutputExitsFourBeforeAskingAnyServer) {
    // Checked before the network: it fails at once even though no server would answer for a second.
    const CliRun missing = runCli("mesh s1 -o /nonexistent-folder/face.ply --profile loopback --timeout 1");
    EXPECT_EQ(missing.exit_code, 4) << missing.out;
    EXPECT_TRUE(contains(missing.out, "cannot write '/nonexistent-folder/face.ply'")) << missing.out;
    const auto tmp = std::filesystem::temp_directory_path() / ("facescan_cli_dir_" + std::to_string(::getpid()));
    std::filesystem::create_directories(tmp / "face.ply");  // a folder where the file should go
    const CliRun folder = runCli("mesh s1 -o " + (tmp / "face.ply").string() + " --profile loopback --timeout 1");
    EXPECT_EQ(folder.exit_code, 4) << folder.out;
    EXPECT_TRUE(contains(folder.out, "it is a folder")) << folder.out;
    std::filesystem::remove_all(tmp);
    if (::geteuid() != 0) {
        const CliRun denied = runCli("preview s1 -o /proc/facescan.png --profile loopback --timeout 1");
        EXPECT_EQ(denied.exit_code, 4) << denied.out;
        EXPECT_TRUE(contains(denied.out, "not writable")) << denied.out;
    }
}

}  // namespace
