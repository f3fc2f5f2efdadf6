#include "recon/parallel.hpp"

#include <pthread.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <new>
#include <system_error>
#include <thread>
#include <vector>

namespace facescan::recon {
namespace {

thread_local bool t_serial = false;
thread_local bool t_accounting = false;
thread_local std::atomic<int64_t> t_pool_cpu_ns{0};  // written by pool workers, read by its thread

int64_t threadCpuNs() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

constexpr int kSlots = 16;  // jobs open at once (concurrent sessions plus nesting); beyond that a call runs alone
constexpr int kMaxWorkers = 63;
// Chunks per thread: rows of the head region cost unevenly (ray casting, ICP pairs), so more chunks than threads
// let whoever finishes early take another; each claim is one atomic operation.
constexpr int kChunksPerThread = 8;
static_assert((kMaxWorkers + 1) * kChunksPerThread < (1 << 16), "chunk indices are 16 bits in a claim word");
// How long a thread that ran out of work polls (yielding the core) before it sleeps. The frame loop's calls follow
// each other within microseconds (ICP's 19 per frame), and waking a sleeping thread on this VM often took longer
// than a whole call, so workers that slept at once took few chunks (~25 % of them with 2 threads, against ~45 %
// when polling). Yielding, not pausing, so that on a busy machine the poll gives the core to whoever wants it.
constexpr std::chrono::microseconds kPollBeforeSleep{100};

// Workers plus the caller. A function, not a namespace-scope constant: a static initialiser elsewhere may call
// parallelFor before this file's constants are initialised.
int plannedThreads() {
    static const int threads =
        std::clamp(static_cast<int>(std::thread::hardware_concurrency()), 1, kMaxWorkers + 1);  // 0 when unknown
    return threads;
}

// What a thread needs to run chunks of one job; workers copy it under the pool mutex.
struct JobView {
    detail::ChunkFn fn = nullptr;
    void* body = nullptr;
    int begin = 0;
    int64_t n = 0;  // end - begin does not fit an int for every pair of ints
    int n_chunks = 0;
    uint32_t generation = 0;
    std::atomic<int64_t>* cpu_ns = nullptr;  // the owner's accounting sink, or null
};

// One open job. Slots belong to the pool and live as long as it, so a worker may touch a slot's atomics after the
// job's owner has returned; it touches the owner's stack (the body) only while it holds a claimed, unfinished
// chunk, which the owner waits for.
struct alignas(64) Slot {
    JobView job;        // written by the owner and read by workers, both under the pool mutex
    bool open = false;  // a job is published here and its owner has not taken it back (under the mutex)
    // Unclaimed chunks [front, back) and the job's generation, in one word (packClaim). The owner takes chunks
    // from the front and workers from the back, so with two threads each runs one contiguous run of rows (cache
    // locality, and no two threads writing next to each other as with interleaved chunks: ICP's per-stripe sums
    // shared cache lines that way). The generation makes the claim of a worker that copied an earlier job of this
    // slot fail instead of taking a chunk of the new one.
    std::atomic<uint64_t> claim{0};
    std::atomic<int> remaining{0};  // chunks not finished yet; the owner waits for 0
};

constexpr uint64_t packClaim(uint32_t generation, int front, int back) {
    return static_cast<uint64_t>(generation) << 32 | static_cast<uint64_t>(front) << 16 | static_cast<uint64_t>(back);
}
constexpr uint32_t claimGeneration(uint64_t v) { return static_cast<uint32_t>(v >> 32); }
constexpr int claimFront(uint64_t v) { return static_cast<int>((v >> 16) & 0xffffu); }
constexpr int claimBack(uint64_t v) { return static_cast<int>(v & 0xffffu); }

void runChunk(const JobView& j, int c) {
    // 64-bit: n * c overflows int for large ranges. Chunk sizes differ by at most one.
    const int lo = static_cast<int>(j.begin + j.n * c / j.n_chunks);
    const int hi = static_cast<int>(j.begin + j.n * (c + 1) / j.n_chunks);
    j.fn(j.body, lo, hi);
}

// Polls done() until it holds or kPollBeforeSleep has passed, yielding the core between polls.
template <class Done>
void pollFor(Done done) {
    const auto until = std::chrono::steady_clock::now() + kPollBeforeSleep;
    while (!done() && std::chrono::steady_clock::now() < until) std::this_thread::yield();
}

void finishChunk(Slot& s) {
    if (s.remaining.fetch_sub(1, std::memory_order_acq_rel) == 1) s.remaining.notify_all();
}

class Pool {
 public:
    Pool() = default;
    Pool(const Pool&) = delete;
    Pool& operator=(const Pool&) = delete;
    ~Pool();

