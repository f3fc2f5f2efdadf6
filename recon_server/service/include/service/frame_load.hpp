// Bounds one session's frame worker (issue 16, "bad input"): a frame that makes the loop slow (a depth image full
// of noise, a head filling the frame at 0.4 m) must not stall the other sessions, which share the same cores and
// the recon core's process-wide parallelFor pool.
//
// Each worker measures what its frames cost in CPU (its own thread plus what pool workers spent on its
// parallelFor calls: recon/parallel.hpp's accounting), as an exponential average, against its budget: the frame
// period times the cores, shared among the sessions that have a worker. A session over budget, while others run,
// is throttled: its parallelFor calls run on its own thread (the pool stays with the others) and its thread gets a
// lower OS priority (kThrottledNice above its own), so on a contended machine the scheduler prefers the sessions within
// budget, while on an idle one it still runs at full speed. It is released below kReleaseFraction of the budget.
// A live session that is throttled or skips frames is reported "behind" (session.cpp).
#pragma once

#include <cstdint>

namespace facescan::service {

class FrameLoad {
 public:
    static constexpr int kThrottledNice = 5;         // CFS weight 335 against 1024 at nice 0: about a quarter
    static constexpr float kReleaseFraction = 0.7f;  // of the budget: hysteresis, so a session does not flap
    static constexpr float kEmaAlpha = 0.2f;         // ~5 frames: one noise frame is enough to react to
    // A throttled session that lost tracking runs its hypothesis search (tens of ms) on one frame in this many
    // (recon::Reconstructor::setSearchEvery); the frames between try the cheap plain fit only.
    static constexpr int kThrottledSearchEvery = 4;

    // source_rate_hz: the frame rate the session's source delivers (CameraInfo).
    explicit FrameLoad(float source_rate_hz);
    ~FrameLoad();
    FrameLoad(const FrameLoad&) = delete;
    FrameLoad& operator=(const FrameLoad&) = delete;

    // On the worker thread, once before its first frame: counts it among the running workers and turns the pool's
    // CPU accounting on for it. leave(), on the same thread, undoes both and the throttle; safe to call twice.
    void join();
    void leave();

    // Around each frame, on the worker thread. endFrame updates the average and throttles or releases the thread.
    void beginFrame();
    void endFrame();

    bool throttled() const { return throttled_; }
    int searchEvery() const { return throttled_ ? kThrottledSearchEvery : 1; }
    float costMs() const { return cost_ms_; }  // CPU a frame, recent average
    float budgetMs() const;                    // CPU a frame this session may use now
    static int runningWorkers();               // sessions with a worker (joined and not left)

 private:
    void throttle(bool on);

    const float period_ms_;
    bool joined_ = false;
    bool throttled_ = false;
    bool first_ = true;
    float cost_ms_ = 0;
    int64_t thread_cpu0_ns_ = 0, pool_cpu0_ns_ = 0;
    int tid_ = 0;
    int base_nice_ = 0;  // the thread's nice value when it joined
};

}  // namespace facescan::service
