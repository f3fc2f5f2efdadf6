// recon::parallelFor: every index exactly once for any range, concurrent and nested callers, work really shared
// with the pool, fork safety, and no heap allocation per call after warm-up (the frame loop's contract, docs/design.md
// s4); and the whole Reconstructor frame loop allocating nothing after warm-up (FrameLoop). Allocations are
// counted by replacing the global operator new in this executable only (allocation_counter.hpp).
#include "recon/parallel.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <climits>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <new>
#include <thread>
#include <vector>

#include "allocation_counter.hpp"
#include "cpu_burn.hpp"
#include "recon/face_pipeline.hpp"
#include "recon/reconstructor.hpp"
#include "recon/scan_step.hpp"

namespace facescan::recon {
namespace {

// Runs parallelFor over [begin, end) and returns how often each index was visited (plain ints: chunks own
// disjoint indices, and the call's return must make their writes visible here). Flags a chunk that is empty or
// leaves the range.
struct Coverage {
    std::vector<int> visits;
    bool bad_chunk = false;
};
Coverage cover(int begin, int end) {
    Coverage c;
    c.visits.assign(static_cast<size_t>(std::max(0, end - begin)), 0);
    std::atomic<bool> bad{false};
    parallelFor(begin, end, [&](int lo, int hi) {
        if (!(begin <= lo && lo < hi && hi <= end)) {
            bad = true;
            return;
        }
        for (int i = lo; i < hi; ++i) ++c.visits[static_cast<size_t>(i - begin)];
    });
    c.bad_chunk = bad.load();
    return c;
}

// Index of the first visit count that is not 1, or -1.
int firstWrong(const Coverage& c) {
    for (size_t i = 0; i < c.visits.size(); ++i)
        if (c.visits[i] != 1) return static_cast<int>(i);
    return -1;
}

TEST(ParallelFor, EmptyAndReversedRangesCallNothing) {
    int calls = 0;
    parallelFor(5, 5, [&](int, int) { ++calls; });
    parallelFor(7, 3, [&](int, int) { ++calls; });
    parallelFor(INT_MAX, INT_MIN, [&](int, int) { ++calls; });
    EXPECT_EQ(calls, 0);
}

TEST(ParallelFor, CoversEveryIndexExactlyOnce) {
    const int t = parallelThreadCount();
    ASSERT_GE(t, 1);
    // One index, fewer indices than threads, around the chunk count, and large; offsets include negatives.
    const int sizes[] = {1, 2, 3, t - 1, t, t + 1, 7, 8 * t - 1, 8 * t, 8 * t + 1, 100, 479, 1000, 100003};
    for (const int begin : {0, 13, -50}) {
        for (const int size : sizes) {
            if (size < 1) continue;
            const Coverage c = cover(begin, begin + size);
            EXPECT_FALSE(c.bad_chunk) << "begin " << begin << " size " << size;
            EXPECT_EQ(firstWrong(c), -1) << "begin " << begin << " size " << size;
        }
    }
}

TEST(ParallelFor, RangesAtTheEndsOfIntDoNotOverflow) {
    for (const auto& [begin, end] : {std::pair{INT_MAX - 1000, INT_MAX}, std::pair{INT_MIN, INT_MIN + 1000}}) {
        const Coverage c = cover(begin, end);
        EXPECT_FALSE(c.bad_chunk);
        EXPECT_EQ(firstWrong(c), -1);
    }
    // The whole int range: end - begin does not fit an int. Chunks must still tile it exactly.
    std::atomic<int64_t> covered{0};
    std::atomic<bool> bad{false};
    parallelFor(INT_MIN, INT_MAX, [&](int lo, int hi) {
        if (!(lo < hi)) bad = true;
        covered += static_cast<int64_t>(hi) - lo;
    });
    EXPECT_FALSE(bad.load());
    EXPECT_EQ(covered.load(), static_cast<int64_t>(INT_MAX) - INT_MIN);
}

TEST(ParallelFor, WorkersShareTheWork) {
    if (parallelThreadCount() < 2) GTEST_SKIP() << "one hardware thread: the caller runs every chunk";
    // Chunks that take a while: a worker woken for the job must take some of them, and the call must not return
    // before the worker's chunks are done. Retried because a loaded machine may leave the worker unscheduled for
    // one call.
    const std::thread::id caller = std::this_thread::get_id();
    bool shared = false;
    for (int attempt = 0; attempt < 20 && !shared; ++attempt) {
        std::atomic<int> on_other_threads{0}, finished{0};
        parallelFor(0, 64, [&](int lo, int hi) {
            if (std::this_thread::get_id() != caller) {
                on_other_threads += hi - lo;
                // Slower than the caller's chunks: the caller runs out of chunks first and must wait for this one.
                std::this_thread::sleep_for(std::chrono::milliseconds(2));
            } else {
                std::this_thread::sleep_for(std::chrono::microseconds(100));
            }
            finished += hi - lo;
        });
        ASSERT_EQ(finished.load(), 64) << "returned before every chunk had finished";
        shared = on_other_threads.load() > 0;
    }
    EXPECT_TRUE(shared) << "no chunk ever ran off the calling thread";
}

// A serial thread runs its calls alone, covering everything, while the pool stays with the others.
TEST(ParallelFor, SerialThreadRunsItsCallsAloneAndOthersKeepThePool) {
    std::thread t([] {
        setParallelSerial(true);
        EXPECT_TRUE(parallelSerial());
        const std::thread::id self = std::this_thread::get_id();
        std::atomic<int> elsewhere{0};
        parallelFor(0, 64, [&](int lo, int hi) {
            if (std::this_thread::get_id() != self) elsewhere += hi - lo;
        });
        EXPECT_EQ(elsewhere.load(), 0) << "a serial thread's chunks ran on the pool";
        EXPECT_EQ(firstWrong(cover(-5, 1000)), -1);
    });
    t.join();
    EXPECT_FALSE(parallelSerial()) << "serial is per thread";
    EXPECT_EQ(firstWrong(cover(0, 1000)), -1);
}

// With accounting on, the CPU pool workers spend on a thread's calls is charged to that thread (what a
// session worker's frames cost, whoever ran them); off, or serial, nothing is charged.
TEST(ParallelFor, PoolWorkersChargeTheirCpuToTheCallingThread) {
    if (parallelThreadCount() < 2) GTEST_SKIP() << "one hardware thread: no pool workers";
    std::thread t([] {
        const std::thread::id self = std::this_thread::get_id();
        auto run = [&](std::atomic<int64_t>& elsewhere_ns) {
            parallelFor(0, 32, [&](int lo, int hi) {
                testing::burnCpuNs(200'000LL * (hi - lo));
                if (std::this_thread::get_id() != self) elsewhere_ns += 200'000LL * (hi - lo);
            });
        };
        std::atomic<int64_t> off_ns{0};
        run(off_ns);
        EXPECT_EQ(parallelPoolCpuNs(), 0) << "charged while accounting was off";
        setParallelAccounting(true);
        bool charged = false;
        for (int attempt = 0; attempt < 20 && !charged; ++attempt) {  // a loaded machine may leave the worker out
            std::atomic<int64_t> elsewhere_ns{0};
            const int64_t before = parallelPoolCpuNs();
            run(elsewhere_ns);
            const int64_t got = parallelPoolCpuNs() - before;
            // At least the CPU the worker's chunks burnt (plus its claiming and polling).
            EXPECT_GE(got, elsewhere_ns.load());
            charged = elsewhere_ns.load() > 0;
        }
        EXPECT_TRUE(charged) << "no chunk ever ran on a pool worker";
        setParallelSerial(true);
        const int64_t before = parallelPoolCpuNs();
        std::atomic<int64_t> serial_ns{0};
        run(serial_ns);
        EXPECT_EQ(parallelPoolCpuNs(), before);
        setParallelAccounting(false);
    });
    t.join();
}

TEST(ParallelFor, ConcurrentCallersFromFourThreads) {
    std::atomic<int> failures{0};
    std::vector<std::thread> callers;
    for (int t = 0; t < 4; ++t) {
        callers.emplace_back([t, &failures] {
            for (int call = 0; call < 200; ++call) {
                const int begin = t * 1000 - 2000 + call, size = 1 + (call * 37 + t * 11) % 600;
                const Coverage c = cover(begin, begin + size);
                if (c.bad_chunk || firstWrong(c) != -1) ++failures;
            }
        });
    }
    for (std::thread& th : callers) th.join();
    EXPECT_EQ(failures.load(), 0);
}

TEST(ParallelFor, MoreConcurrentCallersThanJobSlotsStillCoverEverything) {
    // More simultaneous jobs than the pool has slots (16): the surplus callers run their jobs alone.
    std::atomic<int> failures{0};
    std::vector<std::thread> callers;
    for (int t = 0; t < 24; ++t) {
        callers.emplace_back([t, &failures] {
            for (int call = 0; call < 40; ++call) {
                std::vector<int> visits(300, 0);
                parallelFor(0, 300, [&](int lo, int hi) {
                    for (int i = lo; i < hi; ++i) ++visits[static_cast<size_t>(i)];
                    if (t % 3 == 0) std::this_thread::yield();  // keep slots held while others ask for one
                });
                for (const int v : visits)
                    if (v != 1) ++failures;
            }
        });
    }
    for (std::thread& th : callers) th.join();
    EXPECT_EQ(failures.load(), 0);
}

TEST(ParallelFor, NestedCallFromInsideABody) {
    constexpr int kOuter = 24, kInner = 150;
    std::vector<int> visits(kOuter * kInner, 0);
    parallelFor(0, kOuter, [&](int lo, int hi) {
        for (int o = lo; o < hi; ++o) {
            parallelFor(0, kInner, [&](int ilo, int ihi) {
                for (int i = ilo; i < ihi; ++i) ++visits[static_cast<size_t>(o * kInner + i)];
            });
        }
    });
    for (size_t i = 0; i < visits.size(); ++i) ASSERT_EQ(visits[i], 1) << "index " << i;
}

TEST(ParallelFor, ReductionOverFixedStripesIsDeterministic) {
    // The ICP pattern: one partial per fixed stripe, summed in stripe order after the call. Float sums depend on
    // order, so equal bits across runs show that the stripes, not the chunks, define the result.
    constexpr int kStripes = 16, kN = 100000;
    auto reduce = [] {
        std::vector<double> partial(kStripes, 0.0);
        parallelFor(0, kStripes, [&](int lo, int hi) {
            for (int s = lo; s < hi; ++s) {
                for (int i = kN * s / kStripes; i < kN * (s + 1) / kStripes; ++i) partial[s] += 1.0 / (1.0 + i);
            }
        });
        double sum = 0.0;
        for (const double p : partial) sum += p;
        return sum;
    };
    double serial = 0.0;
    for (int s = 0; s < kStripes; ++s) {
        double p = 0.0;
        for (int i = kN * s / kStripes; i < kN * (s + 1) / kStripes; ++i) p += 1.0 / (1.0 + i);
        serial += p;
    }
    for (int run = 0; run < 20; ++run) ASSERT_EQ(reduce(), serial) << "run " << run;
}

TEST(ParallelFor, CallAfterWarmUpDoesNotAllocate) {
    // A body larger than std::function's small buffer (cv::parallel_for_ copied it to the heap on every call).
    std::vector<float> data(5000, 1.0f);
    double pad[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    std::atomic<int> touched{0};
    auto run = [&] {
        parallelFor(0, static_cast<int>(data.size()), [&, pad](int lo, int hi) {
            for (int i = lo; i < hi; ++i) data[static_cast<size_t>(i)] += static_cast<float>(pad[i % 8]);
            touched += hi - lo;
        });
        parallelFor(0, 8, [&](int lo, int hi) {  // nested, as a stage inside a parallel stage would
            for (int o = lo; o < hi; ++o) parallelFor(0, 64, [&](int a, int b) { touched += b - a; });
        });
    };
    run();  // warm-up: starts the pool's threads
    const long before = testing::heapAllocations();
    for (int i = 0; i < 200; ++i) run();
    const long after = testing::heapAllocations();
    EXPECT_EQ(after - before, 0) << "allocations in 200 calls after warm-up";
    EXPECT_EQ(touched.load(), 201 * (5000 + 8 * 64));
    // The counter itself works (else the check above could not fail).
    void* volatile probe = ::operator new(16);  // a direct call: the compiler may elide a new-expression
    ::operator delete(probe);
    EXPECT_EQ(testing::heapAllocations(), after + 1);
}

TEST(ParallelFor, ForkedChildRunsLoopsAndExitsCleanly) {
#if defined(__SANITIZE_THREAD__)
    GTEST_SKIP() << "ThreadSanitizer does not support starting threads after a multi-threaded fork";
#endif
    (void)cover(0, 1000);  // the pool's workers exist in the parent
    std::fflush(nullptr);  // no buffered output duplicated in the child
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        // Only this thread exists here. Loops must still work, and exit() runs the pool's destructor, which
        // must not wait for the parent's workers.
        bool ok = true;
        for (int size : {1, 50, 1000}) {
            const Coverage c = cover(0, size);
            ok = ok && !c.bad_chunk && firstWrong(c) == -1;
        }
        std::exit(ok ? 0 : 3);
    }
    int status = 0;
    pid_t done = 0;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while ((done = waitpid(child, &status, WNOHANG)) == 0 && std::chrono::steady_clock::now() < deadline) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (done == 0) {
        kill(child, SIGKILL);
        waitpid(child, &status, 0);
        FAIL() << "the forked child hung (in a loop or at exit)";
    }
    ASSERT_TRUE(WIFEXITED(status)) << "child status " << status;
    EXPECT_EQ(WEXITSTATUS(status), 0) << "child's loops missed or repeated indices";
    // The parent's pool is untouched by the fork.
    const Coverage c = cover(-7, 5000);
    EXPECT_FALSE(c.bad_chunk);
    EXPECT_EQ(firstWrong(c), -1);
}

// A sphere (the "head") before a tilted wall, seen by a Kinect v1 camera that slides 1 mm and turns 0.2 deg per
// frame: analytic depth, so the test needs no renderer or data. head_mask: the sphere's pixels, as the segmenter
// would give.
RgbdFrame sphereBeforeWall(int i, cv::Mat& head_mask) {
    const Intrinsics k = Intrinsics::kinectV1();
    const Pose T_world_camera(Eigen::Translation3f(0.001f * static_cast<float>(i), 0, 0) *
                              Eigen::AngleAxisf(0.0035f * static_cast<float>(i), Eigen::Vector3f::UnitY()));
    const Pose T_camera_world = T_world_camera.inverse();
    const Eigen::Vector3f c = T_camera_world * Eigen::Vector3f(0, 0, 0.7f);
    const float r = 0.08f;
    const Eigen::Vector3f wall_n = (T_camera_world.linear() * Eigen::Vector3f(0.2f, 0.1f, -1.0f)).normalized();
    const float wall_d = wall_n.dot(T_camera_world * Eigen::Vector3f(0, 0, 0.95f));
    RgbdFrame f;
    f.depth_m = cv::Mat(k.height_px, k.width_px, CV_32F, cv::Scalar(0));
    f.timestamp_ns = int64_t{33'333'333} * i;
    head_mask = cv::Mat(k.height_px, k.width_px, CV_8UC1, cv::Scalar(0));
    for (int v = 0; v < k.height_px; ++v) {
        for (int u = 0; u < k.width_px; ++u) {
            const Eigen::Vector3f ray = k.ray(static_cast<float>(u), static_cast<float>(v));
            const float a = ray.squaredNorm(), b = ray.dot(c), disc = b * b - a * (c.squaredNorm() - r * r);
            float z = 0.0f;
            if (disc > 0.0f) {
                z = (b - std::sqrt(disc)) / a * ray.z();
                head_mask.at<uint8_t>(v, u) = 255;
            } else if (const float den = wall_n.dot(ray); std::fabs(den) > 1e-6f) {
                z = wall_d / den * ray.z();
            }
            f.depth_m.at<float>(v, u) = z > 0.3f && z < 2.0f ? z : 0.0f;
        }
    }
    return f;
}

TEST(FrameLoop, ReconstructorDoesNotAllocateAfterWarmUp) {
    // docs/design.md (memory): filter, ICP, integration and ray casting allocate nothing per frame after warm-up.
    std::vector<RgbdFrame> frames(12);
    std::vector<cv::Mat> masks(frames.size());
    for (size_t i = 0; i < frames.size(); ++i) frames[i] = sphereBeforeWall(static_cast<int>(i), masks[i]);
    Reconstructor rec(Intrinsics::kinectV1(), ReconParams::faceDefaults());
    ASSERT_TRUE(rec.initStatus().isOk()) << rec.initStatus().toString();
    long before = 0;
    int integrated = 0;
    for (int i = 0; i < static_cast<int>(frames.size()); ++i) {
        if (i == 4) before = testing::heapAllocations();
        const FrameResult r = rec.processFrame(frames[static_cast<size_t>(i)], masks[static_cast<size_t>(i)]);
        integrated += r.integrated ? 1 : 0;
        if (!r.integrated) std::printf("frame %d: %s\n", i, r.reason);
    }
    const long allocations = testing::heapAllocations() - before;
    EXPECT_EQ(integrated, 12) << "every frame must be tracked and fused, or the loop checked is not the full one";
    EXPECT_EQ(allocations, 0) << "heap allocations in 8 frames after 4 warm-up frames";
}

TEST(FrameLoop, FacePipelineAndReconstructorDoNotAllocateAfterWarmUp) {
    // The server's whole per-frame path (recon::scanFrame, as the session worker runs it), detection and
    // segmentation included. Frames without colour, so the detector is the depth-only head finder; it re-detects
    // every 3rd frame (redetect_every_frames) and the tracked model's prediction seeds the segmentation in between
    // (ModelSegmenter), so both paths run after the warm-up.
    std::vector<RgbdFrame> frames(12);
    std::vector<cv::Mat> unused(frames.size());
    for (size_t i = 0; i < frames.size(); ++i) frames[i] = sphereBeforeWall(static_cast<int>(i), unused[i]);
    const Intrinsics k = Intrinsics::kinectV1();
    FacePipelineParams fp;
    fp.redetect_every_frames = 3;
    StatusOr<FacePipeline> created = FacePipeline::create(fp, k, ColourCamera::registeredTo(k));
    ASSERT_TRUE(created.isOk()) << created.status().toString();
    FacePipeline pipeline = std::move(created).value();
    Reconstructor rec(k, ReconParams::faceDefaults());
    ASSERT_TRUE(rec.initStatus().isOk()) << rec.initStatus().toString();
    ScanStep step;
    long before = 0;
    int integrated = 0, detections = 0, from_model = 0;
    for (int i = 0; i < static_cast<int>(frames.size()); ++i) {
        if (i == 4) before = testing::heapAllocations();
        scanFrame(pipeline, rec, frames[static_cast<size_t>(i)], step);
        ASSERT_TRUE(step.head.found) << "frame " << i << ": " << step.head.reason;
        if (i >= 4) detections += step.head.detection_ran ? 1 : 0;
        if (i >= 4) from_model += step.head.from_model ? 1 : 0;
        integrated += step.frame.integrated ? 1 : 0;
        if (!step.frame.integrated) std::printf("frame %d: %s\n", i, step.frame.reason);
    }
    const long allocations = testing::heapAllocations() - before;
    EXPECT_EQ(integrated, 12) << "every frame must be tracked and fused, or the loop checked is not the full one";
    EXPECT_GE(detections, 2) << "re-detection must run after the warm-up, or its allocations go unchecked";
    EXPECT_GE(from_model, 2) << "model-based segmentation must run after the warm-up, or its allocations go unchecked";
    EXPECT_EQ(allocations, 0) << "heap allocations in 8 frames (detection, segmentation, recon) after 4 warm-up frames";
}

}  // namespace
}  // namespace facescan::recon
