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
// The same test picks the model's resolution (coarseModel: recon::Reconstructor::setModelLevel): a session over
// budget while others run casts its model at half resolution, which costs a third less CPU a frame, rather than
// skip frames; it goes back to full resolution once its frames would fit the budget at full-resolution cost.
#pragma once

#include <cstdint>
#include <string>

namespace facescan::recon {
class Reconstructor;
}

namespace facescan::service {

class FrameLoad {
 public:
    static constexpr int kThrottledNice = 5;         // CFS weight 335 against 1024 at nice 0: about a quarter
    static constexpr float kReleaseFraction = 0.7f;  // of the budget: hysteresis, so a session does not flap
    static constexpr float kEmaAlpha = 0.2f;         // ~5 frames: one noise frame is enough to react to
    // A throttled session that lost tracking runs its hypothesis search (tens of ms) on one frame in this many
    // (recon::Reconstructor::setSearchEvery); the frames between try the cheap plain fit only.
    static constexpr int kThrottledSearchEvery = 4;
    // The model's resolution, after the first kWarmUpFrames: coarse when full resolution's average cost is over
    // budget or the session skips more than kCoarseSkipFraction of its frames (noteSkipped), while others run.
    // After kCoarseHoldFrames it probes full resolution again if that would fit kFullModelFraction of the budget
    // (its own average, or the coarse one times kCoarseCostRatio: measured 1.7, i.e. 16.9 against 10.0 ms a frame
    // with 4 sessions on 2 cores). A probe that goes coarse again within kProbeFrames doubles the hold, up to
    // kMaxCoarseHoldFrames; a session leaving resets it.
    static constexpr int kWarmUpFrames = 5;
    static constexpr float kCoarseSkipFraction = 0.05f;
    static constexpr int kCoarseHoldFrames = 150;  // 5 s at 30 Hz
    static constexpr int kProbeFrames = 90;
    static constexpr int kMaxCoarseHoldFrames = 2400;
    static constexpr float kCoarseCostRatio = 1.7f;
    static constexpr float kFullModelFraction = 0.9f;

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
    bool coarseModel() const { return coarse_model_; }
    // The session's recent share of skipped frames (live sessions keep only the newest frame), after each frame.
    void noteSkipped(float recent_fraction) { skipped_recent_ = recent_fraction; }
    float costMs() const { return cost_ms_; }  // CPU a frame, recent average
    float budgetMs() const;                    // CPU a frame this session may use now
    static int runningWorkers();               // sessions with a worker (joined and not left)

 private:
    void throttle(bool on);
    void chooseModel(float frame_ms, float budget_ms, bool alone);

    const float period_ms_;
    bool joined_ = false;
    bool throttled_ = false;
    bool coarse_model_ = false;
    int frames_ = 0;                                     // frames measured
    float full_cost_ms_ = 0.0f, coarse_cost_ms_ = 0.0f;  // average CPU a frame at each model resolution
    int full_frames_ = 0, coarse_frames_ = 0;
    float skipped_recent_ = 0.0f;
    int frames_at_level_ = 0;              // since the last change of resolution
    bool probing_ = false;                 // at full resolution again after a coarse hold
    int hold_frames_ = kCoarseHoldFrames;  // how long the coarse level holds before a probe
    float last_budget_ms_ = 0.0f;
    bool first_ = true;
    float cost_ms_ = 0;
    int64_t thread_cpu0_ns_ = 0, pool_cpu0_ns_ = 0;
    int tid_ = 0;
    int base_nice_ = 0;  // the thread's nice value when it joined
};

// The model level for the session's next cast: base_level, or at least 1 (half resolution) while the load says
// coarse. A change is logged with the session's CPU a frame and budget.
void applyModelLevel(const FrameLoad& load, int base_level, const std::string& session_id,
                     recon::Reconstructor& reconstructor);

}  // namespace facescan::service
