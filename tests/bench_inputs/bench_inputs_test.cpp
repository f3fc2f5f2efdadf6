// facescan-bench reads recordings (docs/design.md s6): detect and codecs take `--input tum:DIR` (they once answered
// "unknown source" and "no frames"), detect's --boxes writes one line per frame and detector, and recon refuses a
// mask-less recording much deeper than its volume with a message that says what to do, instead of rejecting
// nearly every frame. The recording: 5 frames of the Lee Perry-Smith head at 0.7 m with a wall behind, written as a
// TUM folder by `facescan-bench synth --tum`, laid out as a TUM RGB-D benchmark folder (what `--source tum:DIR` of
// facescan-agent also reads).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "run_command.hpp"
#include "test_data.hpp"

namespace facescan::testing {
namespace {

namespace fs = std::filesystem;

constexpr int kRecordedFrames = 5;
constexpr int kBenchFrames = 3;  // --frames: fewer than recorded, so the limit is checked too

std::string quoted(const fs::path& p) { return "'" + p.string() + "'"; }

CommandRun bench(const std::string& args) { return runCommand(std::string(FACESCAN_BENCH_BIN) + " " + args); }

std::vector<std::string> splitCsv(const std::string& line) {
    std::vector<std::string> fields;
    std::stringstream in(line);
    for (std::string f; std::getline(in, f, ',');) fields.push_back(f);
    if (!line.empty() && line.back() == ',') fields.emplace_back();
    return fields;
}

class BenchTumInput : public ::testing::Test {
 protected:
    void SetUp() override {
        FACESCAN_REQUIRE_DATA(head_data, "leeperrysmith");
        // The bench looks for the scan by itself (beside its own binary); hand it the data this test found, so
        // that the two never disagree (a build folder outside the checkout would otherwise fail, not skip).
        ::setenv("FACESCAN_DATA_DIR", head_data.parent_path().c_str(), 1);
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        scratch_ =
            fs::temp_directory_path() / ("facescan-bench-inputs-" + std::to_string(::getpid()) + "-" + info->name());
        fs::remove_all(scratch_);
        fs::create_directories(scratch_);
        recording_ = scratch_ / "head";
        const CommandRun synth = bench("synth --head scan --frames " + std::to_string(kRecordedFrames) +
                                       " --no-detect --tum " + quoted(recording_));
        ASSERT_EQ(synth.exit_code, 0) << synth.out;
        ASSERT_TRUE(fs::exists(recording_ / "depth.txt")) << synth.out;
    }
    void TearDown() override {
        if (!scratch_.empty()) fs::remove_all(scratch_);
    }
    std::string tum() const { return "tum:" + recording_.string(); }