    // Publishes a job and wakes workers for it; nullptr when every slot is taken or the pool is stopping (the
    // caller then runs the job alone).
    Slot* open(detail::ChunkFn fn, void* body, int begin, int64_t n, int n_chunks, std::atomic<int64_t>* cpu_ns);
    // Runs the unclaimed chunks of the caller's own job, waits for those workers took, frees the slot.
    void runAndClose(Slot& s);

    void lockForFork() { mu_.lock(); }
    void unlockAfterFork() { mu_.unlock(); }
    void resetInChild();

 private:
    void startLocked();
    void workerLoop(int id);
    Slot* findOpenLocked(int from);

    std::mutex mu_;
    std::condition_variable wake_;
    std::array<Slot, kSlots> slots_;
    std::vector<std::thread> workers_;    // allocated once, on the first job
    int sleeping_ = 0;                    // workers waiting on wake_
    std::atomic<uint32_t> published_{0};  // jobs published so far: polling workers watch it
    bool started_ = false;
    bool stop_ = false;
};

// Set while the pool has workers: the fork handlers act only then.
constinit std::atomic<Pool*> g_pool{nullptr};
// Set once the pool is destroyed at exit: a parallelFor from a later static destructor runs on its caller.
constinit std::atomic<bool> g_pool_gone{false};

Pool& pool() {
    static Pool p;  // constructed on first use; holds no thread until the first job
    return p;
}

void prepareFork() {
    if (Pool* p = g_pool.load()) p->lockForFork();
}
void parentAfterFork() {
    if (Pool* p = g_pool.load()) p->unlockAfterFork();
}
void childAfterFork() {
    if (Pool* p = g_pool.load()) p->resetInChild();
}

void Pool::startLocked() {
    started_ = true;
    static std::once_flag fork_handlers;
    // A forked child has only the forking thread: without these it would inherit a pool whose workers do not
    // exist (and a mutex one of them may have held), and its exit would wait for them forever.
    std::call_once(fork_handlers, [] { pthread_atfork(prepareFork, parentAfterFork, childAfterFork); });
    const int n = plannedThreads() - 1;
    workers_.reserve(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
        try {
            workers_.emplace_back([this, i] { workerLoop(i); });
        } catch (const std::system_error&) {
            break;  // no more threads to be had: the callers run what the workers cannot
        }
    }
    g_pool.store(this);
}

Slot* Pool::open(detail::ChunkFn fn, void* body, int begin, int64_t n, int n_chunks, std::atomic<int64_t>* cpu_ns) {
    Slot* slot = nullptr;
    bool wake_all = false;
    int wake = 0;
    {
        std::lock_guard lock(mu_);
        if (stop_) return nullptr;
        if (!started_) startLocked();
        for (Slot& s : slots_) {
            if (!s.open) {
                slot = &s;
                break;
            }
        }
        if (slot == nullptr) return nullptr;
        const uint32_t generation = slot->job.generation + 1;
        slot->job = JobView{fn, body, begin, n, n_chunks, generation, cpu_ns};
        slot->open = true;
        published_.fetch_add(1, std::memory_order_relaxed);
        slot->remaining.store(n_chunks, std::memory_order_relaxed);
        slot->claim.store(packClaim(generation, 0, n_chunks), std::memory_order_release);
        // The caller takes one chunk itself; wake no more sleepers than there are chunks left for them.
        wake = std::min(sleeping_, n_chunks - 1);
        wake_all = wake == sleeping_;
    }
    if (wake == 0) return slot;
    if (wake_all) {
        wake_.notify_all();
    } else {
        for (int i = 0; i < wake; ++i) wake_.notify_one();
    }
    return slot;
}

void Pool::runAndClose(Slot& s) {
    const JobView& j = s.job;  // only this thread writes it while the slot is open
    // The owner's claims need no generation check: the slot cannot be reused before it closes it.
    uint64_t v = s.claim.load(std::memory_order_acquire);
    while (claimFront(v) < claimBack(v)) {
        if (!s.claim.compare_exchange_weak(v, v + (1u << 16), std::memory_order_acq_rel, std::memory_order_acquire)) {
            continue;  // v now holds the current value
        }
        runChunk(j, claimFront(v));
        finishChunk(s);
        v = s.claim.load(std::memory_order_acquire);
    }
    // Chunks claimed by workers: their writes happen-before this acquire of the count reaching 0. Workers are
    // mid-chunk, so poll first: a sleeping caller would pay the wake-up on the frame's critical path.
    pollFor([&] { return s.remaining.load(std::memory_order_acquire) == 0; });
    for (int left = s.remaining.load(std::memory_order_acquire); left != 0;
         left = s.remaining.load(std::memory_order_acquire)) {
        s.remaining.wait(left, std::memory_order_acquire);
    }
    std::lock_guard lock(mu_);
    s.open = false;
}

Slot* Pool::findOpenLocked(int from) {
    for (int k = 0; k < kSlots; ++k) {
        Slot& s = slots_[static_cast<size_t>((from + k) % kSlots)];
        if (!s.open) continue;
        const uint64_t v = s.claim.load(std::memory_order_relaxed);
        if (claimFront(v) < claimBack(v)) return &s;
    }
    return nullptr;
}

void Pool::workerLoop(int id) {
    nameThisThread("fs-pool");
    std::unique_lock lock(mu_);
    bool polled = false;  // since the last job: poll once, then sleep
    for (;;) {
        if (stop_) return;
        Slot* s = findOpenLocked(id);
        if (s == nullptr && !polled) {
            polled = true;
            const uint32_t seen = published_.load(std::memory_order_relaxed);
            lock.unlock();
            pollFor([&] { return published_.load(std::memory_order_relaxed) != seen; });
            lock.lock();
            continue;  // look again under the mutex: a job published just after the poll ended is seen here
        }
        if (s == nullptr) {
            ++sleeping_;
            wake_.wait(lock);
            --sleeping_;
            polled = false;
            continue;
        }
        polled = false;
        const JobView j = s->job;
        lock.unlock();
        const int64_t cpu0 = j.cpu_ns ? threadCpuNs() : 0;
        // The last chunk this worker ran is finished only after it failed to claim another: until then the owner
        // keeps waiting, so its accounting sink (on the owner's thread) is still there to add this job's CPU to.
        bool unfinished = false;
        uint64_t v = s->claim.load(std::memory_order_acquire);
        // Stop when the job closed and the slot holds another one, or nothing is left to claim.
        while (claimGeneration(v) == j.generation && claimFront(v) < claimBack(v)) {
            if (!s->claim.compare_exchange_weak(v, v - 1, std::memory_order_acq_rel, std::memory_order_acquire)) {
                continue;  // v now holds the current value
            }
            if (unfinished) finishChunk(*s);
            runChunk(j, claimBack(v) - 1);
            unfinished = true;
            v = s->claim.load(std::memory_order_acquire);
        }
        if (unfinished) {
            if (j.cpu_ns) j.cpu_ns->fetch_add(threadCpuNs() - cpu0, std::memory_order_relaxed);
            finishChunk(*s);
        }
        lock.lock();
    }
}

void Pool::resetInChild() {
    // The forking thread locked mu_ in prepareFork and is the child's only thread. The workers are gone: forget
    // their handles without joining (no such threads here) or destroying them (a joinable std::thread terminates),
    // and start afresh on the child's next job. The condition variable may record the parent's sleeping workers.
    for (std::thread& t : workers_) new (&t) std::thread();
    workers_.clear();
    new (&wake_) std::condition_variable();
    for (Slot& s : slots_) {
        s.open = false;
        s.remaining.store(0, std::memory_order_relaxed);
    }
    sleeping_ = 0;
    started_ = false;
    g_pool.store(nullptr);
    mu_.unlock();
}

Pool::~Pool() {
    g_pool_gone.store(true);
    {
        std::lock_guard lock(mu_);
        stop_ = true;
        g_pool.store(nullptr);
    }
    wake_.notify_all();
    for (std::thread& t : workers_) {
        // exit() called from inside a body on a worker: that worker cannot join itself.
        if (t.get_id() == std::this_thread::get_id()) {
            t.detach();
        } else {
            t.join();
        }
    }
}

}  // namespace

namespace detail {

void parallelForErased(int begin, int end, ChunkFn fn, void* body) {
    const int64_t n = static_cast<int64_t>(end) - begin;
    if (n <= 0) return;
    const int n_chunks = static_cast<int>(std::min<int64_t>(n, plannedThreads() * kChunksPerThread));
    Slot* slot = nullptr;
    if (plannedThreads() > 1 && n > 1 && !t_serial && !g_pool_gone.load(std::memory_order_relaxed)) {
        slot = pool().open(fn, body, begin, n, n_chunks, t_accounting ? &t_pool_cpu_ns : nullptr);
    }
    if (slot == nullptr) {
        fn(body, begin, end);  // one core, one index, a serial thread, every slot taken, or the process is exiting
        return;
    }
    pool().runAndClose(*slot);
}

}  // namespace detail

int parallelThreadCount() { return plannedThreads(); }

void nameThisThread(const char* name) {
    char truncated[16] = {};  // the kernel keeps 15 characters and refuses a longer name outright
    for (size_t i = 0; i < sizeof(truncated) - 1 && name[i] != '\0'; ++i) truncated[i] = name[i];
    (void)pthread_setname_np(pthread_self(), truncated);
}

void setParallelSerial(bool serial) { t_serial = serial; }
bool parallelSerial() { return t_serial; }
void setParallelAccounting(bool on) { t_accounting = on; }
bool parallelAccounting() { return t_accounting; }
int64_t parallelPoolCpuNs() { return t_pool_cpu_ns.load(std::memory_order_acquire); }

}  // namespace facescan::recon
