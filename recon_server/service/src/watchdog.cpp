#include "service/watchdog.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "recon/parallel.hpp"
#include "service/session.hpp"

namespace facescan::service {

void Watchdog::Beat::begin() { beginLong(0); }
void Watchdog::Beat::beginLong(double limit_s) {
    step_limit_s_.store(limit_s, std::memory_order_relaxed);
    doing_.store(nullptr, std::memory_order_relaxed);
    since_ns_.store(steadyNowNs(), std::memory_order_relaxed);
}
void Watchdog::Beat::end() {
    since_ns_.store(0, std::memory_order_relaxed);
    doing_.store(nullptr, std::memory_order_relaxed);
}

Watchdog::Watchdog(Options options, std::function<void(const std::string&)> on_stall,
                   std::function<void(int64_t, int64_t)> on_pause)
    : options_(options), on_stall_(std::move(on_stall)), on_pause_(std::move(on_pause)) {
    last_check_ns_ = steadyNowNs();
}

Watchdog::~Watchdog() { stop(); }

std::shared_ptr<Watchdog::Beat> Watchdog::add(std::string name, double limit_s) {
    auto beat = std::make_shared<Beat>(std::move(name), limit_s);
    std::lock_guard lk(mutex_);
    std::erase_if(beats_, [](const std::weak_ptr<Beat>& b) { return b.expired(); });
    beats_.push_back(beat);
    return beat;
}

std::optional<std::string> Watchdog::stalled(int64_t now_ns) const {
    std::lock_guard lk(mutex_);
    for (const std::weak_ptr<Beat>& weak : beats_) {
        const std::shared_ptr<Beat> beat = weak.lock();
        if (!beat) continue;
        int64_t since = beat->busySinceNs();
        if (since == 0) continue;
        since = std::max(since, resumed_ns_.load(std::memory_order_relaxed));
        const double limit_s = beat->limitS() > 0 ? beat->limitS() : options_.stall_limit_s;
        if (now_ns - since <= static_cast<int64_t>(limit_s * 1e9)) continue;
        char what[320];
        const char* doing = beat->doing();
        std::snprintf(what, sizeof what, "%s has been in one step%s%s%s for %.1f s (the limit is %.1f s)",
                      beat->name().c_str(), doing ? " (" : "", doing ? doing : "", doing ? ")" : "",
                      static_cast<double>(now_ns - since) * 1e-9, limit_s);
        return std::string(what);
    }
    return std::nullopt;
}

void Watchdog::start() {
    std::lock_guard lk(mutex_);
    if (thread_.joinable()) return;
    stopping_ = false;
    thread_ = std::thread([this] { loop(); });
}

void Watchdog::stop() {
    {
        std::lock_guard lk(mutex_);
        stopping_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
}

void Watchdog::loop() {
    recon::nameThisThread("fs-watchdog");
    const auto period = std::chrono::duration<double>(options_.period_s);
    // A check this much later than planned: the whole process was frozen (every thread, this one too).
    const auto pause_ns = static_cast<int64_t>(options_.pause_gap_s * 1e9);
    const auto period_ns = static_cast<int64_t>(options_.period_s * 1e9);
    last_check_ns_ = steadyNowNs();
    std::unique_lock lk(mutex_);
    while (!cv_.wait_for(lk, period, [&] { return stopping_; })) {
        lk.unlock();
        const int64_t now_ns = steadyNowNs();
        const int64_t gap_ns = now_ns - last_check_ns_.load(std::memory_order_relaxed) - period_ns;
        if (gap_ns >= pause_ns) {
            resumed_ns_.store(now_ns, std::memory_order_relaxed);
            if (on_pause_) on_pause_(gap_ns + period_ns, now_ns);
        }
        last_check_ns_.store(now_ns, std::memory_order_relaxed);
        if (const std::optional<std::string> what = stalled(steadyNowNs())) {
            on_stall_(*what);
            lk.lock();
            return;  // once: the server exits, or a test looks at what was said
        }
        lk.lock();
    }
}

}  // namespace facescan::service
