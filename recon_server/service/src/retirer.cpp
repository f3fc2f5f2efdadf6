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

void Retirer::linger(std::function<bool()> step) {
    retire([this, step = std::move(step)]() mutable {
        if (lingering_.empty()) next_linger_ = std::chrono::steady_clock::now();
        lingering_.push_back(std::move(step));
    });
}

void Retirer::runLingering(bool final_turn) {
    for (auto it = lingering_.begin(); it != lingering_.end();) {
        note("looking after a lingering endpoint");
        if ((*it)() || final_turn) {
            note("ending a lingering endpoint");
            it = lingering_.erase(it);  // what it captured ends here
        } else {
            ++it;
        }
    }
    next_linger_ = std::chrono::steady_clock::now() + kLingerPeriod;
}

void Retirer::loop() {
    recon::nameThisThread("fs-retire");
    for (;;) {
        std::function<void()> job;
        bool linger_due = false;
        bool last_turn = false;
        {
            std::unique_lock lk(mutex_);
            if (beat_) beat_->end();
            const auto ready = [&] { return stopping_ || !jobs_.empty(); };
            if (lingering_.empty()) {
                cv_.wait(lk, ready);
            } else {
                cv_.wait_until(lk, next_linger_, ready);
            }
            if (!jobs_.empty()) {
                job = std::move(jobs_.front());
                jobs_.pop_front();
            } else if (stopping_) {
                if (lingering_.empty()) return;  // stopping, and everything handed over has ended
                last_turn = true;
            }
            linger_due = !lingering_.empty() && (last_turn || std::chrono::steady_clock::now() >= next_linger_);
            if (beat_ && (job || linger_due)) beat_->begin();
        }
        if (job) {
            job();
            job = nullptr;  // what it captured ends here too, still timed by the beat
            // Once the queue is drained, what the jobs freed goes back to the system. A session's buffers were
            // allocated by its worker, in that thread's malloc arena; freed, they stay resident until trimmed, and
            // the next session's worker may get another arena: without the trim an idle server kept hundreds of
            // megabytes from scans given up, released or finished (the chaos soak's idle checkpoints).
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
        if (linger_due) runLingering(last_turn);
    }
}

}  // namespace facescan::service
