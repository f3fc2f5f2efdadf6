// A stuck server is a dead server. DDS keeps a process "alive" as long as its own threads run, so a server whose
// intake or a session's worker hangs (a blocked call, a lock never released) would hold its sessions for ever. Every
// loop that does the server's work holds a Beat: it marks when it starts a step and when it goes back to waiting.
// The watchdog's thread looks at the beats; a loop that stays in one step beyond the stall limit means this process
// no longer makes progress, and the watchdog calls on_stall (the server logs it and exits non-zero, so that the
// service manager restarts it while the cluster takes its sessions over).
#pragma once

#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace facescan::service {

class Watchdog {
 public:
    class Beat {
     public:
        Beat(std::string name, double limit_s) : name_(std::move(name)), limit_s_(limit_s) {}
        void begin();  // a step starts now: it must end within the stall limit
        // A step known to be long (a scan's finish, on a loaded machine at a lower priority) that must end within
        // this many seconds instead; the next begin() goes back to the usual limit.
        void beginLong(double limit_s);
        void end();  // back to waiting for work: not expected to progress
        // Names what the current step is doing now (a string literal, kept by pointer), for the stall's message:
        // a step of several calls says which one hung. begin() and end() clear it.
        void note(const char* doing) { doing_.store(doing, std::memory_order_relaxed); }
        const char* doing() const { return doing_.load(std::memory_order_relaxed); }
        int64_t busySinceNs() const { return since_ns_.load(std::memory_order_relaxed); }
        const std::string& name() const { return name_; }
        // 0: the watchdog's stall limit
        double limitS() const {
            const double step = step_limit_s_.load(std::memory_order_relaxed);
            return step > 0 ? step : limit_s_;
        }

     private:
        std::string name_;
        double limit_s_ = 0;
        std::atomic<double> step_limit_s_{0};  // this step's own limit (beginLong); 0: limit_s_
        std::atomic<int64_t> since_ns_{0};     // steady clock; 0 while waiting
        std::atomic<const char*> doing_{nullptr};
    };

    struct Options {
        double stall_limit_s = 20.0;  // seconds one step may take before the process counts as stuck
        double period_s = 0.25;       // seconds between checks
        // seconds: a check this late means the whole process did not run (SIGSTOP, a paused VM). The watchdog's
        // thread does no work of its own, so unlike a busy loop its lateness is time the process was frozen.
        double pause_gap_s = 1.0;
    };
    // on_pause(gap_ns, now_ns) is called from the watchdog's thread when it wakes from such a pause.
    Watchdog(Options options, std::function<void(const std::string& what)> on_stall,
             std::function<void(int64_t gap_ns, int64_t now_ns)> on_pause = nullptr);
    ~Watchdog();  // stop()
    Watchdog(const Watchdog&) = delete;
    Watchdog& operator=(const Watchdog&) = delete;

    // A beat for one loop; it is watched while anybody holds it. `limit_s` (0: the stall limit) for a loop whose
    // steps may take longer without holding up the server's work.
    std::shared_ptr<Beat> add(std::string name, double limit_s = 0);
    // Steady clock of the watchdog's last check. Older than pause_gap_s: the process may have just woken from a
    // pause that the watchdog has not seen yet.
    int64_t lastCheckNs() const { return last_check_ns_.load(std::memory_order_relaxed); }
    // The first loop that has been in one step beyond the limit ("the intake thread has been in one step for
    // 21.3 s"), else nullopt.
    std::optional<std::string> stalled(int64_t now_ns) const;

    void start();
    void stop();

 private:
    void loop();

    Options options_;
    std::function<void(const std::string&)> on_stall_;
    std::function<void(int64_t, int64_t)> on_pause_;
    std::atomic<int64_t> last_check_ns_{0};
    mutable std::mutex mutex_;
    std::vector<std::weak_ptr<Beat>> beats_;
    // When this process last woke from a pause (SIGSTOP, a VM paused): the watchdog's own thread was frozen too, so
    // a step that was under way then is timed from the wake, not from before the pause.
    std::atomic<int64_t> resumed_ns_{0};
    std::condition_variable cv_;
    bool stopping_ = false;
    std::thread thread_;
};

}  // namespace facescan::service
