// A real program of ours as a child process for integration tests, with its output in a log file; stopped with
// SIGTERM (SIGKILL after 10 s) and reaped on destruction, and killed when the test process dies. Safe to start from a
// test process that already runs threads (DDS): nothing allocates between fork and exec. kill9() for the failover tests
// (no clean exit, no last word on the network).
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

namespace facescan::testing {

class ChildProcess {
 public:
    ChildProcess(std::vector<std::string> args, const std::filesystem::path& log) : args_(std::move(args)) {
        std::vector<char*> argv;
        for (std::string& a : args_) argv.push_back(a.data());
        argv.push_back(nullptr);
        const std::string log_path = log.string();
        const pid_t parent = ::getpid();
        pid_ = ::fork();
        if (pid_ == 0) {
            // Ends with the test: a test process killed (a ctest timeout, a replay stopped by hand) left its servers
            // and agents running, minutes of CPU that slowed every test after it. The signal comes when the thread
            // that started the child ends: children are started from the test's main thread.
            ::prctl(PR_SET_PDEATHSIG, SIGKILL);
            if (::getppid() != parent) ::_exit(127);  // the test ended before the prctl

            const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
            if (fd >= 0) {
                ::dup2(fd, 1);
                ::dup2(fd, 2);
            }
            // Nothing else of the test process: its DDS sockets (Cyclone does not open them close-on-exec) would
            // count as the child's own, and a partition of the child (tests/cluster/partition.hpp) would cut the
            // test's own client off too.
            ::close_range(3, ~0U, 0);
            ::execv(argv[0], argv.data());
            ::_exit(127);
        }
    }
    ~ChildProcess() { stop(); }
    ChildProcess(const ChildProcess&) = delete;
    ChildProcess& operator=(const ChildProcess&) = delete;
    pid_t pid() const { return pid_; }
    bool running() const { return pid_ > 0; }
    // Sends `signal` (e.g. SIGINT, as Ctrl-C would) without waiting.
    void signal(int signal) {
        if (pid_ > 0) ::kill(pid_, signal);
    }
    // Waits for the program to end by itself; its exit code (128 + signal when killed), or -1 on timeout.
    int wait(std::chrono::seconds timeout) {
        const auto deadline = std::chrono::steady_clock::now() + timeout;
        while (pid_ > 0) {
            int status = 0;
            if (::waitpid(pid_, &status, WNOHANG) == pid_) {
                pid_ = 0;
                return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
            }
            if (std::chrono::steady_clock::now() >= deadline) break;
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
        return -1;
    }
    void stop() {
        if (pid_ <= 0) return;
        ::kill(pid_, SIGTERM);
        if (wait(std::chrono::seconds(10)) < 0) {
            ::kill(pid_, SIGKILL);
            ::waitpid(pid_, nullptr, 0);
        }
        pid_ = 0;
    }
    // As a crash or a power cut looks to the others: SIGKILL, reaped.
    void kill9() {
        if (pid_ <= 0) return;
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, nullptr, 0);
        pid_ = 0;
    }

 private:
    std::vector<std::string> args_;
    pid_t pid_ = 0;
};

// The whole content of a file (a child's log); empty when it cannot be read.
inline std::string readText(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace facescan::testing
