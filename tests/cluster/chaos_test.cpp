// The cluster under a seeded random schedule of real faults, with the real programs on the loopback profile: three
// servers, recordings (--rate max: every frame must be kept) and live scans (--rate 10) streaming throughout,
// while one server at a time is
//   - killed with SIGKILL and restarted 1-4 s later on its data dir (as systemd would),
//   - frozen with SIGSTOP for 1-10 s and woken with SIGCONT (a paused VM, a stalled disk),
//   - cut off the network for 5-15 s by nftables drop rules (chaos.hpp; a freeze instead without root or nft),
// with a calm of two leases and more after each heal. Checked afterwards:
//   - every recording finished once, in exactly one data dir, with every frame integrated (or tracked, or
//     rejected) exactly once and none dropped, its frames digest the agent's, and its mesh within 0.05 mm of an
//     undisturbed run's;
//   - no two servers wrote files for the same session;
//   - every live scan made progress again within lease + 2 s of each fault's start (lease + 5 s in ctest, beside
//     the rest of the suite: resumeBoundS);
//   - no server crashed, and once the agents are done none is left with open sessions;
//   - no agent was left hanging, and each ended with status 0.
// The seed is printed first and with every failure; FACESCAN_CHAOS_SEED=N replays a run's schedule.
//
// ChaosSoak.* is the long version for the bench (tests/bench/chaos.sh MINUTES; skipped unless
// FACESCAN_CHAOS_MINUTES is set): the same faults for that long, scans started one after another, and a report
// of scans done, frames lost, takeover times and the servers' resident memory over time. One server is never
// killed there, so that its memory can be followed over the whole soak.
#include "chaos.hpp"

#include <gtest/gtest.h>

#include <csignal>
#include <cstdio>

#include "chaos_memory.hpp"
#include "eval/accuracy.hpp"
#include "eval/mesh_io.hpp"

namespace facescan::testing {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

constexpr double kLeaseS = 3.0;                 // the loopback profile's
constexpr double kResumeTargetS = kLeaseS + 2;  // what a live scan's pause after a fault should stay within

// The bound the live scans' resumes are checked against: the target, unless FACESCAN_CHAOS_RESUME_BOUND_S says
// otherwise. ctest sets a wider one (lease + 5 s): the suite runs beside other tests on 2 cores, where a starved
// server's DDS renews and lapses leases a second or two late; a wedged server or a takeover that never comes still
// fails it. Run by hand (tests/bench, the chaos loop), the target itself is the bound, and the report says how many
// resumes missed the target either way.
double resumeBoundS() {
    const char* bound = std::getenv("FACESCAN_CHAOS_RESUME_BOUND_S");
    return bound != nullptr && *bound != '\0' ? std::stod(bound) : kResumeTargetS;
}
const std::vector<std::string> kServers = {"s1", "s2", "s3"};
const std::vector<std::string> kServerFlags = {"--set", "status_hz=10"};  // progress seen to 0.1 s

struct Plan {
    int faults = 0;             // the CI test: this many faults
    double minutes = 0;         // the soak: faults for this long
    int recordings = 3;         // recordings streaming at once
    int frames = 120;           // frames per recording
    int lives = 2;              // live scans streaming at once
    double live_for_s = 0;      // a live scan is ended and a new one started after this long (0: one for the run)
    double settle_every_s = 0;  // the soak: every this long, no new scan and no fault until every server is idle
};

struct Scan {
    std::string id;
    bool recording = false;
    int frames = 0;
    int64_t started_ns = 0;
    int64_t ended_ns = 0;  // 0: still streaming
    int exit_code = -1;
};

struct FaultDone {
    Fault fault;
    int64_t at_ns = 0;
    double at_s = 0;  // since the run began
};

double meanMeshDistanceMm(const fs::path& mesh_path, const fs::path& reference_path) {
    auto mesh = eval::readMesh(mesh_path);
    auto reference = eval::readMesh(reference_path);
    if (!mesh.isOk() || !reference.isOk() || mesh->n_vertices() == 0) return 1e9;
    const eval::SurfaceDistance to_reference(*reference);
    double sum_m = 0;
    for (const auto& v : mesh->vertices()) {
        const auto& p = mesh->point(v);
        sum_m += to_reference.query(Eigen::Vector3f(p[0], p[1], p[2])).distance_m;
    }
    return sum_m / static_cast<double>(mesh->n_vertices()) * 1e3;
}

// The servers that `facescan servers --json` lists with no open session.
int idleServers(const std::string& servers_json) {
    int n = 0;
    for (size_t at = servers_json.find("\"open_sessions\":0,"); at != std::string::npos;
         at = servers_json.find("\"open_sessions\":0,", at + 1)) {
        ++n;
    }
    return n;
}

// Every server log of the run (a restarted server's logs are server-ID.log.2, .3, ...).
std::vector<fs::path> serverLogs(const ClusterRig& rig) {
    std::vector<fs::path> logs;
    for (const auto& e : fs::directory_iterator(rig.dir())) {
        if (e.path().filename().string().rfind("server-", 0) == 0) logs.push_back(e.path());
    }
    std::sort(logs.begin(), logs.end());
    return logs;
}

class ChaosRun {
 public:
    ChaosRun(ClusterRig& rig, Plan plan, uint32_t seed, fs::path baseline_mesh)
        : rig_(rig),
          plan_(plan),
          seed_(seed),
          baseline_mesh_(std::move(baseline_mesh)),
          schedule_(seed, kServers, plan.minutes > 0 ? std::vector<std::string>{"s2", "s3"} : kServers,
                    partitioner_.available(), kLeaseS) {}

