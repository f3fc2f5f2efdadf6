// Agent -> DDS -> a test reader: the real facescan-agent binary streams each source; every depth frame must
// arrive bit-exact and in order, then an end-of-stream sample. Loopback profile, private domain per test.
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <thread>
#include <vector>

#include "capture/frame_source.hpp"
#include "synth/kinect_simulator.hpp"
#include "test_domain.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/messages.hpp"

extern char** environ;

namespace facescan::capture {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

using facescan::testing::privateDomain;

pid_t spawnAgent(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    const std::string bin = FACESCAN_AGENT_BIN;
    argv.push_back(const_cast<char*>(bin.c_str()));
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    pid_t pid = -1;
    if (posix_spawn(&pid, bin.c_str(), nullptr, nullptr, argv.data(), environ) != 0) return -1;
    return pid;
}

// Reads every frame of a source directly: what the agent must deliver.
std::vector<cv::Mat> expectedDepth(const std::string& spec) {
    auto source = openSource(spec, SourceOptions{});
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    std::vector<cv::Mat> frames;
    if (!source.isOk()) return frames;
    CapturedFrame frame;
    while (true) {
        auto got = (*source)->next(frame);
        EXPECT_TRUE(got.isOk()) << got.status().toString();
        if (!got.isOk() || !*got) break;
        frames.push_back(frame.depth_raw.clone());
    }
    return frames;
}

// Streams `spec` through the agent and checks every received depth frame against `expected`. With hold_file, the
// agent runs with --hold-until: it must announce nothing for a second, until the file is created.
void streamAndCompare(const std::string& spec, const std::vector<cv::Mat>& expected, uint32_t salt,
                      const std::vector<std::string>& extra_args = {}, const fs::path& hold_file = {},
                      std::optional<wire::CameraInfoData>* received = nullptr, int ends_wanted = 1) {
    ASSERT_FALSE(expected.empty());
    const uint32_t domain = privateDomain(salt);
    const std::string session = "agent-test-" + std::to_string(salt);
    std::vector<std::string> args = {
        "--source",  spec,    "--profile", "loopback", "--domain",          std::to_string(domain),
        "--session", session, "--rate",    "max",      "--wait-for-server", "30"};
    args.insert(args.end(), extra_args.begin(), extra_args.end());
    if (!hold_file.empty()) args.insert(args.end(), {"--hold-until", hold_file.string()});
    const pid_t agent = spawnAgent(args);
    ASSERT_GT(agent, 0);

    auto participant = wire::Participant::create({domain, "loopback"});
    ASSERT_TRUE(participant.isOk()) << participant.status().toString();
    auto info_topic = wire::Topic<facescan_wire_CameraInfo>::create(*participant);
    auto frame_topic = wire::Topic<facescan_wire_RgbdFrame>::create(*participant);
    ASSERT_TRUE(info_topic.isOk() && frame_topic.isOk());
    auto info_reader = wire::Reader<facescan_wire_CameraInfo>::create(*info_topic);
    // This test plays the session's owning server: it claims the session (the agent streams only to an owner) and
    // reads its frames in the session's partition, where only the owner listens.
    const wire::Qos qos = wire::frameReaderQos();
    auto frame_reader =
        wire::Reader<facescan_wire_RgbdFrame>::create(*frame_topic, &qos, wire::sessionPartition(session));
    ASSERT_TRUE(info_reader.isOk() && frame_reader.isOk());
    auto owner_topic = wire::Topic<facescan_wire_SessionOwner>::create(*participant);
    ASSERT_TRUE(owner_topic.isOk());
    const wire::Qos claim_qos = wire::claimWriterQos(wire::claimStrength(1, "test-owner", session));
    auto claim = wire::Writer<facescan_wire_SessionOwner>::create(*owner_topic, &claim_qos);
    ASSERT_TRUE(claim.isOk());
    wire::SessionOwnerData owner;
    owner.session_id = session;
    owner.owner_id = "test-owner";
    owner.state = wire::OwnerState::kReady;
    ASSERT_TRUE(claim->write(wire::toMessage(owner)).isOk());

    std::optional<wire::CameraInfoData> camera;
    if (!hold_file.empty()) {
        int announced = 0;
        const auto until = std::chrono::steady_clock::now() + 1s;
        while (std::chrono::steady_clock::now() < until) {
            auto n = info_reader->take([&](const facescan_wire_CameraInfo&, const dds_sample_info_t& i) {
                announced += i.valid_data ? 1 : 0;
            });
            ASSERT_TRUE(n.isOk());
            std::this_thread::sleep_for(20ms);
        }
        EXPECT_EQ(announced, 0) << "the agent announced its session before " << hold_file << " existed";
        std::ofstream(hold_file) << "go\n";
    }
    wire::DepthDecoder decoder;
    std::vector<uint32_t> seqs;
    int mismatches = 0;
    int ends = 0;
    std::vector<const facescan_wire_RgbdFrame*> unused;
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    while (ends < ends_wanted && std::chrono::steady_clock::now() < deadline) {
        if (!camera) {
            (void)info_reader->take([&](const facescan_wire_CameraInfo& m, const dds_sample_info_t& i) {
                if (!i.valid_data) return;
                auto parsed = wire::fromMessage(m);
                ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
                camera = *parsed;
            });
            if (!camera) {
                std::this_thread::sleep_for(20ms);
                continue;
            }
        }
        frame_reader->waitForData(200ms);
        auto n = frame_reader->take([&](const facescan_wire_RgbdFrame& m, const dds_sample_info_t& i) {
            if (!i.valid_data) return;
            if (m.end_of_stream) {
                ++ends;
                return;
            }
            seqs.push_back(m.seq);
            cv::Mat depth;
            auto codec = wire::depthCodecFromTag(static_cast<uint32_t>(m.depth_codec));
            ASSERT_TRUE(codec.isOk());
            const Status s = decoder.decode(*codec, m.depth._buffer, m.depth._length, camera->intrinsics.width_px,
                                            camera->intrinsics.height_px, depth);
            ASSERT_TRUE(s.isOk()) << s.toString();
            if (m.seq >= expected.size() || cv::norm(depth, expected[m.seq], cv::NORM_INF) != 0) ++mismatches;
        });
        ASSERT_TRUE(n.isOk());
    }
    // The agent waits for its owner to finish the scan before it exits.
    owner.state = wire::OwnerState::kFinished;
    ASSERT_TRUE(claim->write(wire::toMessage(owner)).isOk());
    int status = 0;
    waitpid(agent, &status, 0);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "agent exit status " << status;
    EXPECT_EQ(ends, ends_wanted) << "end-of-stream samples";
    ASSERT_EQ(seqs.size(), expected.size());
    for (size_t i = 0; i < seqs.size(); ++i) EXPECT_EQ(seqs[i], i) << "out of order at " << i;
    EXPECT_EQ(mismatches, 0) << "depth frames not bit-exact";
    ASSERT_TRUE(camera.has_value());
    EXPECT_EQ(camera->session_id, session);
    EXPECT_TRUE(camera->every_frame);
    if (received) *received = camera;
}

TEST(AgentStream, SyntheticSourceArrivesBitExactAndInOrder) {
    const std::string spec = "synthetic:frames=24,seed=3,subject=builtin";
    const auto expected = expectedDepth(spec);
    ASSERT_EQ(expected.size(), 24u);
    streamAndCompare(spec, expected, 1);
}

// An owner that lost the end of the stream (it went with an owner that had it confirmed, or its write was cut
// short by a takeover) must still learn of it: the agent sends it again while it waits for the finish. Here the
// owner (the test) does not finish after the first one; a second one must come (one a few seconds later).
TEST(AgentStream, TheEndOfTheStreamIsSentAgainWhileTheOwnerHasNotFinished) {
    const std::string spec = "synthetic:frames=6,seed=3,subject=builtin";
    const auto expected = expectedDepth(spec);
    ASSERT_EQ(expected.size(), 6u);
    streamAndCompare(spec, expected, 5, {}, {}, nullptr, /*ends_wanted=*/2);
}

TEST(AgentStream, TumFolderArrivesBitExactAndInOrder) {
    const fs::path dir = fs::temp_directory_path() / ("facescan-tum-" + std::to_string(getpid()));
    synth::SequenceParams seq;
    seq.frames = 16;
    seq.seed = 5;
    const synth::KinectSimulator sim(synth::builtinHead(), seq);
    ASSERT_TRUE(synth::writeTumSequence(sim, dir).isOk());
    const std::string spec = "tum:" + dir.string();
    const auto expected = expectedDepth(spec);
    ASSERT_EQ(expected.size(), 16u);
    // The source reads exactly the PNGs of the folder.
    const cv::Mat first =
        cv::imread((dir / "depth").string() + "/" + fs::directory_iterator(dir / "depth")->path().filename().string(),
                   cv::IMREAD_ANYDEPTH);
    EXPECT_EQ(first.type(), CV_16UC1);
    streamAndCompare(spec, expected, 2);
    // --preload: the whole folder is read first, then the same frames go out in the same order; with --hold-until,
    // only once the file exists.
    const fs::path go = dir / "go";
    streamAndCompare(spec, expected, 3, {"--preload"}, go);
    EXPECT_TRUE(fs::exists(go));
    fs::remove_all(dir);
}

// The camera travels with the stream: the synthetic near-range sensor's description (its range, family and noise)
// arrives in CameraInfo, with --depth-range over it and how the camera is held (--roll); the frames are its own
// 320x240 ones.
TEST(AgentStream, TheCameraArrivesInCameraInfoWithTheAgentsOverrides) {
    const std::string spec = "synthetic:frames=8,seed=3,subject=builtin,sensor=truedepth";
    const auto expected = expectedDepth(spec);
    ASSERT_EQ(expected.size(), 8u);
    EXPECT_EQ(expected.front().cols, 320);
    std::optional<wire::CameraInfoData> camera;
    streamAndCompare(spec, expected, 4, {"--depth-range", "0.2:0.6", "--roll", "30"}, {}, &camera);
    ASSERT_TRUE(camera.has_value());
    EXPECT_EQ(camera->sensor.name, "truedepth");
    EXPECT_EQ(camera->sensor.family, recon::SensorFamily::kStructuredLight);
    EXPECT_FLOAT_EQ(camera->sensor.min_depth_m, 0.2f);
    EXPECT_FLOAT_EQ(camera->sensor.max_depth_m, 0.6f);
    EXPECT_TRUE(camera->sensor.noise.known());
    EXPECT_EQ(camera->intrinsics.width_px, 320);
    EXPECT_EQ(camera->colourIntrinsics(), camera->intrinsics) << "registered colour";
    EXPECT_EQ(camera->roll_deg, 30) << "a slant between quarter turns travels as given";
}

// A live camera: nothing to read ahead.
class LiveSource final : public FrameSource {
 public:
    const SourceInfo& info() const override { return info_; }
    StatusOr<bool> next(CapturedFrame&) override { return true; }

