// A real program of ours as a child process (servers and agents in integration tests), its output in a log file.
// Safe to start from a test process that already runs threads (DDS): nothing allocates between fork and exec.
#pragma once

#include <fcntl.h>
#include <signal.h>
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
        pid_ = ::fork();
        if (pid_ == 0) {
            const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
            if (fd >= 0) {
                ::dup2(fd, 1);
                ::dup2(fd, 2);
            }
            ::execv(argv[0], argv.data());
            ::_exit(127);
        }
    }
    ~ChildProcess() { stop(); }
    ChildProcess(const ChildProcess&) = delete;
    ChildProcess& operator=(const ChildProcess&) = delete;

    // Waits for the program to end by itself; its exit code (128 + signal when killed), or -1 on timeout.
    int wait(std::chrono::milliseconds timeout) {
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
    bool running() const { return pid_ > 0; }
    // SIGTERM (SIGKILL after 10 s), reaped.
    void stop() { signal(SIGTERM); }
    // Sends `sig` and reaps the process (SIGKILL when it has not ended 10 s after a softer signal).
    void signal(int sig) {
        if (pid_ <= 0) return;
        ::kill(pid_, sig);
        if (wait(std::chrono::seconds(10)) < 0) {
            ::kill(pid_, SIGKILL);
            ::waitpid(pid_, nullptr, 0);
        }
        pid_ = 0;
    }

 private:
    std::vector<std::string> args_;
    pid_t pid_ = 0;
};

inline std::string readText(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace facescan::testing