    fs::path scratch_, recording_;
};

TEST_F(BenchTumInput, DetectReadsTheRecordingAndWritesOneBoxLinePerFrameAndDetector) {
    const fs::path csv = scratch_ / "boxes.csv";
    const CommandRun run =
        bench("detect --input '" + tum() + "' --frames " + std::to_string(kBenchFrames) + " --boxes " + quoted(csv));
    ASSERT_EQ(run.exit_code, 0) << run.out;
    EXPECT_EQ(run.out.find("unknown source"), std::string::npos) << run.out;
    // The recording's row: its folder name, the frame count after --frames, both detectors' finds.
    EXPECT_TRUE(std::regex_search(run.out, std::regex("\nhead +" + std::to_string(kBenchFrames) + " "))) << run.out;
    EXPECT_NE(run.out.find("no face boxes: a face in"), std::string::npos) << run.out;

    std::ifstream in(csv);
    ASSERT_TRUE(in) << "no --boxes file " << csv;
    std::string header;
    std::getline(in, header);
    EXPECT_EQ(header, "source,frame,timestamp_s,detector,faces,x,y,w,h");
    std::map<int, std::set<std::string>> detectors_per_frame;
    int lines = 0;
    for (std::string line; std::getline(in, line);) {
        ++lines;
        const std::vector<std::string> f = splitCsv(line);
        ASSERT_EQ(f.size(), 9u) << line;
        EXPECT_EQ(f[0], "head") << line;
        const int frame = std::stoi(f[1]);
        EXPECT_NEAR(std::stod(f[2]), frame / 30.0, 1e-3) << "timestamps of a 30 Hz recording: " << line;
        EXPECT_TRUE(detectors_per_frame[frame].insert(f[3]).second) << "a second line for one detector: " << line;
        // A frontal face at 0.7 m: both detectors find it, and the line carries its box.
        EXPECT_GE(std::stoi(f[4]), 1) << line;
        ASSERT_FALSE(f[7].empty()) << line;
        EXPECT_GT(std::stoi(f[7]), 50) << "face box width in pixels: " << line;
    }
    EXPECT_EQ(lines, 2 * kBenchFrames);
    ASSERT_EQ(detectors_per_frame.size(), static_cast<size_t>(kBenchFrames));
    for (const auto& [frame, detectors] : detectors_per_frame) {
        EXPECT_GE(frame, 0);
        EXPECT_LT(frame, kBenchFrames);
        EXPECT_EQ(detectors, (std::set<std::string>{"ours", "stock"})) << "frame " << frame;
    }
}

TEST_F(BenchTumInput, DetectSaysWhatIsMissingInAFolderThatIsNoRecording) {
    const fs::path empty = scratch_ / "not-a-recording";
    fs::create_directories(empty);
    const CommandRun run = bench("detect --input 'tum:" + empty.string() + "'");
    EXPECT_EQ(run.exit_code, 1) << run.out;
    EXPECT_NE(run.out.find("no depth.txt in " + empty.string()), std::string::npos) << run.out;
}

TEST_F(BenchTumInput, CodecsMeasureTheRecordingsDepthAndColour) {
    const CommandRun run =
        bench("codecs --input '" + tum() + "' --frames " + std::to_string(kBenchFrames) + " --repeat 1 --json");
    ASSERT_EQ(run.exit_code, 0) << run.out;
    EXPECT_EQ(run.out.find("no frames"), std::string::npos) << run.out;
    const std::string frames = "(" + std::to_string(kBenchFrames) + " frames 640x480";
    EXPECT_NE(run.out.find("depth: head " + frames), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("colour: head " + frames), std::string::npos) << run.out;
    EXPECT_NE(run.out.find("(default)"), std::string::npos) << "the shipped depth codec's row: " << run.out;
    EXPECT_NE(run.out.find("\"depth\":{\"codec\":\"packed-delta-zstd\",\"set\":\"head\""), std::string::npos)
        << run.out;
}

// The core fuses every pixel when a frame has no mask; a head 0.7 m in front of a wall 1 m behind it spans more
// depth than the 0.39 m volume, which would sit between the two and reject nearly every frame.
TEST_F(BenchTumInput, ReconRefusesATooDeepRecordingWithoutMasksAndSaysWhatToDo) {
    for (const std::string mask : {"", " --mask none"}) {
        const CommandRun run = bench("recon --input '" + tum() + "' --frames " + std::to_string(kBenchFrames) + mask);
        EXPECT_EQ(run.exit_code, 2) << mask << ": " << run.out;
        EXPECT_NE(run.out.find("fused without head masks"), std::string::npos) << run.out;
        EXPECT_NE(run.out.find("spans 0.9"), std::string::npos) << "the head-to-wall depth: " << run.out;
        EXPECT_NE(run.out.find("use --mask pipeline"), std::string::npos) << run.out;
    }
    // The advice works: the server's own head finding fuses every frame of the same recording.
    const CommandRun pipeline =
        bench("recon --input '" + tum() + "' --frames " + std::to_string(kBenchFrames) + " --mask pipeline");
    ASSERT_EQ(pipeline.exit_code, 0) << pipeline.out;
    EXPECT_NE(pipeline.out.find(std::to_string(kBenchFrames) + " frames, preset face"), std::string::npos)
        << pipeline.out;
    EXPECT_NE(pipeline.out.find("rejected 0,"), std::string::npos) << pipeline.out;
}

// --mask none drops a synthetic input's own head label too: the same refusal, not a scan of the label.
TEST(BenchReconMask, NoneDropsTheInputsOwnMasks) {
    const CommandRun with_label = bench("recon --input synthetic:frames=2 --mask input");
    EXPECT_EQ(with_label.exit_code, 0) << with_label.out;
    EXPECT_NE(with_label.out.find("mask: renderer head label"), std::string::npos) << with_label.out;
    const CommandRun none = bench("recon --input synthetic:frames=2 --mask none");
    EXPECT_EQ(none.exit_code, 2) << none.out;
    EXPECT_NE(none.out.find("fused without head masks"), std::string::npos) << none.out;
    const CommandRun bad = bench("recon --input synthetic:frames=2 --mask nothing");
    EXPECT_EQ(bad.exit_code, 2) << bad.out;
    EXPECT_NE(bad.out.find("--mask input|pipeline|none"), std::string::npos) << bad.out;
}

}  // namespace
}  // namespace facescan::testing