    void run() {
        for (const std::string& id : kServers) rig_.startServer(id, kServerFlags);
        ASSERT_TRUE(rig_.waitForServers(3, 60s)) << rig_.cli("servers").out;
        ASSERT_TRUE(watch_.connect(static_cast<uint32_t>(std::stoul(rig_.domain()))).isOk());
        std::printf("chaos: partitions %s\n",
                    partitioner_.available() ? "by nftables drop rules" : "unavailable (not root or no nft): freezes");
        for (int i = 0; i < plan_.recordings; ++i) startRecording();
        for (int i = 0; i < plan_.lives; ++i) startLive();
        begin_ = std::chrono::steady_clock::now();
        double next_fault_s = 10;  // every session placed and streaming first
        double heal_s = 0;
        bool active = false;
        double next_sample_s = 0;
        double next_settle_s = plan_.settle_every_s;
        Fault current;
        for (;;) {
            watch_.poll(100ms);
            const double now = elapsed();
            // The soak's minutes are minutes of faults: its idle checkpoints come on top.
            const bool more_faults =
                plan_.minutes > 0 ? now - settled_s_ < plan_.minutes * 60 : faults_.size() < size_t(plan_.faults);
            if (!active && more_faults && plan_.settle_every_s > 0 && now >= next_settle_s) {
                const double before_s = elapsed();
                settle();
                settled_s_ += elapsed() - before_s;
                for (int i = 0; i < plan_.recordings; ++i) startRecording();
                for (int i = 0; i < plan_.lives; ++i) startLive();
                next_fault_s = elapsed() + 10;
                next_settle_s = elapsed() + plan_.settle_every_s;
                continue;
            }
            if (!active && more_faults && now >= next_fault_s) {
                current = schedule_.next();
                apply(current);
                active = true;
                heal_s = now + current.hold_s;
            } else if (active && now >= heal_s) {
                heal(current);
                active = false;
                next_fault_s = now + current.gap_s;
                if (plan_.live_for_s > 0) restartOldLives();
            }
            reapRecordings(more_faults || active);
            restartExitedServers(active && current.kind == Fault::Kind::kKill ? current.server : "");
            if (plan_.minutes > 0 && now >= next_sample_s) {
                sampleMemory(now);
                next_sample_s = now + 15;
            }
            if (!active && !more_faults && runningRecordings() == 0) break;
            if (!active && !more_faults && now > last_heal_s_ + 200) break;  // agents hanging: checked below
        }
        // The live scans end as an operator ends them (Ctrl-C); the check window of the last fault is long past.
        for (Scan& s : scans_) {
            if (!s.recording && s.ended_ns == 0) stopLive(s);
        }
        if (plan_.settle_every_s > 0) settle();  // the last idle checkpoint
    }

    void check() {
        SCOPED_TRACE("chaos seed " + std::to_string(seed_) + " (replay: FACESCAN_CHAOS_SEED=" + std::to_string(seed_) +
                     "), logs in " + rig_.dir().string());
        checkAgents();
        checkScans();
        checkResumes();
        checkServers();
    }

