// The pieces of the chaos test (chaos_test.cpp) and of its long soak (tests/bench/chaos.sh): a seeded schedule of
// faults, a network partition of one process on the loopback profile, a watch on the live sessions' progress, and
// a process's resident memory. The partition itself is partition.hpp.
#pragma once

#include <dirent.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "client/scan_client.hpp"
#include "cluster_rig.hpp"
#include "partition.hpp"

namespace facescan::testing {

inline int64_t realtimeNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

// One fault of the schedule: applied to `server`, healed `hold_s` later (a killed server restarts on its data dir,
// a frozen one gets SIGCONT, a partition's drop rules go), then `gap_s` of calm before the next one.
struct Fault {
    enum class Kind { kKill, kFreeze, kPartition };
    Kind kind = Kind::kKill;
    std::string server;
    double hold_s = 0;
    double gap_s = 0;

    std::string describe() const {
        const char* what = kind == Kind::kKill     ? "SIGKILL, restart after"
                           : kind == Kind::kFreeze ? "SIGSTOP for"
                                                   : "partition for";
        std::ostringstream out;
        out.precision(1);
        out << std::fixed << what << " " << hold_s << " s: " << server << " (then " << gap_s << " s calm)";
        return out.str();
    }
};

// The seed of this run: FACESCAN_CHAOS_SEED when set (to replay a run), else a fresh one.
inline uint32_t chaosSeed() {
    if (const char* s = std::getenv("FACESCAN_CHAOS_SEED"); s != nullptr && *s != '\0') {
        return static_cast<uint32_t>(std::strtoul(s, nullptr, 10));
    }
    return std::random_device{}();
}

// A deterministic schedule: the same seed gives the same faults, on every machine (no std distributions, whose
// results are the library's choice). Kills hit only `killable` (the soak keeps one server alive throughout to
// follow its memory); without `partitions` (no root, no nft) a partition becomes a freeze of the same length.
class FaultSchedule {
 public:
    FaultSchedule(uint32_t seed, std::vector<std::string> servers, std::vector<std::string> killable, bool partitions,
                  double lease_s)
        : rng_(seed),
          servers_(std::move(servers)),
          killable_(std::move(killable)),
          partitions_(partitions),
          lease_s_(lease_s) {}

    Fault next() {
        Fault f;
        const uint32_t kind = rng_() % 3;
        if (kind == 0 && !killable_.empty()) {
            f.kind = Fault::Kind::kKill;
            f.server = killable_[rng_() % killable_.size()];
            f.hold_s = uniform(1, 4);
        } else if (kind == 2) {
            f.kind = partitions_ ? Fault::Kind::kPartition : Fault::Kind::kFreeze;
            f.server = servers_[rng_() % servers_.size()];
            f.hold_s = uniform(5, 15);
        } else {
            f.kind = Fault::Kind::kFreeze;
            f.server = servers_[rng_() % servers_.size()];
            f.hold_s = uniform(1, 10);
        }
        // Calm after the heal: a woken or reconnected server re-observes the cluster for two leases, and the
        // sessions settle, before the next fault; one fault at a time.
        f.gap_s = 2 * lease_s_ + 2 + uniform(0, 3);
        return f;
    }

 private:
    double uniform(double lo, double hi) { return lo + (hi - lo) * (static_cast<double>(rng_()) / 4294967296.0); }

    std::mt19937 rng_;
    std::vector<std::string> servers_, killable_;
    bool partitions_;
    double lease_s_;
};

// Resident memory of a process in kB (VmRSS), 0 when it is gone.
inline long rssKb(pid_t pid) {
    const std::string status = readText("/proc/" + std::to_string(pid) + "/status");
    const std::string kb = lastMatch(status, "VmRSS:\\s*([0-9]+) kB");
    return kb.empty() ? 0 : std::stol(kb);
}

// Follows the sessions' ScanStatus (as `facescan watch` would) and keeps, per session, the moments (the server's
// publishing time) at which some server had processed more of its frames than in its previous status: the
// session made progress then. resumedAfter() says when a session first made progress after a moment.
class ProgressWatch {
 public:
    Status connect(uint32_t domain) {
        client::ClientConfig config;
        config.domain = wire::DomainConfig(domain, "loopback");
        config.commands = false;
        auto c = client::ScanClient::connect(config);
        if (!c.isOk()) return c.status();
        client_ = std::move(*c);
        return Status();
    }
    void poll(std::chrono::milliseconds wait) {
        if (!client_) return;
        std::map<std::string, client::SessionStatus> latest;
        if (!client_->poll(wait, latest, "", nullptr).isOk()) return;
        for (const auto& [session, s] : latest) {
            const uint64_t done = uint64_t{s.frames_integrated} + s.frames_rejected + s.frames_tracked_only;
            auto& last = last_done_[session + "@" + s.server_id + "#" + std::to_string(s.owner_epoch)];
            if (done > last && last > 0) progress_[session].push_back(s.updated_ns);
            last = std::max(last, done);
        }
    }
    // A moment of progress known otherwise (a server's log line with its wall-clock time).
    void addProgress(const std::string& session, int64_t at_ns) { progress_[session].push_back(at_ns); }
    // The session's first progress (nullopt: none yet).
    std::optional<int64_t> firstProgress(const std::string& session) const {
        const auto it = progress_.find(session);
        if (it == progress_.end() || it->second.empty()) return std::nullopt;
        return *std::min_element(it->second.begin(), it->second.end());
    }
    std::optional<double> resumedAfter(const std::string& session, int64_t since_ns) const {
        const auto it = progress_.find(session);
        if (it == progress_.end()) return std::nullopt;
        std::optional<int64_t> first;
        for (int64_t t : it->second) {
            if (t >= since_ns && (!first || t < *first)) first = t;
        }
        if (!first) return std::nullopt;
        return static_cast<double>(*first - since_ns) * 1e-9;
    }

 private:
    std::unique_ptr<client::ScanClient> client_;
    std::map<std::string, uint64_t> last_done_;
    std::map<std::string, std::vector<int64_t>> progress_;
};

// p-quantile of `v` (nearest rank), 0 when empty.
inline double quantile(std::vector<double> v, double p) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    const size_t rank = static_cast<size_t>(std::max(1.0, std::ceil(p * static_cast<double>(v.size()))));
    return v[std::min(rank, v.size()) - 1];
}

}  // namespace facescan::testing
