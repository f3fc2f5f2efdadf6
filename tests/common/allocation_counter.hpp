// Counts heap allocations of the whole process by replacing the global operator new (DESIGN.md s4: the frame loop
// allocates nothing after warm-up; tests and the bench check that). Include this header in exactly ONE source file
// of an executable: it defines the replacement operators. Executables that include it count every allocation, so
// keep it out of test programs that do not need it.
#pragma once

// Replacing operator new with malloc/free is deliberate (allocation counting); GCC flags the pairing.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

#include <atomic>
#include <cstdlib>
#include <new>

namespace facescan::testing {
inline std::atomic<long> g_heap_allocations{0};
// Allocations through operator new since the program started.
inline long heapAllocations() { return g_heap_allocations.load(std::memory_order_relaxed); }
}  // namespace facescan::testing

void* operator new(std::size_t n) {
    facescan::testing::g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
    throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
