// A network partition on the loopback profile, for the cluster's fault tests (chaos_test.cpp, stuck_server_test.cpp).
// Every process talks over 127.0.0.1, each from UDP ports of its own (its DDS participant's discovery and data ports
// and its transmit socket). An nftables table of the test drops every UDP packet from or to the ports of a cut
// process, so it neither hears nor is heard by anyone (servers, agents, clients), while it goes on running; or only
// the packets between one process and some others. The ports are elements of sets with a timeout: a partition heals
// by itself even when the test dies before healing it.
#pragma once

#include <dirent.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "cluster_rig.hpp"

namespace facescan::testing {

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

// Cuts one process at a time off the network (see the top of this file), or one process off some others only.
// available() is false without root or nft (the chaos schedule then freezes instead).
class Partitioner {
 public:
    Partitioner() : table_("facescan_chaos_" + std::to_string(::getpid())) {
        if (::geteuid() != 0 || runCommand("command -v nft").exit_code != 0) return;
        const std::string rules = "table inet " + table_ +
                                  " {\n set cut { type inet_service; flags timeout; }\n"
                                  " set side_a { type inet_service; flags timeout; }\n"
                                  " set side_b { type inet_service; flags timeout; }\n"
                                  " chain out { type filter hook output priority 0; policy accept;\n"
                                  "  udp sport @cut drop\n  udp dport @cut drop\n"
                                  "  udp sport @side_a udp dport @side_b drop\n"
                                  "  udp sport @side_b udp dport @side_a drop\n }\n}";
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
    bool cut(pid_t pid, double seconds) { return add("cut", udpPorts(pid), seconds); }
    // Drops the traffic between `pid` and each of `others` (both ways) for at most `seconds`; the rest of the
    // network still hears both sides. False when a side has no UDP port.
    bool cutBetween(pid_t pid, const std::vector<pid_t>& others, double seconds) {
        std::set<int> b;
        for (pid_t o : others) b.merge(udpPorts(o));
        return add("side_a", udpPorts(pid), seconds) && add("side_b", b, seconds);
    }
    void heal() {
        for (const char* set : {"cut", "side_a", "side_b"}) nft("flush set inet " + table_ + " " + set);
    }

 private:
    bool add(const std::string& set, const std::set<int>& ports, double seconds) {
        if (ports.empty()) return false;
        std::string elements;
        for (int p : ports) {
            elements += (elements.empty() ? "" : ", ") + std::to_string(p) + " timeout " +
                        std::to_string(static_cast<int>(seconds * 1000)) + "ms";
        }
        return nft("add element inet " + table_ + " " + set + " { " + elements + " }");
    }
    static bool nft(const std::string& args) { return runCommand("nft " + args).exit_code == 0; }

    std::string table_;
    bool available_ = false;
};

}  // namespace facescan::testing