 private:
    SourceInfo info_;  // is_recording = false
};

TEST(Sources, PreloadHoldsEveryFrameOfARecordingAndRefusesALiveCamera) {
    auto live = preloadSource(std::make_unique<LiveSource>());
    ASSERT_FALSE(live.isOk());
    EXPECT_EQ(live.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(live.status().message().find("recording"), std::string::npos) << live.status().message();

    const std::string spec = "synthetic:frames=6,seed=2,subject=builtin";
    const auto expected = expectedDepth(spec);
    auto source = openSource(spec, SourceOptions{});
    ASSERT_TRUE(source.isOk());
    std::vector<int> progress;
    auto preloaded = preloadSource(std::move(*source), [&](int done, int total) {
        progress.push_back(done);
        EXPECT_EQ(total, 6);
    });
    ASSERT_TRUE(preloaded.isOk()) << preloaded.status().toString();
    EXPECT_EQ(progress, (std::vector<int>{1, 2, 3, 4, 5, 6}));
    EXPECT_TRUE((*preloaded)->info().is_recording);
    EXPECT_EQ((*preloaded)->info().expected_frames, 6);
    CapturedFrame frame;
    for (size_t i = 0; i < expected.size(); ++i) {
        auto got = (*preloaded)->next(frame);
        ASSERT_TRUE(got.isOk() && *got) << "frame " << i;
        EXPECT_EQ(frame.index, i);
        EXPECT_EQ(cv::norm(frame.depth_raw, expected[i], cv::NORM_INF), 0) << "frame " << i;
        EXPECT_FALSE(frame.colour_bgr.empty());
    }
    auto end = (*preloaded)->next(frame);
    ASSERT_TRUE(end.isOk());
    EXPECT_FALSE(*end) << "a preloaded recording ends where the recording ended";
}

TEST(Sources, BadSpecsAndMissingInputsGiveClearErrors) {
    auto unknown = openSource("webcam", SourceOptions{});
    ASSERT_FALSE(unknown.isOk());
    EXPECT_NE(unknown.status().message().find("openni2[:URI], oni:FILE, tum:DIR"), std::string::npos);
    EXPECT_EQ(openSource("tum:/nonexistent/folder", SourceOptions{}).status().code(), StatusCode::kNotFound);
    EXPECT_FALSE(openSource("synthetic:frames=abc", SourceOptions{}).isOk());
    EXPECT_FALSE(openSource("synthetic:colour=1", SourceOptions{}).isOk());
    EXPECT_FALSE(openSource("oni:", SourceOptions{}).isOk());
}

TEST(Sources, TumSourceRejectsMalformedListsAndImages) {
    const fs::path dir = fs::temp_directory_path() / ("facescan-badtum-" + std::to_string(getpid()));
    fs::create_directories(dir);
    { std::ofstream(dir / "depth.txt") << "# comment\n0.0 depth/missing.png\n"; }
    EXPECT_EQ(openSource("tum:" + dir.string(), SourceOptions{}).status().code(), StatusCode::kDataLoss);
    { std::ofstream(dir / "depth.txt") << "not-a-number\n"; }
    EXPECT_FALSE(openSource("tum:" + dir.string(), SourceOptions{}).isOk());
    fs::remove_all(dir);
}

TEST(Sources, SyntheticSourceHonoursFrameLimitAndColourSwitch) {
    SourceOptions options;
    options.colour = false;
    options.max_frames = 5;
    auto source = openSource("synthetic:frames=50,subject=builtin", options);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->info().expected_frames, 5);
    EXPECT_FALSE((*source)->info().has_colour);
    CapturedFrame frame;
    int count = 0;
    while (true) {
        auto got = (*source)->next(frame);
        ASSERT_TRUE(got.isOk());
        if (!*got) break;
        EXPECT_TRUE(frame.colour_bgr.empty());
        EXPECT_EQ(frame.depth_raw.type(), CV_16UC1);
        EXPECT_EQ(frame.index, static_cast<uint32_t>(count));
        ++count;
    }
    EXPECT_EQ(count, 5);
}

}  // namespace
}  // namespace facescan::capture
