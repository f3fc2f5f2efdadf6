// How many objects of a kind are alive in this process. The server's memory line (server_memory.cpp) sets the
// sessions still in memory beside those it has open: a session that left the server's books but not its heap shows
// there, instead of only as resident memory that grows.
#pragma once

#include <atomic>

namespace facescan::service {

template <class Tag>
class LiveCount {
 public:
    LiveCount() noexcept { count_.fetch_add(1, std::memory_order_relaxed); }
    LiveCount(const LiveCount&) noexcept : LiveCount() {}
    LiveCount& operator=(const LiveCount&) noexcept { return *this; }
    ~LiveCount() { count_.fetch_sub(1, std::memory_order_relaxed); }

    static int alive() { return count_.load(std::memory_order_relaxed); }

 private:
    static inline std::atomic<int> count_{0};
};

}  // namespace facescan::service
