// Counts heap allocations of the whole process (docs/design.md s4: the frame loop allocates nothing after warm-up;
// tests and the bench check that). Include this header in exactly ONE source file of an executable: it defines the
// replacement functions. Executables that include it count every allocation, so keep it out of test programs that
// do not need it.
//
// Two doors into the heap are counted: the global operator new (C++ containers, strings, std::function) and the
// C allocator (malloc, calloc, realloc, posix_memalign, aligned_alloc, memalign), which OpenCV's cv::Mat buffers
// (cv::fastMalloc), Eigen's dynamic matrices and C libraries use. operator new here calls malloc, so one `new` counts
// once. The C functions forward to glibc's own (__libc_*): same heap, so memory from either side may be freed by
// either. Under AddressSanitizer or ThreadSanitizer, whose runtimes replace the C allocator themselves, only
// operator new is counted.
#pragma once

// Replacing operator new with malloc/free is deliberate (allocation counting); GCC flags the pairing.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdlib>
#include <new>

namespace facescan::testing {
inline std::atomic<long> g_heap_allocations{0};
// Allocations (operator new and the C allocator) since the program started.
inline long heapAllocations() { return g_heap_allocations.load(std::memory_order_relaxed); }
}  // namespace facescan::testing

#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
#define FACESCAN_COUNT_C_ALLOCATOR 1
extern "C" {
void* __libc_malloc(std::size_t n) noexcept;
void* __libc_calloc(std::size_t n, std::size_t size) noexcept;
void* __libc_realloc(void* p, std::size_t n) noexcept;
void* __libc_memalign(std::size_t alignment, std::size_t n) noexcept;

void* malloc(std::size_t n) noexcept {
    facescan::testing::g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
    facescan::testing::g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) noexcept {
    facescan::testing::g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_realloc(p, n);
}
void* memalign(std::size_t alignment, std::size_t n) noexcept {
    facescan::testing::g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    return __libc_memalign(alignment, n);
}
void* aligned_alloc(std::size_t alignment, std::size_t n) noexcept { return memalign(alignment, n); }
int posix_memalign(void** out, std::size_t alignment, std::size_t n) noexcept {
    if (alignment % sizeof(void*) != 0 || (alignment & (alignment - 1)) != 0) return EINVAL;
    void* p = memalign(alignment, n);
    if (p == nullptr) return ENOMEM;
    *out = p;
    return 0;
}
}
#endif

void* operator new(std::size_t n) {
#ifndef FACESCAN_COUNT_C_ALLOCATOR
    facescan::testing::g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
#endif
    if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
    throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
