// Bad input: a session worker whose frames cost more CPU than its share is throttled (its parallelFor
// calls run on its own thread, its priority drops) while other sessions run, and released when alone. Asserted on
// CPU time (CLOCK_THREAD_CPUTIME_ID), which a loaded machine does not change.
#include "service/frame_load.hpp"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <thread>

#include "cpu_burn.hpp"
#include "recon/parallel.hpp"
#include "recon/reconstructor.hpp"

namespace facescan::service {
namespace {

int myNice() { return getpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid))); }

void frame(FrameLoad& load, int64_t cpu_ns) {
    load.beginFrame();
    testing::burnCpuNs(cpu_ns);
    load.endFrame();
}

// Two running sessions, on the calling thread: `other` at 30 Hz and `busy` with a 10 ms frame period; ns(share) is
// the CPU of that share of busy's budget. Each test leaves them itself, in the order it needs.
struct TwoSessions {
    FrameLoad other{30.0f}, busy{100.0f};
    float budget_ms = 0.0f;  // busy's, with the two running
    TwoSessions() {
        other.join();
        busy.join();
        budget_ms = busy.budgetMs();
    }
    int64_t ns(float share) const { return static_cast<int64_t>(share * budget_ms * 1e6f); }
};

TEST(FrameLoad, AFrameOverItsShareIsThrottledWhileOthersRunAndReleasedAlone) {
    std::thread([] {
        const int base = myNice();              // ctest may run niced
        FrameLoad other(30.0f), busy(1000.0f);  // busy: a 1 ms frame period, so 5 ms of CPU is far over its share
        other.join();
        busy.join();
        ASSERT_EQ(FrameLoad::runningWorkers(), 2);
        EXPECT_NEAR(busy.budgetMs(), 1.0f * static_cast<float>(recon::parallelThreadCount()) / 2, 1e-3f);
        frame(busy, 5'000'000);
        EXPECT_GE(busy.costMs(), 5.0f);
        EXPECT_TRUE(busy.throttled());
        EXPECT_TRUE(recon::parallelSerial());
        EXPECT_EQ(myNice(), base + FrameLoad::kThrottledNice);
        other.leave();  // alone now: nobody to protect
        frame(busy, 5'000'000);
        EXPECT_FALSE(busy.throttled());
        EXPECT_FALSE(recon::parallelSerial());
        if (geteuid() == 0) {  // lowering nice again needs CAP_SYS_NICE
            EXPECT_EQ(myNice(), base);
        }
        busy.leave();
        EXPECT_EQ(FrameLoad::runningWorkers(), 0);
    }).join();
}

// A session's finish runs below the sessions still scanning (kFinishNice), on its own thread alone while one runs,
// and with the whole pool when none does; a throttled worker does not add both nice values up.
TEST(FrameLoad, AFinishRunsBelowTheScanningSessionsAndAloneBesideThem) {
    std::thread([] {
        const int base = myNice();
        FrameLoad scanning(30.0f);
        scanning.join();
        std::thread([base] {
            FrameLoad finishing(1000.0f);
            finishing.join();
            ASSERT_EQ(FrameLoad::runningWorkers(), 2);
            frame(finishing, 5'000'000);  // far over its share: throttled (nice + kThrottledNice)
            EXPECT_TRUE(finishing.throttled());
            finishing.leaveToFinish();
            EXPECT_EQ(FrameLoad::runningWorkers(), 1);  // no longer a scanning session
            EXPECT_EQ(myNice(), base + FrameLoad::kFinishNice);
            EXPECT_TRUE(recon::parallelSerial());
            finishing.leave();  // the worker's own leave at its end: nothing more
            EXPECT_EQ(FrameLoad::runningWorkers(), 1);
        }).join();
        scanning.leave();
        std::thread([base] {
            FrameLoad finishing(30.0f);
            finishing.join();
            finishing.leaveToFinish();  // nobody scans: the pool is its to use
            EXPECT_EQ(myNice(), base + FrameLoad::kFinishNice);
            EXPECT_FALSE(recon::parallelSerial());
            EXPECT_EQ(FrameLoad::runningWorkers(), 0);
        }).join();
        // On a thread that did not join it (a session finished without a worker): nothing changes.
        FrameLoad other(30.0f);
        std::thread([&other] { other.join(); }).join();
        other.leaveToFinish();
        EXPECT_EQ(myNice(), base);
        EXPECT_EQ(FrameLoad::runningWorkers(), 1);
        std::thread([&other] { other.leave(); }).join();
    }).join();
}

