#include "service/frame_load.hpp"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>

#include "recon/parallel.hpp"

namespace facescan::service {
namespace {

std::atomic<int> g_running_workers{0};

int64_t threadCpuNs() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

FrameLoad::FrameLoad(float source_rate_hz) : period_ms_(1000.0f / (source_rate_hz > 0 ? source_rate_hz : 30.0f)) {}

FrameLoad::~FrameLoad() {
    // Normally the worker left already. Its thread may be gone, and its id reused: touch no priority here.
    if (joined_) g_running_workers.fetch_sub(1, std::memory_order_relaxed);
}

int FrameLoad::runningWorkers() { return g_running_workers.load(std::memory_order_relaxed); }

float FrameLoad::budgetMs() const {
    return period_ms_ * static_cast<float>(recon::parallelThreadCount()) /
           static_cast<float>(std::max(1, runningWorkers()));
}

void FrameLoad::join() {
    if (joined_) return;
    joined_ = true;
    tid_ = static_cast<int>(syscall(SYS_gettid));
    base_nice_ = getpriority(PRIO_PROCESS, static_cast<id_t>(tid_));  // the server may run niced as a whole
    g_running_workers.fetch_add(1, std::memory_order_relaxed);
    recon::setParallelAccounting(true);
}

void FrameLoad::leave() {
    if (!joined_) return;
    throttle(false);
    recon::setParallelAccounting(false);
    g_running_workers.fetch_sub(1, std::memory_order_relaxed);
    joined_ = false;
}

void FrameLoad::beginFrame() {
    thread_cpu0_ns_ = threadCpuNs();
    pool_cpu0_ns_ = recon::parallelPoolCpuNs();
}

void FrameLoad::endFrame() {
    const int64_t cpu_ns = (threadCpuNs() - thread_cpu0_ns_) + (recon::parallelPoolCpuNs() - pool_cpu0_ns_);
    const float ms = static_cast<float>(cpu_ns) * 1e-6f;
    cost_ms_ = first_ ? ms : cost_ms_ + kEmaAlpha * (ms - cost_ms_);
    first_ = false;
    if (!joined_) return;
    const float budget = budgetMs();
    const bool alone = runningWorkers() <= 1;  // nobody to protect: use the whole machine
    if (!throttled_ && !alone && cost_ms_ > budget) throttle(true);
    if (throttled_ && (alone || cost_ms_ < kReleaseFraction * budget)) throttle(false);
}

void FrameLoad::throttle(bool on) {
    if (on == throttled_) return;
    throttled_ = on;
    recon::setParallelSerial(on);
    // Raising the nice value is always allowed; lowering it back needs CAP_SYS_NICE or RLIMIT_NICE. Without them a
    // released worker stays at kThrottledNice (it still gets idle cores) but keeps the whole pool again.
    (void)setpriority(PRIO_PROCESS, static_cast<id_t>(tid_), base_nice_ + (on ? kThrottledNice : 0));
}

}  // namespace facescan::service
