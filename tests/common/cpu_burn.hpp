// Work that costs the same CPU however loaded the machine is: for tests that assert on CPU time, not wall time.
#pragma once

#include <time.h>

#include <cstdint>

namespace facescan::testing {

// Spins until the calling thread has used `ns` of CPU.
inline void burnCpuNs(int64_t ns) {
    timespec t0{}, t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t0);
    do {
        clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    } while ((t.tv_sec - t0.tv_sec) * 1'000'000'000LL + (t.tv_nsec - t0.tv_nsec) < ns);
}

}  // namespace facescan::testing
