// The real facescan-agent against a test that plays its session's owner, on a private loopback domain: an owner
// that stops taking frames is reported and does not keep the agent from stopping within 2 s of SIGTERM; the
// frames no owner confirmed are saved as a TUM folder that `--source tum:DIR` streams again, bit-exact.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <regex>
#include <thread>
#include <vector>

#include "capture/frame_source.hpp"
#include "capture/tum_recorder.hpp"
#include "child_process.hpp"
#include "fake_owner.hpp"
#include "must.hpp"
#include "test_domain.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/messages.hpp"

namespace facescan::capture {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using facescan::testing::ChildProcess;
using facescan::testing::privateDomain;
using facescan::testing::readText;

using facescan::testing::FakeOwner;
using facescan::testing::must;

std::vector<cv::Mat> expectedDepth(const std::string& spec) {
    auto source = openSource(spec, SourceOptions{});
    EXPECT_TRUE(source.isOk()) << source.status().toString();
    std::vector<cv::Mat> frames;
    CapturedFrame frame;
    while (source.isOk()) {
        auto got = (*source)->next(frame);
        EXPECT_TRUE(got.isOk()) << got.status().toString();
        if (!got.isOk() || !*got) break;
        frames.push_back(frame.depth_raw.clone());
    }
    return frames;
}

class AgentStop : public ::testing::Test {
 protected:
    void SetUp() override {
        const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        dir_ = fs::temp_directory_path() / ("facescan-agent-stop-" + std::to_string(getpid()) + "-" + name);
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override {
        if (!HasFailure()) fs::remove_all(dir_);
    }
    std::unique_ptr<ChildProcess> startAgent(uint32_t domain, const std::string& session, const std::string& source,
                                             const std::vector<std::string>& extra = {}) {
        std::vector<std::string> args = {FACESCAN_AGENT_BIN,
                                         "--source",
                                         source,
                                         "--profile",
                                         "loopback",
                                         "--domain",
                                         std::to_string(domain),
                                         "--session",
                                         session,
                                         "--rate",
                                         "max",
                                         "--wait-for-server",
                                         "60",
                                         "--save-dir",
                                         (dir_ / "saved").string()};
        args.insert(args.end(), extra.begin(), extra.end());
        return std::make_unique<ChildProcess>(args, dir_ / (session + ".log"));
    }
    // SIGTERM, then the seconds until the agent exited (its exit code in `code`).
    static double terminate(ChildProcess& agent, int& code) {
        const auto sent = Clock::now();
        agent.signal(SIGTERM);
        code = agent.wait(30s);
        const double exit_s = std::chrono::duration<double>(Clock::now() - sent).count();
        std::printf("the agent exited %.2f s after SIGTERM\n", exit_s);
        return exit_s;
    }
    // The folder the agent says it saved `frames` frames to (empty when it said nothing of the kind).
    static fs::path savedFolder(const std::string& log, int& frames) {
        std::smatch m;
        static const std::regex line("saved the ([0-9]+) frames no server confirmed .* to ([^ ]+): replay them");
        if (!std::regex_search(log, m, line)) return {};
        frames = std::stoi(m[1]);
        return m[2].str();
    }
    fs::path dir_;
};

bool waitForLog(const fs::path& log, const std::string& text, std::chrono::seconds timeout) {
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
        if (readText(log).find(text) != std::string::npos) return true;
        std::this_thread::sleep_for(50ms);
    }
    return false;
}

TEST_F(AgentStop, AnOwnerThatStopsTakingFramesIsReportedAndSigtermStillEndsTheAgentWithin2s) {
    const uint32_t domain = privateDomain(1);
    const std::string session = "stuck-" + std::to_string(getpid());
    const std::string spec = "synthetic:frames=200,seed=4,subject=builtin";
    FakeOwner owner(domain, session, /*reader_samples=*/2);  // never takes a frame
    auto agent = startAgent(domain, session, spec, {"--stalled-after", "1"});
    const fs::path log = dir_ / (session + ".log");
    ASSERT_TRUE(waitForLog(log, "server '" + owner.data.owner_id + "' has stopped taking frames", 60s))
        << readText(log);
    // The status line (once a second) says it too.
    ASSERT_TRUE(waitForLog(log, "| WAITING: server '" + owner.data.owner_id + "' has stopped taking frames", 5s))
        << readText(log);

    int code = -1;
    const double exit_s = terminate(*agent, code);
    const std::string text = readText(log);
    EXPECT_EQ(code, 0) << text;
    EXPECT_LT(exit_s, 2.0) << text;
    // Nothing was confirmed: what it sent, and what it had captured for sending, is on disk in order.
    int frames = 0;
    const fs::path saved = savedFolder(text, frames);
    ASSERT_FALSE(saved.empty()) << text;
    EXPECT_GT(frames, 0);
    EXPECT_EQ(saved.parent_path(), dir_ / "saved");
    const auto expected = expectedDepth(spec);
    const auto replayed = expectedDepth("tum:" + saved.string());
    ASSERT_EQ(replayed.size(), static_cast<size_t>(frames));
    for (size_t i = 0; i < replayed.size(); ++i) {
        EXPECT_EQ(cv::norm(replayed[i], expected[i], cv::NORM_INF), 0) << "frame " << i;
    }
}

TEST_F(AgentStop, UnconfirmedFramesAreSavedAndReplayIntoAnotherOwnerBitExact) {
    const uint32_t domain = privateDomain(2);
    const std::string session = "unconfirmed-" + std::to_string(getpid());
    const std::string spec = "synthetic:frames=24,seed=3,subject=builtin";
    const auto expected = expectedDepth(spec);
    ASSERT_EQ(expected.size(), 24u);
    FakeOwner owner(domain, session);
    auto agent = startAgent(domain, session, spec);
    const auto received = owner.takeUntilEnd(60s);
    ASSERT_EQ(received.size(), expected.size());
    // The owner confirms the first 10 and never finishes the scan.
    constexpr uint32_t kConfirmed = 10;
    owner.data.confirmed_seq = kConfirmed;
    owner.claim();
    std::this_thread::sleep_for(500ms);  // the agent reads claims every 20 ms
    int code = -1;
    const double exit_s = terminate(*agent, code);
    const std::string text = readText(dir_ / (session + ".log"));
    EXPECT_EQ(code, 0) << text;
    EXPECT_LT(exit_s, 2.0) << text;
    int frames = 0;
    const fs::path saved = savedFolder(text, frames);
    ASSERT_FALSE(saved.empty()) << text;
    EXPECT_EQ(frames, 24 - static_cast<int>(kConfirmed)) << text;
    EXPECT_NE(text.find("(frames 10-23 of session " + session + ")"), std::string::npos) << text;
    EXPECT_TRUE(fs::exists(saved / "intrinsics.txt"));
    // The saved frames are a face: owner-only folders and files, whatever the agent's umask.
    const auto mode = [](const fs::path& p) {
        struct stat st {};
        return ::lstat(p.c_str(), &st) == 0 ? st.st_mode & 07777 : 0u;
    };
    EXPECT_EQ(mode(saved.parent_path()), 0700u) << saved.parent_path();
    EXPECT_EQ(mode(saved), 0700u) << saved;
    int private_files = 0;
    for (const auto& entry : fs::recursive_directory_iterator(saved)) {
        EXPECT_EQ(mode(entry.path()), entry.is_directory() ? 0700u : 0600u) << entry.path();
        private_files += entry.is_regular_file() ? 1 : 0;
    }
    EXPECT_GE(private_files, frames + 2) << "a depth image per frame, depth.txt and intrinsics.txt";

    // Another agent streams the folder into another owner: the same frames, bit-exact, in order.
    const std::string replay_session = "replay-" + std::to_string(getpid());
    FakeOwner second(domain, replay_session);
    auto replay = startAgent(domain, replay_session, "tum:" + saved.string());
    const auto again = second.takeUntilEnd(60s);
    second.data.state = wire::OwnerState::kFinished;
    second.claim();
    EXPECT_EQ(replay->wait(30s), 0) << readText(dir_ / (replay_session + ".log"));
    ASSERT_EQ(again.size(), expected.size() - kConfirmed);
    for (size_t i = 0; i < again.size(); ++i) {
        EXPECT_EQ(again[i].first, i);
        EXPECT_EQ(cv::norm(again[i].second, expected[kConfirmed + i], cv::NORM_INF), 0) << "frame " << i;
    }
    EXPECT_EQ(readText(dir_ / (replay_session + ".log")).find("saved the"), std::string::npos)
        << "a finished scan leaves nothing to save";
}

// Frames captured but still queued when the stop comes are never sent: the end of the stream follows the last
// frame sent (a recording's owner takes frames in order only: a later seq would make it wait for the rest), and
// the saved folder has every frame from the first unconfirmed one to the last captured.
TEST_F(AgentStop, CtrlCMidStreamEndsTheStreamAfterTheLastFrameSentAndSavesEveryFrameNotConfirmed) {
    const uint32_t domain = privateDomain(4);
    const std::string session = "midstream-" + std::to_string(getpid());
    const std::string spec = "synthetic:frames=200,seed=6,subject=builtin";
    const auto expected = expectedDepth(spec);
    FakeOwner owner(domain, session);
    auto agent = startAgent(domain, session, spec);
    auto received = owner.takeUntilEnd(60s, 15, 100ms);  // a slow server: the agent's queue fills up
    ASSERT_EQ(received.size(), 15u);
    int code = -1;
    const auto sent = Clock::now();
    agent->signal(SIGINT);
    const auto rest = owner.takeUntilEnd(10s);
    received.insert(received.end(), rest.begin(), rest.end());
    code = agent->wait(30s);
    const double exit_s = std::chrono::duration<double>(Clock::now() - sent).count();
    const std::string text = readText(dir_ / (session + ".log"));
    EXPECT_EQ(code, 0) << text;
    EXPECT_LT(exit_s, 2.0) << text;
    ASSERT_TRUE(owner.end_seq.has_value()) << text;
    for (size_t i = 0; i < received.size(); ++i) ASSERT_EQ(received[i].first, i);
    EXPECT_EQ(*owner.end_seq, received.size()) << "the end of the stream must follow the last frame sent";
    int frames = 0;
    const fs::path saved = savedFolder(text, frames);
    ASSERT_FALSE(saved.empty()) << text;
    EXPECT_GE(static_cast<size_t>(frames), received.size()) << text;
    const auto replayed = expectedDepth("tum:" + saved.string());
    ASSERT_EQ(replayed.size(), static_cast<size_t>(frames));
    for (size_t i = 0; i < replayed.size(); ++i) {
        EXPECT_EQ(cv::norm(replayed[i], expected[i], cv::NORM_INF), 0) << "frame " << i;
    }
}

TEST_F(AgentStop, CtrlCEndsAnAgentWaitingForAServerAndASecondCtrlCEndsAStuckOneAtOnce) {
    const uint32_t domain = privateDomain(3);
    const std::string waiting = "waiting-" + std::to_string(getpid());
    auto lonely = startAgent(domain, waiting, "synthetic:frames=20,subject=builtin");
    ASSERT_TRUE(waitForLog(dir_ / (waiting + ".log"), "waiting for one", 30s)) << readText(dir_ / (waiting + ".log"));
    auto sent = Clock::now();
    lonely->signal(SIGINT);
    EXPECT_EQ(lonely->wait(10s), 0);
    EXPECT_LT(std::chrono::duration<double>(Clock::now() - sent).count(), 2.0);

    const std::string session = "twice-" + std::to_string(getpid());
    FakeOwner owner(domain, session, /*reader_samples=*/2);
    auto agent = startAgent(domain, session, "synthetic:frames=200,subject=builtin", {"--stalled-after", "1"});
    const fs::path log = dir_ / (session + ".log");
    ASSERT_TRUE(waitForLog(log, "has stopped taking frames", 60s)) << readText(log);
    sent = Clock::now();
    agent->signal(SIGINT);
    std::this_thread::sleep_for(50ms);
    agent->signal(SIGINT);
    EXPECT_EQ(agent->wait(10s), 130) << readText(log);
    EXPECT_LT(std::chrono::duration<double>(Clock::now() - sent).count(), 1.0);
    EXPECT_NE(readText(log).find("second signal: exiting at once"), std::string::npos) << readText(log);
}

TEST_F(AgentStop, SavingNeverOverwritesAFolder) {
    const fs::path parent = dir_ / "saved";
    auto first = createFreshDir(parent, "s1");
    ASSERT_TRUE(first.isOk()) << first.status().toString();
    EXPECT_EQ(*first, parent / "s1");
    std::ofstream(*first / "keep.txt") << "a scan's frames\n";
    auto second = createFreshDir(parent, "s1");
    ASSERT_TRUE(second.isOk()) << second.status().toString();
    EXPECT_EQ(*second, parent / "s1-2");
    SourceInfo info;
    EXPECT_EQ(TumRecorder::create(*first, info).status().code(), StatusCode::kAlreadyExists);
    EXPECT_EQ(readText(*first / "keep.txt"), "a scan's frames\n");
}

}  // namespace
}  // namespace facescan::capture
