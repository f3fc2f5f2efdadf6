// facescan-bench recon reads depth cameras' own recordings through the agent's sources: the shared data's Azure
// Kinect recording (mkv:FILE) and a RealSense bag written in librealsense's layout from the synthetic Kinect
// (bag:FILE); a file of neither kind gets one line, not a crash.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "capture/frame_source.hpp"
#include "realsense_bag.hpp"
#include "run_command.hpp"
#include "test_data.hpp"

namespace facescan::testing {
namespace {

namespace fs = std::filesystem;

CommandRun bench(const std::string& args) { return runCommand(std::string(FACESCAN_BENCH_BIN) + " " + args); }
bool contains(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

TEST(BenchRecordings, ReconReadsAnAzureKinectMkv) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    // A mug on a desk before a window, not a head: whole frames, in a volume that holds the room.
    const CommandRun run =
        bench("recon --input 'mkv:" + (data / "recording.mkv").string() + "' --mask none --volume-m 3 --trunc-m 0.05");
    ASSERT_EQ(run.exit_code, 0) << run.out;
    EXPECT_TRUE(contains(run.out, "1 frames")) << run.out;
    EXPECT_TRUE(contains(run.out, "camera azure-kinect")) << run.out;
    EXPECT_TRUE(contains(run.out, "rejected 0")) << run.out;
}

TEST(BenchRecordings, ReconReadsARealSenseBag) {
    const fs::path bag = fs::temp_directory_path() / ("facescan-bench-" + std::to_string(::getpid()) + ".bag");
    auto source = capture::openSource("synthetic:frames=12,subject=builtin,seed=2", {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    writeRealSenseBag(bag.string(), **source, {});
    const CommandRun run = bench("recon --input 'bag:" + bag.string() + "' --mask pipeline");
    fs::remove(bag);
    ASSERT_EQ(run.exit_code, 0) << run.out;
    EXPECT_TRUE(contains(run.out, "12 frames")) << run.out;
    EXPECT_TRUE(contains(run.out, "camera realsense-d415")) << run.out;
}

TEST(BenchRecordings, NeitherKindIsOneLine) {
    const fs::path text = fs::temp_directory_path() / ("facescan-bench-" + std::to_string(::getpid()) + ".mkv");
    std::ofstream(text) << "not a recording\n";
    for (const std::string kind : {"mkv:", "bag:"}) {
        const CommandRun run = bench("recon --input '" + kind + text.string() + "'");
        EXPECT_NE(run.exit_code, 0) << run.out;
        EXPECT_TRUE(contains(run.out, text.string())) << run.out;
    }
    fs::remove(text);
}

}  // namespace
}  // namespace facescan::testing
