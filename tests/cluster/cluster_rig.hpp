// Real facescan-server, facescan-agent and facescan processes on the loopback profile in a private domain, for
// the cluster tests: start, kill -9, restart, and read what they logged and wrote.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "child_process.hpp"
#include "run_command.hpp"
#include "test_domain.hpp"

namespace facescan::testing {

// The last match of `pattern`'s first group in `text` (empty when none).
inline std::string lastMatch(const std::string& text, const std::string& pattern) {
    const std::regex re(pattern);
    std::string last;
    for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator(); ++it) {
        last = (*it)[1].str();
    }
    return last;
}

// A JSON field of one flat object line: "key":"text" or "key":number (the CLI's and summary.json's layout).
inline std::string jsonField(const std::string& line, const std::string& key) {
    return lastMatch(line, "\"" + key + "\"\\s*:\\s*\"?([^\",}]*)\"?");
}

// A number of summary.json ("key": N), -1 when it has none.
inline int summaryNumber(const std::string& summary, const std::string& key) {
    const std::string v = lastMatch(summary, "\"" + key + "\": ([0-9]+)");
    return v.empty() ? -1 : std::stoi(v);
}

inline bool waitUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!done()) {
        if (std::chrono::steady_clock::now() >= deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return true;
}

class ClusterRig {
 public:
    explicit ClusterRig(const std::string& name, uint32_t salt)
        : domain_(std::to_string(privateDomain(salt))),
          dir_(std::filesystem::temp_directory_path() /
               ("facescan-cluster-" + name + "-" + std::to_string(::getpid()))) {
        std::filesystem::remove_all(dir_);
        std::filesystem::create_directories(dir_);
    }
    ~ClusterRig() {
        for (auto& [session, agent] : agents_) agent->signal(SIGINT);  // all at once: each finishes its scan
        agents_.clear();
        servers_.clear();  // SIGTERM: they finish and exit
        // The logs and data dirs stay for a failed test (the failure messages name them).
        if (!::testing::Test::HasFailure()) std::filesystem::remove_all(dir_);
    }

    const std::filesystem::path& dir() const { return dir_; }
    const std::string& domain() const { return domain_; }
    std::filesystem::path dataDir(const std::string& server_id) const { return dir_ / ("data-" + server_id); }
    std::filesystem::path serverLog(const std::string& id) const { return dir_ / ("server-" + id + ".log"); }
    std::filesystem::path agentLog(const std::string& session) const { return dir_ / ("agent-" + session + ".log"); }

    // A server with its own data dir; `extra` adds flags (e.g. "--max-sessions", "2"). Restarting an id that
    // was killed starts it again on the same data dir.
    ChildProcess& startServer(const std::string& id, std::vector<std::string> extra = {}) {
        std::vector<std::string> args = {
            FACESCAN_SERVER_BIN, "--profile",          "loopback", "--domain", domain_,         "--server-id", id,
            "--data-dir",        dataDir(id).string(), "--preset", "fast",     "--snapshot-hz", "0",           "--set",
            "join_settle_s=0.6"};
        args.insert(args.end(), extra.begin(), extra.end());
        auto& slot = servers_[id];
        slot.reset();
        const std::string log =
            serverLog(id).string() + (restarts_[id]++ > 0 ? "." + std::to_string(restarts_[id]) : "");
        slot = std::make_unique<ChildProcess>(args, log);
        return *slot;
    }
    ChildProcess& server(const std::string& id) { return *servers_.at(id); }

    // An agent streaming the synthetic head: `rate` "max" is a recording (every frame), a number a live stream.
    // `motion` adds synthetic source options (e.g. ",period=1200" for a slower head); `extra` adds flags (e.g.
    // "--finish-timeout", "150").
    ChildProcess& startAgent(const std::string& session, int frames, const std::string& rate,
                             const std::string& motion = "", std::vector<std::string> extra = {}) {
        std::vector<std::string> args = {
            FACESCAN_AGENT_BIN,
            "--profile",
            "loopback",
            "--domain",
            domain_,
            "--session",
            session,
            "--source",
            "synthetic:frames=" + std::to_string(frames) + ",subject=builtin,seed=1" + motion,
            "--rate",
            rate,
            "--wait-for-server",
            "60"};
        args.insert(args.end(), extra.begin(), extra.end());
        auto& slot = agents_[session];
        slot = std::make_unique<ChildProcess>(args, agentLog(session));
        return *slot;
    }
    ChildProcess& agent(const std::string& session) { return *agents_.at(session); }

    // Two live scans (10 Hz) started one after the other, the second once a server owns the first (so that its
    // placement sees that load): their owners, in order (empty where no server took it within 30 s).
    std::pair<std::string, std::string> startTwoLiveScans(const std::string& first, const std::string& second,
                                                          int frames = 3000) {
        startAgent(first, frames, "10");
        const std::string first_owner = waitForOwner(first, std::chrono::seconds(30));
        startAgent(second, frames, "10");
        return {first_owner, waitForOwner(second, std::chrono::seconds(30))};
    }

    // The server that owns `session`, as its agent was told (empty until then).
    std::string ownerOf(const std::string& session) const {
        return lastMatch(readText(agentLog(session)), "server '([^']+)' owns session " + session);
    }
    std::string waitForOwner(const std::string& session, std::chrono::milliseconds timeout) const {
        std::string owner;
        waitUntil([&] { return !(owner = ownerOf(session)).empty(); }, timeout);
        return owner;
    }
    // Frames the agent has sent so far (its status line).
    int published(const std::string& session) const {
        const std::string n = lastMatch(readText(agentLog(session)), "\\nframes ([0-9]+) \\|");
        return n.empty() ? 0 : std::stoi(n);
    }

    // Until `n` servers are up, past their join and responding (facescan servers).
    bool waitForServers(int n, std::chrono::milliseconds timeout) const {
        return waitUntil(
            [&] {
                std::istringstream out(cli("servers --json").out);
                int working = 0;
                for (std::string line; std::getline(out, line);) {
                    working += line.find("\"joining\":false") != std::string::npos &&
                               line.find("\"responding\":true") != std::string::npos;
                }
                return working >= n;
            },
            timeout);
    }

    CommandRun cli(const std::string& args) const {
        return runCommand(std::string(FACESCAN_CLI) + " " + args + " --profile loopback --domain " + domain_ +
                          " --timeout 10");
    }
    // The client command line (for clients run as child processes).
    std::vector<std::string> cliArgs(const std::vector<std::string>& args) const {
        std::vector<std::string> out = {FACESCAN_CLI};
        out.insert(out.end(), args.begin(), args.end());
        for (const char* a : {"--profile", "loopback", "--domain"}) out.push_back(a);
        out.push_back(domain_);
        return out;
    }

 private:
    std::string domain_;
    std::filesystem::path dir_;
    std::map<std::string, std::unique_ptr<ChildProcess>> servers_;
    std::map<std::string, std::unique_ptr<ChildProcess>> agents_;
    std::map<std::string, int> restarts_;
};

// True once the agent has dropped frames its owner confirmed (its standby then holds a copy), within 60 s.
inline bool standbyHoldsACopy(const ClusterRig& rig, const std::string& session) {
    return waitUntil(
        [&] {
            const std::string kept = lastMatch(readText(rig.agentLog(session)), "\\| kept ([0-9]+)");
            return !kept.empty() && std::stoi(kept) < rig.published(session);
        },
        std::chrono::seconds(60));
}

// The loopback profile with another DDS lease, for a process whose death the others should notice late (its
// --profile flag, after the rig's own): returns the file's path in the rig's folder.
inline std::filesystem::path loopbackProfileWithLease(const ClusterRig& rig, int lease_s) {
    std::string profile = readText(std::filesystem::path(FACESCAN_SOURCE_DIR) / "deploy" / "profiles" / "loopback.xml");
    const std::string lease = "<LeaseDuration>3s</LeaseDuration>";
    EXPECT_NE(profile.find(lease), std::string::npos) << profile;
    if (profile.find(lease) != std::string::npos) {
        profile.replace(profile.find(lease), lease.size(),
                        "<LeaseDuration>" + std::to_string(lease_s) + "s</LeaseDuration>");
    }
    const std::filesystem::path path = rig.dir() / ("loopback-" + std::to_string(lease_s) + "s-lease.xml");
    std::ofstream(path) << profile;
    return path;
}

}  // namespace facescan::testing
