// facescan-bench: benchmarks (not tests). Sub-commands: recon, detect, codecs, transport, accuracy, ...
#include <cstdio>
#include <string>
#include <vector>

#include "bench_command.hpp"
#include "facescan/version.hpp"

namespace facescan::bench {
std::map<std::string, Command>& commands() {
    static std::map<std::string, Command> registry;
    return registry;
}
}  // namespace facescan::bench

static void printUsage(std::FILE* out) {
    std::fprintf(out,
                 "usage: facescan-bench COMMAND [options] [--json]\n\n"
                 "Benchmarks of facescan: human-readable tables; with --json, one JSON object as the last line.\n\n"
                 "commands:\n");
    for (const auto& [name, command] : facescan::bench::commands()) {
        std::fprintf(out, "  %-10s %s\n", name.c_str(), command.summary.c_str());
    }
    std::fprintf(out,
                 "\n'facescan-bench COMMAND --help' describes a command's options; 'facescan-bench --version'\n"
                 "prints the version and the git commit it was built from.\n");
}

int main(int argc, char** argv) {
    if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
        printUsage(argc < 2 ? stderr : stdout);
        return argc < 2 ? 2 : 0;
    }
    if (std::string(argv[1]) == "--version") {
        facescan::printVersion("facescan-bench");
        return 0;
    }
    const auto& registry = facescan::bench::commands();
    const auto it = registry.find(argv[1]);
    if (it == registry.end()) {
        std::fprintf(stderr, "facescan-bench: unknown command '%s'\n\n", argv[1]);
        printUsage(stderr);
        return 2;
    }
    return it->second.run(std::vector<std::string>(argv + 2, argv + argc));
}
