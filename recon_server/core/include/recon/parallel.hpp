// Allocation-free parallel loop for the per-frame path (docs/design.md s4: "no allocation in the per-frame path after
// warm-up"). cv::parallel_for_ wraps every body in std::function copies (three heap allocations a call, ~57 a
// frame), so the recon core uses this instead.
//
// One process-wide pool of hardware_concurrency - 1 persistent workers, started on the first call that has work to
// share. The calling thread runs chunks too, so on one core the loop is a plain loop, and a call from inside a body
// (nested) or from several threads at once never waits for a thread that is not making progress. The job lives on
// the caller's stack; after warm-up a call allocates nothing. Workers out of work poll for 100 us (the frame loop's
// calls come microseconds apart), then sleep on a condition variable: no CPU while idle.
#pragma once

#include <cstdint>
#include <memory>
#include <type_traits>

namespace facescan::recon {

namespace detail {

// A body erased to a function pointer and its object: no std::function, so no allocation.
using ChunkFn = void (*)(void* body, int lo, int hi);

// Runs fn(body, lo, hi) over disjoint chunks that together cover [begin, end) exactly once; returns when all ran.
void parallelForErased(int begin, int end, ChunkFn fn, void* body);

}  // namespace detail

// Per-thread control and accounting (bad input: one session's slow frames must not monopolise the
// pool that every session shares). Both act on the calling thread's own calls only.
// Serial: its parallelFor calls run on itself alone, leaving the pool's workers to the other threads.
void setParallelSerial(bool serial);
bool parallelSerial();
// Accounting: pool workers add the CPU time they spend on its calls (two clock reads per worker and call, none
// while off), so CLOCK_THREAD_CPUTIME_ID plus this is what the thread's work cost, whoever ran it.
void setParallelAccounting(bool on);
bool parallelAccounting();
int64_t parallelPoolCpuNs();  // since accounting was first turned on for the calling thread

// Names the calling thread for top -H, ps -L and perf (Linux: at most 15 characters are kept). The pool's workers
// are "fs-pool"; the server names its session workers after their session, so a thread that burns a core says
// whose it is.
void nameThisThread(const char* name);

// Threads that run chunks of one parallelFor: the pool's workers plus the caller (1 on a single core).
int parallelThreadCount();

// Calls body(lo, hi) on disjoint chunks [lo, hi) that together cover [begin, end) exactly once, some on pool
// workers and some on the calling thread, and returns when all have run (their writes are then visible to the
// caller). An empty range calls nothing. Chunks may run in any order and on any thread, so a body must write only
// to what its chunk owns; a reduction keeps one partial per fixed index and sums them in order after the call
// (deterministic on any core count). The body must not throw: an exception escaping it terminates the process.
template <class F>
void parallelFor(int begin, int end, F&& body) {
    if (end <= begin) return;
    using Body = std::remove_reference_t<F>;
    detail::parallelForErased(
        begin, end, [](void* b, int lo, int hi) noexcept { (*static_cast<Body*>(b))(lo, hi); },
        const_cast<void*>(static_cast<const void*>(std::addressof(body))));
}

}  // namespace facescan::recon