    // The soak's figures (and a summary line in the CI test).
    void report() {
        std::vector<double> takeovers_ms;
        for (const fs::path& log : serverLogs(rig_)) {
            const std::string text = readText(log);
            const std::regex re("first frame integrated after the takeover \\(frame [0-9]+, ([0-9]+) ms after");
            for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator(); ++it) {
                takeovers_ms.push_back(std::stod((*it)[1].str()));
            }
        }
        int kills = 0, freezes = 0, partitions = 0;
        for (const FaultDone& f : faults_) {
            (f.fault.kind == Fault::Kind::kKill     ? kills
             : f.fault.kind == Fault::Kind::kFreeze ? freezes
                                                    : partitions)++;
        }
        std::printf("chaos report (seed %u): %.1f min, %zu faults (%d kills, %d freezes, %d partitions)\n", seed_,
                    elapsed() / 60, faults_.size(), kills, freezes, partitions);
        std::printf("  scans done: %d recordings (%d failed), %d live scans; recording frames lost: %d\n",
                    recordings_done_, recordings_failed_, lives_done_, frames_lost_);
        std::printf(
            "  takeovers: %zu; old owner's last sign of life to first frame integrated: p50 %.0f ms, p95 %.0f "
            "ms, max %.0f ms\n",
            takeovers_ms.size(), quantile(takeovers_ms, 0.5), quantile(takeovers_ms, 0.95),
            quantile(takeovers_ms, 1.0));
        const auto missed =
            std::count_if(resumes_s_.begin(), resumes_s_.end(), [](double s) { return s > kResumeTargetS; });
        std::printf(
            "  live scans, fault to progress again: p50 %.2f s, p95 %.2f s, max %.2f s over %zu (bound %.0f s; "
            "%zu over the %.0f s target)\n",
            quantile(resumes_s_, 0.5), quantile(resumes_s_, 0.95), quantile(resumes_s_, 1.0), resumes_s_.size(),
            resumeBoundS(), static_cast<size_t>(missed), kResumeTargetS);
        if (!memory_.empty()) {
            const double under_load = reportMemoryUnderLoad(memory_, kServers);
            const double idle = reportIdleMemory(memory_, idle_memory_);
            memory_growth_ = idle_memory_.empty() ? under_load : idle;
        }
    }

    double memoryGrowthAfterFiveMinutes() const { return memory_growth_; }
    int framesLost() const { return frames_lost_; }

