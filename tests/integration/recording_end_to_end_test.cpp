// Depth cameras' own recordings through the whole product over real DDS (loopback profile, a private domain):
// facescan-server and facescan-agent (--source mkv:FILE, the shared data's Azure Kinect recording) run as child
// processes; the facescan client watches the scan to its end, reads its status and fetches the mesh.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>

#include "child_process.hpp"
#include "run_command.hpp"
#include "test_data.hpp"
#include "test_domain.hpp"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using facescan::testing::ChildProcess;
using facescan::testing::CommandRun;
using facescan::testing::readText;

CommandRun runCli(const std::string& args) {
    return facescan::testing::runCommand(std::string(FACESCAN_CLI) + " " + args);
}
bool contains(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

// Streams `source` from the agent to a server and checks, with the client, that the scan finished with every
// frame integrated and that its mesh can be fetched.
void scanRecording(const std::string& source, const std::string& name, int frames) {
    const std::string domain = std::to_string(facescan::testing::privateDomain(11));
    const std::string session = name + "-" + std::to_string(::getpid());
    const std::string dds = " --profile loopback --domain " + domain;
    const fs::path dir = fs::temp_directory_path() / ("facescan_" + session);
    fs::remove_all(dir);
    fs::create_directories(dir);

    ChildProcess server(
        {FACESCAN_SERVER_BIN, "--profile", "loopback", "--domain", domain, "--data-dir", (dir / "data").string()},
        dir / "server.log");
    ChildProcess agent({FACESCAN_AGENT_BIN, "--profile", "loopback", "--domain", domain, "--session", session,
                        "--source", source, "--rate", "max", "--wait-for-server", "30"},
                       dir / "agent.log");
    const CommandRun watch = runCli("watch " + session + dds + " --timeout 30");
    ASSERT_EQ(watch.exit_code, 0) << watch.out << "\nserver:\n"
                                  << readText(dir / "server.log") << "\nagent:\n"
                                  << readText(dir / "agent.log");
    EXPECT_TRUE(contains(watch.out, "scan " + session + " finished")) << watch.out;
    EXPECT_EQ(agent.wait(30s), 0) << readText(dir / "agent.log");
    EXPECT_FALSE(contains(readText(dir / "agent.log"), "error")) << readText(dir / "agent.log");

    const CommandRun status = runCli("status " + session + dds);
    EXPECT_EQ(status.exit_code, 0) << status.out;
    EXPECT_TRUE(contains(status.out, "FINISHED")) << status.out;
    const std::string integrated = std::to_string(frames) + " integrated";
    EXPECT_TRUE(contains(status.out, std::to_string(frames) + " received, " + integrated)) << status.out;

    const CommandRun mesh = runCli("mesh " + session + " -o " + (dir / "scan.ply").string() + dds);
    EXPECT_EQ(mesh.exit_code, 0) << mesh.out << "\nserver:\n" << readText(dir / "server.log");
    EXPECT_TRUE(contains(mesh.out, "with colours")) << "colour from the recording's own colour camera: " << mesh.out;
    fs::remove_all(dir);
}

TEST(RecordingEndToEnd, AzureKinectMkv) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    scanRecording("mkv:" + (data / "recording.mkv").string(), "mkv", 1);
}

}  // namespace
