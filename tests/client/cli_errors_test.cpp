// The real `facescan` binary on its error paths: each gives its message on stderr and its exit code
// (notes/protocol.md: 1 server refused, 2 usage, 3 no server, 4 cannot write). The unknown-session path needs a
// real server and is covered by tests/integration.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>

#include "run_command.hpp"
#include "test_domain.hpp"
namespace {

using CliRun = facescan::testing::CommandRun;

// The real `facescan` binary with these arguments.
CliRun runCli(const std::string& args) { return facescan::testing::runCommand(std::string(FACESCAN_CLI) + " " + args); }

std::string privateDomain() { return std::to_string(facescan::testing::privateDomain()); }

bool contains(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

TEST(CliErrors, HelpOnEveryCommandExitsZero) {
    for (const char* cmd :
         {"", "sessions ", "watch ", "status ", "mesh ", "preview ", "trajectory ", "finish ", "reset "}) {
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