TEST(FrameLoad, AFrameWithinItsShareIsLeftAlone) {
    std::thread([] {
        const int base = myNice();
        FrameLoad a(30.0f), b(30.0f);  // 33 ms period: 2 ms of CPU is well within half the machine
        a.join();
        b.join();
        for (int i = 0; i < 5; ++i) frame(a, 2'000'000);
        EXPECT_FALSE(a.throttled());
        EXPECT_FALSE(recon::parallelSerial());
        EXPECT_EQ(myNice(), base);
        EXPECT_LT(a.costMs(), a.budgetMs());
        b.leave();
        a.leave();
    }).join();
}

// How much a session spends on its model follows the same budget: over it while another session runs (after the
// first frames, which detection and the model's start make slow), the session steps down the ladder: the model
// cast after every other frame (step 1), then also at half resolution (step 2), then also fusing every other frame
// with a cast after each fused one (step 3), then every third (step 4), a step at most every kStepDownFrames. After a
// hold it goes back up one step at a time if the step above would fit kStepUpFraction of the budget; alone, to full at
// once.
TEST(FrameLoad, OverItsShareASessionStepsDownTheLadderAndBackUpOnceTheStepAboveWouldFit) {
    std::thread([] {
        TwoSessions two;
        FrameLoad &other = two.other, &busy = two.busy;
        const auto ns = [&](float share) { return two.ns(share); };
        for (int i = 0; i < FrameLoad::kWarmUpFrames; ++i) frame(busy, ns(3.0f));
        EXPECT_EQ(busy.economy(), 0) << "the first frames do not count";
        frame(busy, ns(0.8f));
        EXPECT_EQ(busy.economy(), 1) << "over kStepDownFraction of the budget with another session running";
        EXPECT_EQ(busy.modelCastEvery(), 2);
        EXPECT_FALSE(busy.coarseModel());
        // 0.85 of the budget: over, and one step down (0.85 / kStepCostRatio) is predicted to fit.
        for (int i = 0; i < FrameLoad::kStepDownFrames - 1; ++i) frame(busy, ns(0.85f));
        EXPECT_EQ(busy.economy(), 1) << "a step holds kStepDownFrames before the next one down";
        frame(busy, ns(0.85f));
        EXPECT_EQ(busy.economy(), 2) << "still over budget";
        EXPECT_TRUE(busy.coarseModel());
        EXPECT_EQ(busy.modelCastEvery(), 2);
        EXPECT_EQ(busy.fuseEvery(), 1);
        // Steps 3 and 4, still over budget: every other, then every third tracked frame fused, the model cast after
        // each fused frame (at step 3 as often as at step 2). The session's reconstructor is told so (applyEconomy).
        const recon::ReconParams base = recon::ReconParams::faceDefaults();
        recon::Reconstructor rec(recon::Intrinsics::kinectV1(), base);
        for (const int step : {3, 4}) {
            for (int i = 0; i < FrameLoad::kStepDownFrames; ++i) frame(busy, ns(0.85f));
            EXPECT_EQ(busy.economy(), step) << "still over budget";
            EXPECT_TRUE(busy.coarseModel());
            EXPECT_EQ(busy.fuseEvery(), step - 1);
            EXPECT_EQ(busy.modelCastEvery(), 1) << "cast after each fused frame";
            applyEconomy(busy, base, "s", rec);
            EXPECT_EQ(rec.requestedModelLevel(), 1);
            EXPECT_EQ(rec.modelCastEvery(), 1);
            EXPECT_EQ(rec.fuseEvery(), step - 1);
        }
        // A session's own settings are a floor.
        recon::ReconParams floor = base;
        floor.model_cast_every = 3;
        floor.fuse_every = 4;
        applyEconomy(busy, floor, "s", rec);
        EXPECT_EQ(rec.modelCastEvery(), 3);
        EXPECT_EQ(rec.fuseEvery(), 4);
        for (int i = 0; i < FrameLoad::kStepDownFrames; ++i) frame(busy, ns(1.3f));
        EXPECT_EQ(busy.economy(), 4) << "the last step";
        // At 0.75 of the budget, the step above (~1.3 x 0.75) would not fit: it stays, past the hold.
        for (int i = 0; i < FrameLoad::kStepHoldFrames + 10; ++i) frame(busy, ns(0.75f));
        EXPECT_EQ(busy.economy(), 4);
        // At 0.3 of the budget it does (~0.4), although step 3's own last average (1.3 budgets) says otherwise.
        for (int i = 0; i < 15 && busy.economy() == 4; ++i) frame(busy, ns(0.3f));
        EXPECT_EQ(busy.economy(), 3);
        int n = 0;
        while (busy.economy() == 3 && n < 2 * FrameLoad::kStepHoldFrames) frame(busy, ns(0.3f)), ++n;
        EXPECT_EQ(busy.economy(), 2);
        n = 0;
        while (busy.economy() == 2 && n < 2 * FrameLoad::kStepHoldFrames) frame(busy, ns(0.3f)), ++n;
        EXPECT_EQ(busy.economy(), 1);
        n = 0;
        while (busy.economy() == 1 && n < 2 * FrameLoad::kStepHoldFrames) frame(busy, ns(0.3f)), ++n;
        EXPECT_EQ(busy.economy(), 0) << "one step at a time, each after its hold";
        EXPECT_GE(n, FrameLoad::kStepHoldFrames - 1);
        EXPECT_LE(n, FrameLoad::kStepHoldFrames + 1);
        frame(busy, ns(1.3f));
        EXPECT_EQ(busy.economy(), 0) << "one frame over on its own (a stall) does not move the ladder";
        frame(busy, ns(1.3f));
        EXPECT_EQ(busy.economy(), 1) << "over budget again: the probe of full fails, back one step";
        other.leave();  // alone: the whole machine, full, even for a frame full would not fit
        frame(busy, ns(10.0f));
        EXPECT_EQ(busy.economy(), 0);
        busy.leave();
    }).join();
}

