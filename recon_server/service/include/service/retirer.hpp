// Where a session's endpoints end. Ending them can wait: deleting a DDS reader waits for Cyclone's garbage collector,
// which waits for every DDS call in flight in the process (a reliable write blocked on a slow peer holds it for up
// to its max_blocking_time); stopping a Session joins its worker, which may be in the middle of a frame. The intake
// thread, which makes the cluster's decisions and asserts this server's liveliness, must never wait for either,
// and a Session must never be destroyed on its own worker thread (joining itself aborts the process). So every path
// that gives up a session's endpoints (yield, release, finish, shutdown) hands them here, and one thread ends them
// in the order they were handed over, under the watchdog like every other loop.
//
// Some endpoints must not end yet: a session's frame reader that its agent still writes to (Cyclone 0.10 delivers
// to a full keep-all reader by retrying on its receive thread, which then never lets the garbage collector on, and
// the reader's deletion waits for that collector: a deadlock). Those linger here, looked after every
// kLingerPeriod, until they can end.
#pragma once

#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "service/watchdog.hpp"

namespace facescan::service {

class Retirer {
 public:
    explicit Retirer(std::shared_ptr<Watchdog::Beat> beat);
    ~Retirer();  // ends whatever is still queued, then joins
    Retirer(const Retirer&) = delete;
    Retirer& operator=(const Retirer&) = delete;

    // Runs `end` on the retiring thread, after everything handed over before it. `end` and whatever it captured
    // are destroyed there too.
    void retire(std::function<void()> end);
    // After everything handed over before it, calls `step` on the retiring thread every kLingerPeriod until it
    // returns true; `step` and whatever it captured are then destroyed there. On shutdown each lingering step
    // runs once more and is destroyed, done or not.
    void linger(std::function<bool()> step);
    static constexpr std::chrono::milliseconds kLingerPeriod{50};
    // From a job: what it does now (a string literal), named if it hangs (Watchdog::Beat::note).
    void note(const char* doing) {
        if (beat_) beat_->note(doing);
    }

 private:
    void loop();
    void runLingering(bool final_turn);  // the retiring thread only

    std::shared_ptr<Watchdog::Beat> beat_;
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::deque<std::function<void()>> jobs_;
    std::deque<std::function<bool()>> lingering_;  // the retiring thread only
    std::chrono::steady_clock::time_point next_linger_;
    bool stopping_ = false;
    std::thread thread_;
};

}  // namespace facescan::service
