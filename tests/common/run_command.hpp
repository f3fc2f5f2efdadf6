// Runs a shell command line (a real program of ours, in tests) and captures its output and exit code.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

namespace facescan::testing {

struct CommandRun {
    int exit_code = -1;  // -1 when the command could not be started or did not exit normally
    std::string out;     // stdout and stderr together
};

inline CommandRun runCommand(const std::string& command_line) {
    const std::string command = command_line + " 2>&1";
    CommandRun run;
    FILE* pipe = ::popen(command.c_str(), "r");
    if (!pipe) return run;
    std::array<char, 4096> buf{};
    size_t n = 0;
    while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) run.out.append(buf.data(), n);
    const int status = ::pclose(pipe);
    run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return run;
}

}  // namespace facescan::testing