// Far over its share (a session that starts beside others, or a session joined): straight down to the first step
// predicted to fit, each step costing 1 / kStepCostRatio of the one above, instead of one step every
// kStepDownFrames. A probe of the step above that fails goes back one step only. A session that joins starts at the
// deepest step in use.
TEST(FrameLoad, FarOverItsShareASessionGoesStraightToTheStepPredictedToFitAndJoinersStartThere) {
    std::thread([] {
        TwoSessions two;
        FrameLoad &other = two.other, &busy = two.busy;
        const auto ns = [&](float share) { return two.ns(share); };
        for (int i = 0; i < FrameLoad::kWarmUpFrames; ++i) frame(busy, ns(3.0f));
        frame(busy, ns(1.0f));
        EXPECT_EQ(busy.economy(), 2) << "1.0 / 1.3 = 0.77 is still over 0.7 of the budget; 1.0 / 1.69 = 0.59 is not";
        {
            // A session that joins now starts at the deepest step in use (with one more session every share only
            // shrinks; no step has been measured for kSettledFrames yet), and its reconstructor is told so before
            // its first frame.
            FrameLoad late(30.0f);
            late.join();
            EXPECT_EQ(late.economy(), 2);
            recon::Reconstructor rec(recon::Intrinsics::kinectV1(), recon::ReconParams::faceDefaults());
            applyEconomy(late, recon::ReconParams::faceDefaults(), "late", rec);
            EXPECT_EQ(rec.requestedModelLevel(), 1);
            late.leave();
        }
        for (int i = 0; i < FrameLoad::kStepHoldFrames + 1 && busy.economy() == 2; ++i) frame(busy, ns(0.3f));
        ASSERT_EQ(busy.economy(), 1) << "a probe after the hold";
        frame(busy, ns(2.5f));
        frame(busy, ns(2.5f));
        EXPECT_EQ(busy.economy(), 2) << "a failed probe goes back one step";
        for (int i = 0; i < FrameLoad::kStepDownFrames; ++i) frame(busy, ns(2.5f));
        EXPECT_EQ(busy.economy(), FrameLoad::kEconomySteps - 1) << "then to the last step at once";
        busy.leave();
        other.leave();
    }).join();
}

