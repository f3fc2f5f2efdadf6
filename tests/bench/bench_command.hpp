// facescan-bench sub-commands register themselves here; main.cpp dispatches by name.
// Each sub-command prints a human-readable table and, with --json, one JSON object as its LAST line
// (keys in docs/design.md section 6; scripts read them).
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace facescan::bench {

struct Command {
    std::string summary;                                           // one line for `facescan-bench --help`
    std::function<int(const std::vector<std::string>& args)> run;  // args after the sub-command name
};

std::map<std::string, Command>& commands();

struct Registrar {
    Registrar(const std::string& name, Command command) { commands().emplace(name, std::move(command)); }
};

}  // namespace facescan::bench

#define FACESCAN_BENCH_COMMAND(name, summary, fn)                             \
    static const ::facescan::bench::Registrar facescan_bench_registrar_##fn { \
        name, { summary, fn }                                                 \
    }
