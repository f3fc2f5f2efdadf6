// Bounds one session's frame worker against bad input: a frame that makes the loop slow (a depth image full
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
// The same test picks how much the session spends on its model (economy(), applied by applyEconomy): a session
// over budget while others run steps down a ladder rather than skip frames. Step 1 casts the model after every
// other frame (recon::Reconstructor::setModelCastEvery: a frame's serial CPU 10.3 -> 8.0 ms, accuracy kept);
// step 2 also casts it at half resolution (setModelLevel: 6.1 ms, ATE up by about 0.5 mm on the scenarios); step 3
// also fuses only every other tracked frame (setFuseEvery; the model is then cast after each fused frame, so as
// often as at step 2): integration is the largest stage left at step 2 (4.5 of 11.2 ms a frame on a slow host),
// and the scenarios' mean distance to the true head moves by at most 0.01 mm (bench recon); step 4 fuses every
// third tracked frame (a frame 1.01-1.26x cheaper than at step 3 on a slow host; the mean distance moves by
// -0.022..+0.016 mm from step 3's, completeness by 0.2 % at most). Every frame is still tracked: from step 3 the
// frames not fused are registered on the coarser pyramid levels only (recon::ReconParams::unfused_finest_level;
// four sessions held at step 4 used 7 % less server CPU a tracked frame, the scenarios' mean distance moved by
// -0.006..+0.007 mm). It goes back up one step at a time once the step above would fit the budget.
#pragma once

#include <cstdint>
#include <string>

namespace facescan::recon {
class Reconstructor;
struct ReconParams;
}  // namespace facescan::recon

namespace facescan::service {

class FrameLoad {
 public:
    static constexpr int kThrottledNice = 5;         // CFS weight 335 against 1024 at nice 0: about a quarter
    static constexpr float kReleaseFraction = 0.7f;  // of the budget: hysteresis, so a session does not flap
    static constexpr float kEmaAlpha = 0.2f;         // ~5 frames: one noise frame is enough to react to
    // A throttled session that lost tracking runs its hypothesis search (tens of ms) on one frame in this many
    // (recon::Reconstructor::setSearchEvery); the frames between try the cheap plain fit only.
    static constexpr int kThrottledSearchEvery = 4;
    // The economy step, after the first kWarmUpFrames: down when the step's average cost is over
    // kStepDownFraction of the budget or the session skips more than kStepDownSkipFraction of its frames
    // (noteSkipped), while others run: to the first step whose cost, the average over kStepCostRatio per step,
    // would fit (skipping alone: one step); a step is kept kStepDownFrames before the next one down (the skip share
    // lags). After kStepHoldFrames at a step it probes the step above if that would fit kStepUpFraction of the
    // budget (the lower of that step's last average and this one's times kStepCostRatio: measured 10.3 / 8.0,
    // 8.0 / 6.1, and 1.25-1.48 for step 2 over step 3 in tests/bench/server_realtime.sh). A probe that steps down again
    // within kProbeFrames doubles the hold, up to kMaxStepHoldFrames; a session leaving resets it. A session joining,
    // or seeing one join (its share shrinks), goes at once to the step predicted to fit its share from the costs
    // measured on this host (stepToFit: its own steps' averages, or the last other session's, kSettledFrames or more
    // frames old) and judges it on its first two frames, as a probe. 0: the model cast after every frame; 1: after
    // every other; 2: and coarse; 3: and every other frame fused; 4: every third fused
    static constexpr int kEconomySteps = 5;
    static constexpr int kWarmUpFrames = 5;
    static constexpr int kStepDownFrames = 10;
    static constexpr int kSettledFrames = 3;  // frames at a step before its average predicts (stepToFit)
    static constexpr float kStepDownSkipFraction = 0.05f;
    static constexpr int kStepHoldFrames = 150;  // 5 s at 30 Hz
    static constexpr int kProbeFrames = 90;
    static constexpr int kMaxStepHoldFrames = 2400;
    static constexpr float kStepCostRatio = 1.3f;
    // A session's frames queue behind the others' long before its cost reaches its whole share (the budget: every
    // core busy), so it steps down at kStepDownFraction of it, and up only where the step above would stay under
    // kStepUpFraction (hysteresis).
    static constexpr float kStepDownFraction = 0.7f;
    static constexpr float kStepUpFraction = 0.6f;

    // source_rate_hz: the frame rate the session's source delivers (CameraInfo).
    explicit FrameLoad(float source_rate_hz);
    ~FrameLoad();
    FrameLoad(const FrameLoad&) = delete;
    FrameLoad& operator=(const FrameLoad&) = delete;

