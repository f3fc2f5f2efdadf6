#include "service/retirer.hpp"

#include <malloc.h>

#include "recon/parallel.hpp"

namespace facescan::service {

Retirer::Retirer(std::shared_ptr<Watchdog::Beat> beat) : beat_(std::move(beat)) {
    thread_ = std::thread([this] { loop(); });
}

Retirer::~Retirer() {
    {
        std::lock_guard lk(mutex_);
        stopping_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
}

void Retirer::retire(std::function<void()> job) {
    {
        std::lock_guard lk(mutex_);
        jobs_.push_back(std::move(job));
    }
    cv_.notify_one();
}

void Retirer::loop() {
    recon::nameThisThread("fs-retire");
    for (;;) {
        std::function<void()> job;
        {
            std::unique_lock lk(mutex_);
            if (beat_) beat_->end();
            cv_.wait(lk, [&] { return stopping_ || !jobs_.empty(); });
            if (jobs_.empty()) return;  // stopping, and everything handed over has ended
            job = std::move(jobs_.front());
            jobs_.pop_front();
            if (beat_) beat_->begin();
        }
        job();
        job = nullptr;  // what it captured ends here too, still timed by the beat
        // Once the queue is drained, what the jobs freed goes back to the system: freed, a session's buffers stay
        // resident until trimmed (facescan-server keeps one malloc arena, so that the trim reaches all of it), and
        // without the trim an idle server kept hundreds of megabytes from scans given up, released or finished
        // (the chaos soak's idle checkpoints).
        bool drained = false;
        {
            std::lock_guard lk(mutex_);
            drained = jobs_.empty();
        }
        if (drained) {
            if (beat_) beat_->note("returning freed memory (malloc_trim)");
            malloc_trim(0);
        }
    }
}

}  // namespace facescan::service