 private:
    double elapsed() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - begin_).count(); }

    std::vector<std::string> agentFlags() const {
        // Recordings keep every frame until confirmed; what no server confirmed is saved in the run's folder.
        return {"--finish-timeout", "150", "--keep-frames", "400", "--save-dir", (rig_.dir() / "unconfirmed").string()};
    }
    void startRecording() {
        Scan s{"rec-" + std::to_string(++counter_), true, plan_.frames, realtimeNs()};
        rig_.startAgent(s.id, s.frames, "max", "", agentFlags());
        scans_.push_back(s);
    }
    void startLive() {
        // A nearly still head: the frames of a takeover's gap are lost by design, and tracking goes on from there.
        Scan s{"live-" + std::to_string(++counter_), false, 0, realtimeNs()};
        rig_.startAgent(s.id, 100000, "10", ",period=4000", agentFlags());
        scans_.push_back(s);
    }
    void stopLive(Scan& s) {
        rig_.agent(s.id).signal(SIGINT);
        s.exit_code = rig_.agent(s.id).wait(20s);
        s.ended_ns = realtimeNs();
        if (s.exit_code < 0) rig_.agent(s.id).kill9();
        if (s.exit_code == 0) ++lives_done_;
    }
    void restartOldLives() {
        const size_t n = scans_.size();
        for (size_t i = 0; i < n; ++i) {
            if (scans_[i].recording || scans_[i].ended_ns != 0) continue;
            if (static_cast<double>(realtimeNs() - scans_[i].started_ns) * 1e-9 < plan_.live_for_s) continue;
            stopLive(scans_[i]);
            startLive();
        }
    }
    int runningRecordings() const {
        return static_cast<int>(
            std::count_if(scans_.begin(), scans_.end(), [](const Scan& s) { return s.recording && s.ended_ns == 0; }));
    }
    void reapRecordings(bool start_more) {
        const size_t n = scans_.size();
        for (size_t i = 0; i < n; ++i) {
            Scan& s = scans_[i];
            if (!s.recording || s.ended_ns != 0) continue;
            const int rc = rig_.agent(s.id).wait(0s);
            if (rc < 0) continue;
            s.exit_code = rc;
            s.ended_ns = realtimeNs();
            if (start_more) startRecording();
        }
    }

    void apply(const Fault& f) {
        faults_.push_back({f, realtimeNs(), elapsed()});
        std::printf("chaos %6.1f s: %s\n", elapsed(), f.describe().c_str());
        std::fflush(stdout);
        ChildProcess& server = rig_.server(f.server);
        switch (f.kind) {
            case Fault::Kind::kKill: server.kill9(); break;
            case Fault::Kind::kFreeze: server.signal(SIGSTOP); break;
            case Fault::Kind::kPartition:
                if (!partitioner_.cut(server.pid(), f.hold_s + 1)) ADD_FAILURE() << "could not cut " << f.server;
                break;
        }
    }
    void heal(const Fault& f) {
        switch (f.kind) {
            case Fault::Kind::kKill: rig_.startServer(f.server, kServerFlags); break;
            case Fault::Kind::kFreeze: rig_.server(f.server).signal(SIGCONT); break;
            case Fault::Kind::kPartition: partitioner_.heal(); break;
        }
        last_heal_s_ = elapsed();
    }

    // A server that ended by itself (its watchdog, a crash) is restarted on its data dir as systemd would, and
    // the run fails for it.
    void restartExitedServers(const std::string& killed) {
        for (const std::string& id : kServers) {
            if (id == killed) continue;
            const int rc = rig_.server(id).wait(0s);
            if (rc < 0) continue;
            exits_.push_back(id + " exited with status " + std::to_string(rc) + " at " + std::to_string(elapsed()) +
                             " s");
            std::printf("chaos %6.1f s: %s; restarting it\n", elapsed(), exits_.back().c_str());
            rig_.startServer(id, kServerFlags);
        }
    }

    // An idle checkpoint: no new scan and no fault until every recording has ended and every server holds no open
    // session, then each server's resident memory. Under load a server's memory follows the sessions and copies it
    // holds at that instant (twofold from minute to minute); idle, it is what stays behind after the scans, so the
    // checkpoints compare like with like and show a leak as growth.
    void settle() {
        std::printf("chaos %6.1f s: settling: no new scan and no fault until every server is idle\n", elapsed());
        std::fflush(stdout);
        for (Scan& s : scans_) {
            if (!s.recording && s.ended_ns == 0) stopLive(s);
        }
        const double began_s = elapsed();
        const auto idle = [&] {
            watch_.poll(100ms);
            reapRecordings(false);
            restartExitedServers("");
            if (runningRecordings() > 0) return false;
            return idleServers(rig_.cli("servers --json").out) == static_cast<int>(kServers.size());
        };
        if (!waitUntil(idle, 300s)) {
            std::printf("chaos %6.1f s: the servers did not become idle within 300 s: no checkpoint\n", elapsed());
            return;
        }
        // Finished sessions leave memory on the status thread's next turns (retireFinished), then malloc_trim.
        std::this_thread::sleep_for(10s);
        std::string line;
        for (const std::string& id : kServers) {
            const pid_t pid = rig_.server(id).pid();
            if (pid <= 0) continue;
            idle_memory_.push_back({elapsed(), id, pid, rssKb(pid)});
            line += " " + id + " " + std::to_string(idle_memory_.back().rss_kb / 1024) + " MB";
        }
        std::printf("chaos %6.1f s: idle after %.0f s:%s\n", elapsed(), elapsed() - began_s, line.c_str());
        std::fflush(stdout);
    }

    void sampleMemory(double now) {
        for (const std::string& id : kServers) {
            const pid_t pid = rig_.server(id).pid();
            if (pid > 0) memory_.push_back({now, id, pid, rssKb(pid)});
        }
    }
    void checkAgents() {
        for (Scan& s : scans_) {
            if (s.ended_ns == 0) {
                const int rc = rig_.agent(s.id).wait(0s);
                if (rc >= 0) {
                    s.exit_code = rc;
                    s.ended_ns = realtimeNs();
                } else {
                    ADD_FAILURE() << "agent " << s.id << " left hanging:\n" << readText(rig_.agentLog(s.id));
                    rig_.agent(s.id).kill9();
                    continue;
                }
            }
            EXPECT_EQ(s.exit_code, 0) << s.id << ":\n" << readText(rig_.agentLog(s.id));
        }
    }

    void checkScans() {
        for (const Scan& s : scans_) {
            if (!s.recording) {
                // A live scan's agent ends (Ctrl-C) without waiting for the result: its owner finishes it at a low
                // priority, which on a loaded machine takes a while.
                (void)waitUntil(
                    [&] {
                        return std::any_of(kServers.begin(), kServers.end(), [&](const std::string& id) {
                            return fs::exists(rig_.dataDir(id) / s.id / "summary.json");
                        });
                    },
                    60s);
            }
            std::vector<std::string> wrote;  // the servers with any file of this session
            std::vector<fs::path> summaries;
            for (const std::string& id : kServers) {
                const fs::path dir = rig_.dataDir(id) / s.id;
                bool any = false;
                for (const char* file : {"summary.json", "mesh.ply", "trajectory.txt", "frames.tsv"}) {
                    any = any || fs::exists(dir / file);
                }
                if (any) wrote.push_back(id);
                if (fs::exists(dir / "summary.json")) summaries.push_back(dir / "summary.json");
            }
            EXPECT_LE(wrote.size(), 1u) << s.id << " has files from more than one server (split)";
            if (!s.recording) {
                EXPECT_EQ(summaries.size(), 1u) << s.id;
                continue;
            }
            EXPECT_EQ(summaries.size(), 1u) << s.id << " finished in " << summaries.size() << " data dirs";
            const std::string summary = summaries.empty() ? "" : readText(summaries.front());
            const int done = summaries.empty()
                                 ? 0
                                 : summaryNumber(summary, "integrated") + summaryNumber(summary, "tracked_only") +
                                       summaryNumber(summary, "rejected");
            const int lost = std::max(0, s.frames - done);
            frames_lost_ += lost;
            const bool ok =
                summaries.size() == 1 && done == s.frames && summaryNumber(summary, "dropped") == 0 && s.exit_code == 0;
            ok ? ++recordings_done_ : ++recordings_failed_;
            if (summaries.empty()) continue;
            EXPECT_EQ(done, s.frames) << summaries.front() << ": " << summary;
            EXPECT_EQ(summaryNumber(summary, "dropped"), 0) << summary;
            EXPECT_EQ(jsonField(summary, "frames_digest"),
                      lastMatch(readText(rig_.agentLog(s.id)), "frames digest ([0-9a-f]{16})"))
                << s.id;
            if (!baseline_mesh_.empty()) {
                const double mm = meanMeshDistanceMm(summaries.front().parent_path() / "mesh.ply", baseline_mesh_);
                EXPECT_LT(mm, 0.05) << s.id << ": mesh " << mm << " mm from the undisturbed run's; " << summary;
            }
        }
    }

    void checkResumes() {
        // A new owner's first frame is in its log to the nanosecond; its statuses show progress only from the next.
        for (const fs::path& log : serverLogs(rig_)) {
            const std::string text = readText(log);
            const std::regex re(
                "session ([^ :]+): first frame integrated after the takeover [^\\n]* at realtime_ns ([0-9]+)");
            for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator(); ++it) {
                watch_.addProgress((*it)[1].str(), std::stoll((*it)[2].str()));
            }
        }
        const double bound_s = resumeBoundS();
        for (const FaultDone& f : faults_) {
            for (const Scan& s : scans_) {
                // Live scans streaming from the fault until its bound has passed. A scan streams from its first
                // progress: on a loaded host its placement can take longer than a fault's bound, and a fault before
                // it would measure that wait, not a recovery. A scan never placed fails checkScans.
                if (s.recording || s.started_ns + 5'000'000'000 > f.at_ns) continue;
                const std::optional<int64_t> streaming = watch_.firstProgress(s.id);
                if (!streaming || *streaming > f.at_ns) continue;
                if (s.ended_ns != 0 && s.ended_ns < f.at_ns + static_cast<int64_t>((bound_s + 1) * 1e9)) continue;
                const std::optional<double> after = watch_.resumedAfter(s.id, f.at_ns);
                if (after) resumes_s_.push_back(*after);
                EXPECT_TRUE(after && *after <= bound_s)
                    << s.id << " made no progress within " << bound_s << " s of the fault at " << f.at_s << " s ("
                    << f.fault.describe() << "): " << (after ? std::to_string(*after) + " s" : std::string("never"));
            }
        }
    }

    void checkServers() {
        restartExitedServers("");
        for (const std::string& exit : exits_) ADD_FAILURE() << "server " << exit;
        for (const fs::path& log : serverLogs(rig_)) {
            const std::string text = readText(log);
            EXPECT_EQ(text.find("terminate called"), std::string::npos) << log;
            EXPECT_EQ(text.find("stuck:"), std::string::npos) << log;
        }
        // Nothing left open: every server answers, with no open session, and no session is left unfinished.
        std::string servers, sessions;
        const bool settled = waitUntil(
            [&] {
                servers = rig_.cli("servers --json").out;
                sessions = rig_.cli("sessions --json").out;
                return idleServers(servers) == static_cast<int>(kServers.size()) &&
                       std::regex_search(sessions, std::regex("FINISHED")) &&
                       !std::regex_search(sessions, std::regex("\"state\":\"(WAITING|SCANNING|LOST)\""));
            },
            60s);
        EXPECT_TRUE(settled) << "servers:\n" << servers << "sessions:\n" << sessions;
    }

    ClusterRig& rig_;
    Plan plan_;
    uint32_t seed_;
    fs::path baseline_mesh_;
    Partitioner partitioner_;
    FaultSchedule schedule_;
    ProgressWatch watch_;
    std::chrono::steady_clock::time_point begin_ = std::chrono::steady_clock::now();
    std::vector<Scan> scans_;
    std::vector<FaultDone> faults_;
    std::vector<MemorySample> memory_;
    std::vector<MemorySample> idle_memory_;  // the soak's idle checkpoints (settle)
    std::vector<double> resumes_s_;
    std::vector<std::string> exits_;
    double last_heal_s_ = 0;
    double settled_s_ = 0;  // seconds spent in idle checkpoints
    double memory_growth_ = 0;
    int counter_ = 0;
    int recordings_done_ = 0, recordings_failed_ = 0, lives_done_ = 0, frames_lost_ = 0;
};

