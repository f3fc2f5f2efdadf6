// Wall-clock stopwatch for the per-stage timings the pipeline reports (StageTimesMs). steady_clock only: no
// allocation, safe in the frame loop.
#pragma once

#include <chrono>

namespace facescan::recon {

class Stopwatch {
 public:
    Stopwatch() : start_(Clock::now()) {}
    void restart() { start_ = Clock::now(); }
    // Milliseconds since construction or the last restart().
    float elapsedMs() const { return std::chrono::duration<float, std::milli>(Clock::now() - start_).count(); }
    // Milliseconds since the last lap (or start) and restarts; sums of laps equal the total.
    float lapMs() {
        const auto now = Clock::now();
        const float ms = std::chrono::duration<float, std::milli>(now - start_).count();
        start_ = now;
        return ms;
    }

 private:
    using Clock = std::chrono::steady_clock;
    Clock::time_point start_;
};

}  // namespace facescan::recon
