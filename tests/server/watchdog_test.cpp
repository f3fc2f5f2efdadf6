// The server's watchdog and retiring thread (watchdog.hpp, retirer.hpp), in process: a loop stuck in one step is
// reported with its name, one that waits is not, and retired things end on the retiring thread in order; a Session
// retired there never joins its own worker.
#include "service/watchdog.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>
#include <vector>

#include "service/retirer.hpp"
#include "service/session.hpp"

namespace facescan::service {
namespace {

using namespace std::chrono_literals;

TEST(Watchdog, ALoopStuckInOneStepIsReportedByNameAndAWaitingOneIsNot) {
    Watchdog::Options options;
    options.stall_limit_s = 0.3;
    options.period_s = 0.05;
    std::mutex mutex;
    std::vector<std::string> said;
    Watchdog watchdog(options, [&](const std::string& what) {
        std::lock_guard lk(mutex);
        said.push_back(what);
    });
    const auto waiting = watchdog.add("the waiting loop");
    const auto stuck = watchdog.add("the stuck loop");
    waiting->begin();
    waiting->end();  // back to waiting: not expected to progress, however long it waits
    stuck->begin();
    EXPECT_FALSE(watchdog.stalled(steadyNowNs()).has_value());  // within the limit
    watchdog.start();
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    for (;;) {
        {
            std::lock_guard lk(mutex);
            if (!said.empty()) break;
        }
        ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "the watchdog never reported the stuck loop";
        std::this_thread::sleep_for(20ms);
    }
    watchdog.stop();
    std::lock_guard lk(mutex);
    ASSERT_EQ(said.size(), 1u);
    EXPECT_NE(said[0].find("the stuck loop has been in one step for"), std::string::npos) << said[0];
    // A step of several calls names the one it is in.
    stuck->note("deleting a reader");
    const std::optional<std::string> doing = watchdog.stalled(steadyNowNs() + 3'000'000'000);
    ASSERT_TRUE(doing.has_value());
    EXPECT_NE(doing->find("the stuck loop has been in one step (deleting a reader) for"), std::string::npos) << *doing;
    stuck->end();
    EXPECT_FALSE(watchdog.stalled(steadyNowNs() + 3'000'000'000).has_value());
}

// A scan's finish on a loaded machine is one long step: it gets its own limit, and the next step the usual one.
TEST(Watchdog, ALongStepHasItsOwnLimitAndTheNextStepTheUsualOne) {
    Watchdog watchdog({1.0, 0.05}, [](const std::string&) {});
    const auto worker = watchdog.add("a session's worker");
    worker->beginLong(30.0);
    EXPECT_FALSE(watchdog.stalled(steadyNowNs() + 10'000'000'000).has_value());  // 10 s into a 30 s step
    EXPECT_TRUE(watchdog.stalled(steadyNowNs() + 31'000'000'000).has_value());
    worker->begin();
    EXPECT_TRUE(watchdog.stalled(steadyNowNs() + 2'000'000'000).has_value());  // back to 1 s
}

TEST(Watchdog, ABeatNobodyHoldsIsNotWatched) {
    Watchdog watchdog({0.1, 0.05}, [](const std::string&) {});
    {
        const auto gone = watchdog.add("a session's worker that ended");
        gone->begin();
    }
    EXPECT_FALSE(watchdog.stalled(steadyNowNs() + 1'000'000'000).has_value());
}

TEST(Retirer, EndsWhatItIsGivenOnItsOwnThreadInOrder) {
    Watchdog watchdog({5.0, 0.05}, [](const std::string&) {});
    std::vector<int> order;
    std::mutex mutex;
    std::atomic<bool> other_thread{true};
    const auto caller = std::this_thread::get_id();
    {
        Retirer retirer(watchdog.add("the retiring thread"));
        for (int i = 0; i < 5; ++i) {
            retirer.retire([&, i] {
                std::lock_guard lk(mutex);
                order.push_back(i);
                if (std::this_thread::get_id() == caller) other_thread = false;
            });
        }
    }  // the destructor ends what is still queued
    EXPECT_EQ(order, (std::vector<int>{0, 1, 2, 3, 4}));
    EXPECT_TRUE(other_thread.load());
}

TEST(Retirer, ASessionGivenUpEndsWithoutFinishingOrAnsweringAndWithoutJoiningItself) {
    // A session abandoned and retired: its worker stops, nothing is finished (no files), and a waiting finish is
    // dropped unanswered. Before the retiring thread, a session given up was finished through a callback that
    // held the last reference, so its destructor ran on its own worker and the process aborted.
    ServerParams params;
    params.data_dir = std::filesystem::temp_directory_path() / ("facescan-retire-" + std::to_string(::getpid()));
    Watchdog watchdog({5.0, 0.05}, [](const std::string&) {});
    auto session = std::make_shared<Session>("given-up", params, nullptr);
    session->setWatch(watchdog.add("the worker"), [] { return false; });
    std::atomic<int> answered{0};
    session->abandon();
    session->requestFinish("a finish nobody answers here", [&](const Status&, const MeshResult&) { ++answered; });
    {
        Retirer retirer(watchdog.add("the retiring thread"));
        retirer.retire([held = std::move(session)]() mutable { held.reset(); });
    }
    EXPECT_EQ(answered.load(), 0);
    EXPECT_FALSE(std::filesystem::exists(params.data_dir / "given-up" / "summary.json"));
    std::filesystem::remove_all(params.data_dir);
}

}  // namespace
}  // namespace facescan::service
