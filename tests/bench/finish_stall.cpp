// facescan-bench texture --stall: finish_stall.hpp.
#include "finish_stall.hpp"

#include <dirent.h>
#include <sched.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "recon/reconstructor.hpp"
#include "service/frame_load.hpp"

namespace facescan::bench {
namespace {

// Every thread of the process (the pool's workers included) on the core the calling thread runs on now.
Status holdToOneCore() {
    cpu_set_t one;
    CPU_ZERO(&one);
    const int cpu = sched_getcpu();
    if (cpu < 0) return unavailable("cannot tell which core this thread runs on");
    CPU_SET(cpu, &one);
    DIR* tasks = opendir("/proc/self/task");
    if (!tasks) return unavailable("cannot list /proc/self/task");
    Status st = Status::ok();
    while (const dirent* e = readdir(tasks)) {
        if (e->d_name[0] == '.') continue;
        const pid_t tid = static_cast<pid_t>(std::atoi(e->d_name));
        if (sched_setaffinity(tid, sizeof one, &one) != 0) st = unavailable("cannot hold the threads to one core");
    }
    closedir(tasks);
    return st;
}

void releaseCores() {
    cpu_set_t all;
    CPU_ZERO(&all);
    for (int c = 0; c < CPU_SETSIZE; ++c) CPU_SET(c, &all);
    if (DIR* tasks = opendir("/proc/self/task")) {
        while (const dirent* e = readdir(tasks)) {
            if (e->d_name[0] != '.')
                (void)sched_setaffinity(static_cast<pid_t>(std::atoi(e->d_name)), sizeof all, &all);
        }
        closedir(tasks);
    }
}

}  // namespace

StatusOr<StallFigures> measureFinishStall(const Sequence& seq, const std::function<void()>& finish, bool as_server) {
    RETURN_IF_ERROR(holdToOneCore());
    // The scanning session: frames in a loop until told to stop, counting those done in each phase.
    std::atomic<int> phase{0};  // 0 warm-up, 1 alone, 2 beside the finish, 3 stop
    std::atomic<int64_t> frames[3] = {0, 0, 0};
    std::thread scanning([&] {
        service::FrameLoad load(30.0f);
        load.join();  // one running worker, as a scanning session is
        recon::Reconstructor rec(seq.k, recon::ReconParams::faceDefaults());
        for (size_t i = 0; phase.load() < 3; ++i) {
            const size_t f = i % seq.frames.size();
            if (f == 0 && i > 0) rec.reset();
            rec.processFrame(seq.frames[f], seq.masks[f]);
            const int p = phase.load();
            if (p < 3) frames[p].fetch_add(1);
        }
        load.leave();
    });
    using Clock = std::chrono::steady_clock;
    auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
    std::this_thread::sleep_for(std::chrono::seconds(1));
    phase = 1;
    const auto t_alone = Clock::now();
    std::this_thread::sleep_for(std::chrono::seconds(3));
    const double alone_s = seconds(Clock::now() - t_alone);
    const int64_t alone_frames = frames[1].load();
    phase = 2;
    const auto t_finish = Clock::now();
    std::thread finishing([&] {
        service::FrameLoad load(30.0f);
        load.join();  // the finishing session's worker, which scanned before
        if (as_server) load.leaveToFinish();
        finish();
        load.leave();
    });
    finishing.join();
    StallFigures out;
    out.finish_wall_s = seconds(Clock::now() - t_finish);
    const int64_t beside_frames = frames[2].load();
    phase = 3;
    scanning.join();
    releaseCores();
    out.alone_fps = static_cast<double>(alone_frames) / alone_s;
    out.beside_fps = static_cast<double>(beside_frames) / out.finish_wall_s;
    return out;
}

}  // namespace facescan::bench
