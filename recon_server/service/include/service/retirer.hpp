// Where a session's endpoints end. Ending them can wait: deleting a DDS reader waits for Cyclone's garbage collector,
// which waits for every DDS call in flight in the process (a reliable write blocked on a slow peer holds it for up
// to its max_blocking_time); stopping a Session joins its worker, which may be in the middle of a frame. The intake
// thread, which makes the cluster's decisions and asserts this server's liveliness, must never wait for either,
// and a Session must never be destroyed on its own worker thread (joining itself aborts the process). So every path
// that gives up a session's endpoints (yield, release, finish, shutdown) hands them here, and one thread ends them
// in the order they were handed over, under the watchdog like every other loop.
#pragma once

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
    // From a job: what it does now (a string literal), named if it hangs (Watchdog::Beat::note).
    void note(const char* doing) {
        if (beat_) beat_->note(doing);
    }

 private:
    void loop();

    std::shared_ptr<Watchdog::Beat> beat_;
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::deque<std::function<void()>> jobs_;
    bool stopping_ = false;
    std::thread thread_;
};

}  // namespace facescan::service
