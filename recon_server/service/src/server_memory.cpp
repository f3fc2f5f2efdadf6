// What a server holds in memory, in its log. A compute box runs for weeks: when its memory grows, the operator (and
// the soak, tests/bench/chaos.sh) must see whether it is the heap (something kept), the allocator (freed memory
// held) or neither (the DDS library, mapped files), and which of the server's holdings grew.
#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <string>

#include "service/replication.hpp"
#include "service/server.hpp"

namespace facescan::service {
namespace {

constexpr int64_t kMemoryLineEveryNs = 60'000'000'000;
// Idle, the check is cheap and the memory is all freed; under load a trim costs page faults (the kernel zeroes the
// pages given back when the sessions' buffers grow into them again), so it comes seldom.
constexpr int64_t kTrimCheckIdleNs = 2'000'000'000;
constexpr int64_t kTrimCheckBusyNs = 30'000'000'000;
// Resident beyond the heap in use and what the process held before its first session: past this, freed memory is
// given back to the system. Idle, nothing will reuse it soon, and a trim is a walk over a small heap: so almost
// all of it goes (with 32 MB held back when idle too, a soak's idle server read 91-111 MB from checkpoint to
// checkpoint with its heap in use at 29-35 MB).
constexpr double kHeldResidentBusyMiB = 32.0;
constexpr double kHeldResidentIdleMiB = 4.0;
constexpr double kMiB = 1.0 / (1024.0 * 1024.0);

double residentMiB() {
    std::ifstream statm("/proc/self/statm");
    long pages_total = 0;
    long pages_resident = 0;
    if (!(statm >> pages_total >> pages_resident)) return 0;
    return static_cast<double>(pages_resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) * kMiB;
}

}  // namespace

void Server::returnHeldMemory(int64_t now_ns) {
    // The retiring thread trims once its queue drains, after the frees it does itself. Other threads free as much:
    // the replication thread a standby copy it no longer needs, the status thread a finished session's volume, a
    // worker its buffers. Without a trim after those, an idle server of the chaos soak held 261 MB resident with
    // 29 MB of heap in use, more at every idle checkpoint.
    const bool idle = openSessions() == 0;
    if (now_ns - trim_checked_ns_ < (idle ? kTrimCheckIdleNs : kTrimCheckBusyNs)) return;
    trim_checked_ns_ = now_ns;
    const struct mallinfo2 heap = ::mallinfo2();
    const double outside_heap_mib = residentMiB() - static_cast<double>(heap.uordblks + heap.hblkhd) * kMiB;
    if (baseline_outside_heap_mib_ < 0) baseline_outside_heap_mib_ = outside_heap_mib;  // the libraries, DDS
    if (outside_heap_mib - baseline_outside_heap_mib_ > (idle ? kHeldResidentIdleMiB : kHeldResidentBusyMiB)) {
        ::malloc_trim(0);
    }
}

void Server::logMemory(int64_t now_ns) {
    if (now_ns - memory_logged_ns_ < kMemoryLineEveryNs) return;
    memory_logged_ns_ = now_ns;
    const struct mallinfo2 heap = ::mallinfo2();
    const double resident_mib = residentMiB();
    const double in_use_mib = static_cast<double>(heap.uordblks + heap.hblkhd) * kMiB;
    // Resident beyond the heap in use and the libraries' share at start: freed, not yet given back.
    const double held_mib = std::max(0.0, resident_mib - in_use_mib - std::max(0.0, baseline_outside_heap_mib_));
    const double standby_mib = static_cast<double>(replicator_->standbyBytes()) * kMiB;
    char counts[256];
    std::snprintf(counts, sizeof counts,
                  "%d sessions open, %d in memory (%d records); %d standby copies (%.0f MB); %zu finished listed; "
                  "%d frame readers lingering",
                  openSessions(), Session::liveCount(), LiveCount<OwnedSession>::alive(), replicator_->standbyCount(),
                  standby_mib, finished_.size(), lingering_count_.load());
    // Said again when the holdings changed, or when the heap moved by 8 MB or more: a steady server stays quiet.
    const std::string said = std::string(counts) + " " + std::to_string(static_cast<long>(in_use_mib / 8));
    if (said == memory_said_) return;
    memory_said_ = said;
    std::fprintf(stderr,
                 "facescan-server: memory: %.0f MB resident: heap %.0f MB in use, about %.0f MB freed and not given "
                 "back yet; %s\n",
                 resident_mib, in_use_mib, held_mib, counts);
}

}  // namespace facescan::service