// A session that joins starts at the step its share is predicted to need from the costs the running sessions
// measured, and they go at once to the step their smaller share needs; both judge that step on its first two
// frames. The costs are forgotten when the last session leaves (the host may be another speed by the next).
TEST(FrameLoad, AJoinerStartsWhereTheMeasuredCostsSayAndTheOthersStepDownAtOnce) {
    std::thread([] {
        TwoSessions two;  // `other` at 30 Hz, `busy` at 100 Hz
        FrameLoad &other = two.other, &busy = two.busy;
        const auto ns = [&](float share) { return two.ns(share); };
        for (int i = 0; i < FrameLoad::kWarmUpFrames + FrameLoad::kStepDownFrames; ++i) frame(busy, ns(0.6f));
        ASSERT_EQ(busy.economy(), 0) << "0.6 of its share is within kStepDownFraction";
        // A third session at 100 Hz: its share, and busy's, is 2/3 of what it was; 0.7 x 2/3 = 0.47 of the old.
        // Full is measured at 0.6 of it; one step down is predicted at 0.6 / 1.3 = 0.46: it fits.
        FrameLoad late(100.0f);
        late.join();
        EXPECT_EQ(late.economy(), 1) << "the step predicted to fit, below the deepest in use (full)";
        frame(busy, ns(0.4f));
        EXPECT_EQ(busy.economy(), 1) << "a session joined: at once, although this frame was within the share";
        for (int i = 0; i < FrameLoad::kWarmUpFrames; ++i) frame(late, ns(3.0f));
        EXPECT_EQ(late.economy(), 1) << "the first frames do not count";
        frame(late, ns(0.6f));
        frame(late, ns(0.6f));
        EXPECT_EQ(late.economy(), 2) << "the predicted step was over: down after two frames, not kStepDownFrames";
        late.leave();
        busy.leave();
        other.leave();
        // All gone: a session joining three later starts at full, not where the old costs would have put it.
        FrameLoad a(100.0f), b(100.0f), c(100.0f);
        a.join();
        b.join();
        c.join();
        EXPECT_EQ(c.economy(), 0);
        c.leave();
        b.leave();
        a.leave();
    }).join();
}

// Within budget by its own measure but skipping frames (other processes and the server's own threads take CPU
// the budget does not see): down the ladder too. A probe of the step above that skips again holds twice as long.
TEST(FrameLoad, ASessionThatSkipsFramesStepsDownAndProbesLessOften) {
    std::thread([] {
        TwoSessions two;
        FrameLoad &other = two.other, &busy = two.busy;
        const auto ns = [&](float share) { return two.ns(share); };
        for (int i = 0; i < FrameLoad::kWarmUpFrames + 3; ++i) frame(busy, ns(0.4f));
        EXPECT_EQ(busy.economy(), 0);
        busy.noteSkipped(0.2f);
        frame(busy, ns(0.4f));
        EXPECT_EQ(busy.economy(), 1) << "skipping a fifth of its frames";
        for (int i = 0; i < FrameLoad::kStepDownFrames; ++i) frame(busy, ns(0.4f));
        EXPECT_EQ(busy.economy(), 2) << "still skipping after kStepDownFrames";
        busy.noteSkipped(0.0f);
        const auto framesUntil = [&](int step) {
            int n = 0;
            while (busy.economy() != step && n < 10 * FrameLoad::kStepHoldFrames) frame(busy, ns(0.2f)), ++n;
            return n;
        };
        const int first_hold = framesUntil(1);
        EXPECT_GE(first_hold, FrameLoad::kStepHoldFrames - 1);
        EXPECT_LE(first_hold, FrameLoad::kStepHoldFrames + 1);
        busy.noteSkipped(0.2f);  // the probe skips again at once: back after its second frame
        frame(busy, ns(0.4f));
        EXPECT_EQ(busy.economy(), 1);
        frame(busy, ns(0.4f));
        ASSERT_EQ(busy.economy(), 2);
        busy.noteSkipped(0.0f);
        EXPECT_GE(framesUntil(1), 2 * FrameLoad::kStepHoldFrames - 1) << "a failed probe doubles the hold";
        other.leave();
        busy.leave();
    }).join();
}

}  // namespace
}  // namespace facescan::service