    // On the worker thread, once before its first frame: counts it among the running workers and turns the pool's
    // CPU accounting on for it. Beside running workers it starts at the deepest economy step one of them is at, or
    // deeper where the costs they measured say its share needs it.
    // leave(), on the same thread, undoes both and the throttle; safe to call twice.
    void join();
    void leave();
    // On the worker thread, for its session's finish (the model closed, decimated and textured: seconds of CPU; the
    // worker ends with it): leave(), then run kFinishNice above the thread's nice value at join, and, while other
    // sessions' workers run, on this thread alone (the pool's workers run at the workers' priority: chunks of the
    // finish there would compete with their frames at full weight). So a finish does not take the cores from the
    // sessions still scanning. Nothing when not joined on this thread (a session finished without a worker).
    void leaveToFinish();
    // Not the background's 10: against scanning workers that fill every core a thread at nice 10 gets a tenth of
    // a core, and the watchdog's 20 s a step would no longer cover a finish's 3 s of CPU; at 5 (CFS weight 335
    // against 1024: a quarter) it takes about 12 s.
    static constexpr int kFinishNice = 5;

    // Around each frame, on the worker thread. endFrame updates the average and throttles or releases the thread.
    void beginFrame();
    void endFrame();

    bool throttled() const { return throttled_; }
    int searchEvery() const { return throttled_ ? kThrottledSearchEvery : 1; }
    int economy() const { return economy_; }            // 0 .. kEconomySteps - 1
    bool coarseModel() const { return economy_ >= 2; }  // the model cast at half resolution
    // The model cast after one fused frame in this many: every other at steps 1 and 2; from step 3, after each
    // fused frame, which is every other tracked one (every third at step 4).
    int modelCastEvery() const { return economy_ == 1 || economy_ == 2 ? 2 : 1; }
    int fuseEvery() const { return economy_ >= 4 ? 3 : economy_ == 3 ? 2 : 1; }  // one tracked frame in this many fused
    // The session's recent share of skipped frames (live sessions keep only the newest frame), after each frame.
    void noteSkipped(float recent_fraction) { skipped_recent_ = recent_fraction; }
    float costMs() const { return cost_ms_; }             // CPU a frame, recent average
    float lastFrameMs() const { return last_frame_ms_; }  // CPU of the last frame (endFrame)
    float budgetMs() const;                               // CPU a frame this session may use now
    static int runningWorkers();                          // sessions with a worker (joined and not left)

 private:
    void throttle(bool on);
    void chooseModel(float frame_ms, float previous_ms, float budget_ms, bool alone);
    // The shallowest step predicted to cost at most down_ms a frame (0 with nothing measured yet on this host).
    int stepToFit(float down_ms) const;

    const float period_ms_;
    bool joined_ = false;
    bool throttled_ = false;
    int economy_ = 0;
    int frames_ = 0;                          // frames measured
    float step_cost_ms_[kEconomySteps] = {};  // average CPU a frame at each economy step
    int step_frames_[kEconomySteps] = {};     // frames measured at each step
    float skipped_recent_ = 0.0f;
    float last_frame_ms_ = 0.0f;         // the CPU of the last frame
    int frames_at_step_ = 0;             // since the last change of step
    bool probing_ = false;               // a step up after a hold, not yet proven
    bool predicted_ = false;             // a step taken on the costs measured, at a join: not yet proven
    int hold_frames_ = kStepHoldFrames;  // how long a step below full holds before a probe
    float last_budget_ms_ = 0.0f;
    bool first_ = true;
    float cost_ms_ = 0;
    int64_t thread_cpu0_ns_ = 0, pool_cpu0_ns_ = 0;
    int tid_ = 0;
    int base_nice_ = 0;  // the thread's nice value when it joined
};

// Threads whose work can wait for the sessions' frames: snapshots, replication, a joining session's engine build.
// They run kBackgroundNice above the thread's nice value (CFS weight 110 against 1024: about a tenth of a worker's
// share), so on a busy machine the scheduler prefers the workers, while an idle core still runs them at full
// speed. Replication at nice 0 encoded each session's first, full replica (50-90 ms) at the moment the next
// session joined: four sessions skipped 52 frames in 10 runs with it, 18 in 9 without (server_realtime.sh).
inline constexpr int kBackgroundNice = 10;
void runThisThreadInBackground();

// The model level, cast interval and fusion interval for the session's next frames: the session's own
// (recon::ReconParams model_level, model_cast_every, fuse_every), or cheaper as the load's economy step says. A
// change is logged with the session's CPU a frame and budget.
void applyEconomy(const FrameLoad& load, const recon::ReconParams& base, const std::string& session_id,
                  recon::Reconstructor& reconstructor);

}  // namespace facescan::service
