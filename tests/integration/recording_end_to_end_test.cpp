// Depth cameras' own recordings through the whole product over real DDS (loopback profile, a private domain):
// facescan-server and facescan-agent (--source mkv:FILE, the shared data's Azure Kinect recording) run as child
// processes, and so does a RealSense .bag written in librealsense's layout from the synthetic Kinect (bag:FILE);
// the facescan client watches each scan to its end, reads its status and fetches the mesh. A recording whose depth
// units are wrong (a median of 300 m, or of a millimetre) is stopped by the agent with one line.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "capture/frame_source.hpp"
#include "child_process.hpp"
#include "matroska_edit.hpp"
#include "realsense_bag.hpp"
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
    // Every frame reaches the server; most are integrated (the first ones go by while the head is being found).
    const size_t received_at = status.out.find(std::to_string(frames) + " received, ");
    ASSERT_NE(received_at, std::string::npos) << status.out;
    const int integrated = std::atoi(status.out.c_str() + status.out.find(", ", received_at) + 2);
    EXPECT_GE(integrated, (frames + 1) / 2) << status.out;

    const CommandRun mesh = runCli("mesh " + session + " -o " + (dir / "scan.ply").string() + dds);
    EXPECT_EQ(mesh.exit_code, 0) << mesh.out << "\nserver:\n" << readText(dir / "server.log");
    // Colour from the recording's own colour camera: vertex colours, kept beside the texture when one was baked.
    EXPECT_TRUE(contains(mesh.out, "vertex colours")) << mesh.out;
    fs::remove_all(dir);
}

TEST(RecordingEndToEnd, AzureKinectMkv) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    scanRecording("mkv:" + (data / "recording.mkv").string(), "mkv", 1);
}

// A recording that breaks off after some frames: the agent stops with one line and the server still finishes the
// scan with the frames it got (nothing already scanned is lost).
TEST(RecordingEndToEnd, ACutShortRecordingKeepsWhatWasScanned) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    namespace mk = facescan::testing::matroska;
    // Five captures 200 ms apart, cut inside the fourth one's depth block: three whole frames, then the break.
    std::vector<uint8_t> bytes = mk::repeated(mk::readFile(data / "recording.mkv"), 5, -1);
    bytes.resize(bytes.size() - 1691600 - 1200000);
    const std::string domain = std::to_string(facescan::testing::privateDomain(13));
    const std::string session = "mkvcut-" + std::to_string(::getpid());
    const std::string dds = " --profile loopback --domain " + domain;
    const fs::path dir = fs::temp_directory_path() / ("facescan_" + session);
    fs::create_directories(dir);
    mk::writeFile(dir / "cut.mkv", bytes);
    ChildProcess server(
        {FACESCAN_SERVER_BIN, "--profile", "loopback", "--domain", domain, "--data-dir", (dir / "data").string()},
        dir / "server.log");
    const CommandRun agent = facescan::testing::runCommand(
        "timeout 90 " + std::string(FACESCAN_AGENT_BIN) + dds + " --session " + session +
        " --wait-for-server 30 --source mkv:" + (dir / "cut.mkv").string() + " --rate max");
    EXPECT_NE(agent.exit_code, 0) << agent.out;
    EXPECT_TRUE(contains(agent.out, "is cut short: it ends at 0.86 s of its 1.26 s")) << agent.out;
    const CommandRun status = runCli("status " + session + dds);
    EXPECT_EQ(status.exit_code, 0) << status.out << "\nserver:\n" << readText(dir / "server.log");
    EXPECT_TRUE(contains(status.out, "FINISHED")) << status.out;
    EXPECT_TRUE(contains(status.out, "3 received, 3 integrated")) << status.out;
    fs::remove_all(dir);
}

// A RealSense bag of the synthetic Kinect filming the built-in head.
fs::path writeBag(const std::string& name, int frames, const facescan::testing::RealSenseBagSpec& spec) {
    const fs::path path = fs::temp_directory_path() / ("facescan-" + name + "-" + std::to_string(::getpid()) + ".bag");
    auto source =
        facescan::capture::openSource("synthetic:frames=" + std::to_string(frames) + ",subject=builtin,seed=1", {});
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    facescan::testing::writeRealSenseBag(path.string(), **source, spec);
    return path;
}

TEST(RecordingEndToEnd, RealSenseBag) {
    const fs::path bag = writeBag("e2e", 20, {});
    scanRecording("bag:" + bag.string(), "bag", 20);
    fs::remove(bag);
}

// The agent checks its first frame against the camera before sending anything: wrong units stop it with one line,
// which says how to give the right ones; given, the recording is scanned.
TEST(RecordingEndToEnd, DepthInWrongUnitsIsStoppedWithOneLine) {
    const std::string domain = std::to_string(facescan::testing::privateDomain(12));
    const fs::path dir = fs::temp_directory_path() / ("facescan_units-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    ChildProcess server(
        {FACESCAN_SERVER_BIN, "--profile", "loopback", "--domain", domain, "--data-dir", (dir / "data").string()},
        dir / "server.log");
    facescan::testing::RealSenseBagSpec far, near;
    far.depth_units_m = 0.01f;  // says centimetres, holds fiftieths of a millimetre: a head at 300 m
    far.raw_per_mm = 50.0f;
    near.depth_units_m = 2e-6f;  // says micrometres, holds millimetres: a head at about a millimetre
    for (const auto& [name, spec] : {std::pair{"far", far}, std::pair{"near", near}}) {
        const fs::path bag = writeBag(name, 3, spec);
        const CommandRun agent = facescan::testing::runCommand(
            "timeout 60 " + std::string(FACESCAN_AGENT_BIN) + " --profile loopback --domain " + domain +
            " --wait-for-server 30 --source bag:" + bag.string() + " --rate max");
        EXPECT_NE(agent.exit_code, 0) << agent.out;
        EXPECT_TRUE(contains(agent.out, "depth units look wrong")) << name << ": " << agent.out;
        size_t lines_saying = 0;
        for (size_t at = agent.out.find("depth units look wrong"); at != std::string::npos;
             at = agent.out.find("depth units look wrong", at + 1))
            ++lines_saying;
        EXPECT_EQ(lines_saying, 1u) << agent.out;
        EXPECT_TRUE(contains(agent.out, "--depth-scale")) << "says what to do: " << agent.out;
        fs::remove(bag);
    }
    // What the line says to do: the millimetres of the second bag, given as such, are scanned.
    const fs::path bag = writeBag("near-fixed", 3, near);
    const CommandRun fixed = facescan::testing::runCommand(
        "timeout 60 " + std::string(FACESCAN_AGENT_BIN) + " --profile loopback --domain " + domain +
        " --wait-for-server 30 --depth-scale 1000 --source bag:" + bag.string() + " --rate max");
    EXPECT_EQ(fixed.exit_code, 0) << fixed.out;
    EXPECT_FALSE(contains(fixed.out, "depth units look wrong")) << fixed.out;
    fs::remove(bag);
    fs::remove_all(dir);
}

}  // namespace