// The undisturbed run of the same recording: one server, nothing happens to it.
fs::path undisturbedMesh(ClusterRig& base, int frames) {
    base.startServer("base");
    base.startAgent("rec", frames, "max");
    EXPECT_EQ(base.agent("rec").wait(180s), 0) << readText(base.agentLog("rec"));
    return base.dataDir("base") / "rec" / "mesh.ply";
}

TEST(Chaos, KillsFreezesAndPartitionsLoseNoFrameSplitNoScanAndLeaveNothingHanging) {
    const uint32_t seed = chaosSeed();
    std::printf("chaos seed %u (replay: FACESCAN_CHAOS_SEED=%u)\n", seed, seed);
    Plan plan;
    plan.faults = 4;
    ClusterRig base("chaos-baseline", 71);
    const fs::path reference = undisturbedMesh(base, plan.frames);
    ASSERT_TRUE(fs::exists(reference));
    ClusterRig rig("chaos", 72);
    ChaosRun run(rig, plan, seed, reference);
    run.run();
    run.check();
    run.report();
}

TEST(ChaosSoak, TheSameFaultsForMinutes) {
    const char* minutes = std::getenv("FACESCAN_CHAOS_MINUTES");
    if (minutes == nullptr || *minutes == '\0') GTEST_SKIP() << "tests/bench/chaos.sh MINUTES runs the soak";
    const uint32_t seed = chaosSeed();
    std::printf("chaos soak seed %u (replay: FACESCAN_CHAOS_SEED=%u)\n", seed, seed);
    Plan plan;
    plan.minutes = std::stod(minutes);
    plan.live_for_s = 120;
    plan.settle_every_s = 300;
    ClusterRig base("chaos-soak-baseline", 73);
    const fs::path reference = undisturbedMesh(base, plan.frames);
    ClusterRig rig("chaos-soak", 74);
    ChaosRun run(rig, plan, seed, reference);
    run.run();
    run.check();
    run.report();
    EXPECT_EQ(run.framesLost(), 0);
    EXPECT_LT(run.memoryGrowthAfterFiveMinutes(), 0.05);
}

}  // namespace
}  // namespace facescan::testing
