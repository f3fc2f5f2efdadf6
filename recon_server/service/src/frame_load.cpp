#include "service/frame_load.hpp"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>

#include "recon/parallel.hpp"
#include "recon/reconstructor.hpp"

namespace facescan::service {
namespace {

std::atomic<int> g_running_workers{0};
// How many running workers are at each economy step: a worker that joins starts at the deepest one in use.
std::array<std::atomic<int>, FrameLoad::kEconomySteps> g_at_step{};
// The host's recent CPU a frame at each economy step, as the last session to settle there measured it (0: not yet
// measured since the workers last all left). A session that joins, or sees one join, predicts its step from these.
std::array<std::atomic<float>, FrameLoad::kEconomySteps> g_step_cost_ms{};

int64_t threadCpuNs() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

FrameLoad::FrameLoad(float source_rate_hz) : period_ms_(1000.0f / (source_rate_hz > 0 ? source_rate_hz : 30.0f)) {}

FrameLoad::~FrameLoad() {
    // Normally the worker left already. Its thread may be gone, and its id reused: touch no priority here.
    if (!joined_) return;
    g_running_workers.fetch_sub(1, std::memory_order_relaxed);
    g_at_step[static_cast<size_t>(economy_)].fetch_sub(1, std::memory_order_relaxed);
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
    recon::setParallelAccounting(true);
    // Beside running sessions, start at the deepest step one of them needs (with one more session each one's share
    // only shrinks), or deeper where the costs they measured say this share needs it. A session that started at full
    // skipped its first second of frames while it found its step; one that started at the deepest step in use still
    // spent its first 25 frames above its step (warm-up, then kStepDownFrames), where most of four sessions' skipped
    // frames and slowest poses fell (tests/bench/server_realtime.sh). It probes the steps above after the hold, as any
    // session does.
    int deepest = 0;
    for (int s = 0; s < kEconomySteps; ++s) {
        if (g_at_step[static_cast<size_t>(s)].load(std::memory_order_relaxed) > 0) deepest = s;
    }
    const int running = g_running_workers.fetch_add(1, std::memory_order_relaxed) + 1;
    if (running > 1) deepest = std::max(deepest, stepToFit(kStepDownFraction * budgetMs()));
    economy_ = deepest;
    predicted_ = economy_ > 0;
    g_at_step[static_cast<size_t>(economy_)].fetch_add(1, std::memory_order_relaxed);
}

int FrameLoad::stepToFit(float down_ms) const {
    // Each step's cost: this session's own average where it has one, the host's otherwise, and where neither is
    // known the nearest known step's scaled by kStepCostRatio a step.
    std::array<float, kEconomySteps> known{};
    for (int s = 0; s < kEconomySteps; ++s) {
        known[static_cast<size_t>(s)] = step_frames_[s] >= kSettledFrames
                                            ? step_cost_ms_[s]
                                            : g_step_cost_ms[static_cast<size_t>(s)].load(std::memory_order_relaxed);
    }
    for (int s = 0; s < kEconomySteps; ++s) {
        float predicted_ms = 0.0f;
        for (int d = 0; d < kEconomySteps && predicted_ms <= 0.0f; ++d) {
            // d steps away: below (cheaper, scaled up) first, then above (dearer, scaled down)
            if (s + d < kEconomySteps && known[static_cast<size_t>(s + d)] > 0) {
                predicted_ms = known[static_cast<size_t>(s + d)] * std::pow(kStepCostRatio, static_cast<float>(d));
            } else if (s - d >= 0 && known[static_cast<size_t>(s - d)] > 0) {
                predicted_ms = known[static_cast<size_t>(s - d)] / std::pow(kStepCostRatio, static_cast<float>(d));
            }
        }
        if (predicted_ms <= 0.0f) return 0;  // nothing measured on this host yet
        if (predicted_ms <= down_ms) return s;
    }
    return kEconomySteps - 1;
}

void FrameLoad::leaveToFinish() {
    if (!joined_ || tid_ != static_cast<int>(syscall(SYS_gettid))) return;
    leave();
    // Absolute, from the value at join: a throttled worker whose nice could not be lowered again is at
    // base + kThrottledNice already, and must not end up at the sum of both.
    if (getpriority(PRIO_PROCESS, static_cast<id_t>(tid_)) < base_nice_ + kFinishNice) {
        (void)setpriority(PRIO_PROCESS, static_cast<id_t>(tid_), base_nice_ + kFinishNice);
    }
    if (runningWorkers() > 0) recon::setParallelSerial(true);
}

void FrameLoad::leave() {
    if (!joined_) return;
    throttle(false);
    g_at_step[static_cast<size_t>(economy_)].fetch_sub(1, std::memory_order_relaxed);
    economy_ = 0;
    recon::setParallelAccounting(false);
    if (g_running_workers.fetch_sub(1, std::memory_order_relaxed) == 1) {
        // The last worker gone: the next ones may find a host of another speed (shared machines vary 2x by day).
        for (auto& cost : g_step_cost_ms) cost.store(0.0f, std::memory_order_relaxed);
    }
    joined_ = false;
}

void FrameLoad::beginFrame() {
    thread_cpu0_ns_ = threadCpuNs();
    pool_cpu0_ns_ = recon::parallelPoolCpuNs();
}

void FrameLoad::endFrame() {
    const int64_t cpu_ns = (threadCpuNs() - thread_cpu0_ns_) + (recon::parallelPoolCpuNs() - pool_cpu0_ns_);
    const float ms = static_cast<float>(cpu_ns) * 1e-6f;
    const float previous_ms = last_frame_ms_;
    last_frame_ms_ = ms;
    cost_ms_ = first_ ? ms : cost_ms_ + kEmaAlpha * (ms - cost_ms_);
    first_ = false;
    if (!joined_) return;
    const float budget = budgetMs();
    const bool alone = runningWorkers() <= 1;  // nobody to protect: use the whole machine
    if (!throttled_ && !alone && cost_ms_ > budget) throttle(true);
    if (throttled_ && (alone || cost_ms_ < kReleaseFraction * budget)) throttle(false);
    chooseModel(ms, previous_ms, budget, alone);
}

void FrameLoad::chooseModel(float frame_ms, float previous_ms, float budget_ms, bool alone) {
    // The first frames (detection, the model's start: tens of ms) say nothing about the steady cost.
    if (++frames_ <= kWarmUpFrames) return;
    float& cost = step_cost_ms_[economy_];
    cost = step_frames_[economy_]++ == 0 ? frame_ms : cost + kEmaAlpha * (frame_ms - cost);
    if (step_frames_[economy_] >= kSettledFrames) {
        g_step_cost_ms[static_cast<size_t>(economy_)].store(cost, std::memory_order_relaxed);
    }
    if (budget_ms > last_budget_ms_ * 1.1f) hold_frames_ = kStepHoldFrames;  // a session left: probe sooner
    const bool joined = budget_ms * 1.1f < last_budget_ms_;                  // a session joined: share shrank
    last_budget_ms_ = budget_ms;
    ++frames_at_step_;
    const auto step = [&](int to, bool probe) {
        g_at_step[static_cast<size_t>(economy_)].fetch_sub(1, std::memory_order_relaxed);
        g_at_step[static_cast<size_t>(to)].fetch_add(1, std::memory_order_relaxed);
        economy_ = to;
        step_frames_[to] = 0;  // its average starts afresh: the last one may be from a busier minute
        probing_ = probe;
        predicted_ = false;
        frames_at_step_ = 0;
    };
    if (alone) {  // nobody to protect: the whole machine, every cast at full resolution
        if (economy_ > 0) step(0, false);
        return;
    }
    const float down_ms = kStepDownFraction * budget_ms;
    // A session joined: go at once to the step its smaller share is predicted to need, rather than when two frames
    // over and kStepDownFrames at the step have shown it (the joiner's first frames cost the most).
    if (joined) {
        if (const int to = stepToFit(down_ms); to > economy_) {
            step(to, false);
            predicted_ = true;
            return;
        }
    }
    // Down: over budget by this step's own average, or skipping frames (the budget cannot see what other processes
    // and the server's own threads take). Below full, only after kStepDownFrames at this step: its average and the
    // skip share need that long to show what the step did. A probe that fails steps back after two frames (one
    // with a cast, one without) and doubles the hold.
    // Over by cost only when this frame and the one before are over too: one frame stalled on its own (on a shared
    // virtual machine a thread's CPU clock also runs while the host holds its core) does not move the ladder.
    const bool over =
        (cost > down_ms && std::min(frame_ms, previous_ms) > down_ms) || skipped_recent_ > kStepDownSkipFraction;
    // A probe, or a step taken on a prediction, is judged on its first two frames.
    const bool settled = economy_ == 0 || frames_at_step_ >= (probing_ || predicted_ ? 2 : kStepDownFrames);
    if (economy_ + 1 < kEconomySteps && over && settled) {
        if (probing_ && frames_at_step_ < kProbeFrames) hold_frames_ = std::min(2 * hold_frames_, kMaxStepHoldFrames);
        // Far over (a session joined, or this one just started beside others): straight to the first step predicted
        // to fit, each step costing 1 / kStepCostRatio of the one above, rather than one step every
        // kStepDownFrames. Four sessions on 2 cores took 45 frames and more to get from full to the last step, and
        // most of a 300-frame run's skipped frames fell in those (tests/bench/server_realtime.sh). A failed probe goes
        // back one. The prediction starts from the lowest of the step's average and the last two frames: a stall does
        // not add steps.
        int to = economy_ + 1;
        for (float predicted_ms = std::min({cost, frame_ms, previous_ms}) / kStepCostRatio;
             !probing_ && to + 1 < kEconomySteps && predicted_ms > down_ms; predicted_ms /= kStepCostRatio) {
            ++to;
        }
        step(to, false);
        return;
    }
    if (economy_ == 0 || frames_at_step_ < hold_frames_) return;
    // Up one step (a probe) after the hold, when it would fit: the lower of that step's last average and this
    // step's cost scaled by the measured ratio (an average from a busier minute must not bar the way up for good;
    // a probe that fails doubles the hold instead).
    const int up = economy_ - 1;
    const float scaled_ms = cost * kStepCostRatio;
    const float up_ms = step_frames_[up] >= kWarmUpFrames ? std::min(step_cost_ms_[up], scaled_ms) : scaled_ms;
    if (up_ms < kStepUpFraction * budget_ms) step(up, true);
}

void FrameLoad::throttle(bool on) {
    if (on == throttled_) return;
    throttled_ = on;
    recon::setParallelSerial(on);
    // Raising the nice value is always allowed; lowering it back needs CAP_SYS_NICE or RLIMIT_NICE. Without them a
    // released worker stays at kThrottledNice (it still gets idle cores) but keeps the whole pool again.
    (void)setpriority(PRIO_PROCESS, static_cast<id_t>(tid_), base_nice_ + (on ? kThrottledNice : 0));
}

void runThisThreadInBackground() {
    const auto tid = static_cast<id_t>(syscall(SYS_gettid));
    // Relative to the thread's own value: a server run niced as a whole keeps its background threads below it.
    (void)setpriority(PRIO_PROCESS, tid, getpriority(PRIO_PROCESS, tid) + kBackgroundNice);
}

void applyEconomy(const FrameLoad& load, const recon::ReconParams& base, const std::string& session_id,
                  recon::Reconstructor& reconstructor) {
    const int level = std::max(base.model_level, load.coarseModel() ? 1 : 0);
    const int every = std::max(base.model_cast_every, load.modelCastEvery());
    const int fuse = std::max(base.fuse_every, load.fuseEvery());
    if (level == reconstructor.requestedModelLevel() && every == reconstructor.modelCastEvery() &&
        fuse == reconstructor.fuseEvery()) {
        return;
    }
    const auto often = [](int n) {
        return n == 1 ? "every" : n == 2 ? "every other" : n == 3 ? "every third" : "fewer than every third";
    };
    std::fprintf(stderr,
                 "facescan-server: session %s: model cast at %s after %s fused frame, %s tracked frame fused (%.1f ms "
                 "of CPU a frame, budget %.1f ms)\n",
                 session_id.c_str(),
                 level == 0   ? "full resolution"
                 : level == 1 ? "half resolution"
                              : "a coarser level",
                 often(every), often(fuse), load.costMs(), load.budgetMs());
    reconstructor.setModelLevel(level);
    reconstructor.setModelCastEvery(every);
    reconstructor.setFuseEvery(fuse);
}

}  // namespace facescan::service
