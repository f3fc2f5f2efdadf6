// The pieces of the chaos test (chaos_test.cpp) and of its long soak (tests/bench/chaos.sh): a seeded schedule of
// faults, a network partition of one process on the loopback profile, a watch on the live sessions' progress, and
// a process's resident memory.
//
// The partition: on the loopback profile every process talks over 127.0.0.1, each from UDP ports of its own (its
// DDS participant's discovery and data ports and its transmit socket). An nftables table of this test drops every
// UDP packet from or to the ports of the cut process, so it neither hears nor is heard by anyone (servers, agents,
// clients), while it goes on running. The ports are elements of a set with a timeout: a partition heals by itself
// even when the test dies before healing it.
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

// The local UDP ports of a process's sockets (from /proc: its descriptors' socket inodes in /proc/net/udp{,6}).
inline std::set<int> udpPorts(pid_t pid) {
    std::set<std::string> inodes;
    const std::string fd_dir = "/proc/" + std::to_string(pid) + "/fd";
    if (DIR* d = ::opendir(fd_dir.c_str())) {
        while (dirent* e = ::readdir(d)) {
            char target[256] = {};
            const std::string link = fd_dir + "/" + e->d_name;
            const ssize_t n = ::readlink(link.c_str(), target, sizeof(target) - 1);
            const std::string t(target, n > 0 ? static_cast<size_t>(n) : 0);
            if (t.rfind("socket:[", 0) == 0) inodes.insert(t.substr(8, t.size() - 9));
        }
        ::closedir(d);
    }
    std::set<int> ports;
    for (const char* table : {"/proc/net/udp", "/proc/net/udp6"}) {
        std::istringstream in(readText(table));
        std::string line;
        std::getline(in, line);  // header
        while (std::getline(in, line)) {
            std::istringstream l(line);
            std::string slot, local, remote, st, queues, tr, retr, uid, timeout, inode;
            if (!(l >> slot >> local >> remote >> st >> queues >> tr >> retr >> uid >> timeout >> inode)) continue;
            if (inodes.count(inode) == 0) continue;
            const size_t colon = local.rfind(':');
            if (colon != std::string::npos) ports.insert(std::stoi(local.substr(colon + 1), nullptr, 16));
        }
    }
    return ports;
}

// Cuts one process at a time off the network (see the top of this file). available() is false without root or
// nft: the schedule then freezes instead.
class Partitioner {
 public:
    Partitioner() : table_("facescan_chaos_" + std::to_string(::getpid())) {
        if (::geteuid() != 0 || runCommand("command -v nft").exit_code != 0) return;
        const std::string rules = "table inet " + table_ +
                                  " {\n set cut { type inet_service; flags timeout; }\n"
                                  " chain out { type filter hook output priority 0; policy accept;\n"
                                  "  udp sport @cut drop\n  udp dport @cut drop\n }\n}";
        const std::string file = (std::filesystem::temp_directory_path() / (table_ + ".nft")).string();
        std::ofstream(file) << rules << "\n";
        available_ = nft("-f " + file);
        std::filesystem::remove(file);
    }
    ~Partitioner() {
        if (available_) nft("delete table inet " + table_);
    }
    Partitioner(const Partitioner&) = delete;
    Partitioner& operator=(const Partitioner&) = delete;

    bool available() const { return available_; }
    // Drops `pid`'s traffic for at most `seconds` (heal() ends it sooner); false when it has no UDP port.
    bool cut(pid_t pid, double seconds) {
        const std::set<int> ports = udpPorts(pid);
        if (ports.empty()) return false;
        std::string elements;
        for (int p : ports) {
            elements += (elements.empty() ? "" : ", ") + std::to_string(p) + " timeout " +
                        std::to_string(static_cast<int>(seconds * 1000)) + "ms";
        }
        return nft("add element inet " + table_ + " cut { " + elements + " }");
    }
    void heal() { nft("flush set inet " + table_ + " cut"); }

 private:
    static bool nft(const std::string& args) { return runCommand("nft " + args).exit_code == 0; }

    std::string table_;
    bool available_ = false;
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
