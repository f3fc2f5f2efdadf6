// facescan-server: the thin main around service::Server (recon_server/service). Parses and validates the
// parameters, runs until SIGINT/SIGTERM, then finishes every open session to disk and exits 0.
#include <malloc.h>
#include <signal.h>

#include <cstdio>
#include <string>
#include <vector>

#include "facescan/version.hpp"
#include "service/server.hpp"
#include "service/session_store.hpp"
#include "wire/dds.hpp"
#include "wire/dds_options.hpp"
#include "wire/private_files.hpp"

int main(int argc, char** argv) {
    using namespace facescan;
    // One malloc arena for the process, before any thread allocates. glibc gives threads that allocate at once
    // arenas of their own (up to 8 a core), and malloc_trim never returns the free top of those, only the main
    // arena's: each session's engine, worker and copies come and go in threads of their own, so an idle server kept
    // 50-250 MB of freed memory spread over up to 16 arenas, more after each burst of scans (the chaos soak's idle
    // checkpoints). Six recordings, three at a time, then idle: 87 MB resident against 133-184 MB, in the same
    // wall and CPU time (docs/benchmarks.md, Memory).
    (void)mallopt(M_ARENA_MAX, 1);
    const std::vector<std::string> args(argv + 1, argv + argc);
    if (!args.empty() && args[0] == "--version") {
        printVersion("facescan-server");
        return 0;
    }
    auto parsed = service::parseServerArgs(args);
    if (!parsed.isOk()) {
        std::fprintf(stderr, "facescan-server: %s\n(see facescan-server --help)\n", parsed.status().message().c_str());
        return 2;
    }
    if (parsed->help) {
        std::fputs(service::serverUsage().c_str(), stdout);
        return 0;
    }
    if (parsed->check) {  // what an administrator runs after editing the config file
        const service::ServerParams& p = parsed->params;
        Status s = service::checkDataDir(p.data_dir);
        const auto profile_file = wire::findProfileFile(p.domain.profile);
        if (s.isOk()) {
            auto xml = wire::loadProfileXml(p.domain.profile);
            s = xml.isOk() ? wire::checkSocketBuffers(*xml) : xml.status();
        }
        if (!s.isOk()) {
            std::fprintf(stderr, "facescan-server: configuration NOT ok: %s\n", s.message().c_str());
            return 1;
        }
        std::printf("facescan-server: configuration ok: profile %s (%s), domain %u, data in %s, preset %s\n",
                    p.domain.profile.c_str(), profile_file->c_str(), p.domain.domain_id, p.data_dir.c_str(),
                    p.preset.c_str());
        return 0;
    }
    // Block the stop signals in every thread (the server's threads inherit this mask) and wait for them here.
    sigset_t stop_signals;
    sigemptyset(&stop_signals);
    sigaddset(&stop_signals, SIGINT);
    sigaddset(&stop_signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

    const service::ServerParams& p = parsed->params;
    auto server = service::Server::create(p);
    if (!server.isOk()) {
        std::fprintf(stderr, "facescan-server: cannot start: %s\n", server.status().message().c_str());
        return 1;
    }
    std::fprintf(stderr, "facescan-server '%s': %s, preset %s, up to %d sessions, snapshots %.2g Hz, data in %s\n",
                 p.server_id.c_str(), p.domain.describe().c_str(), p.preset.c_str(), p.max_sessions,
                 static_cast<double>(p.snapshot_hz), p.data_dir.c_str());
    std::fprintf(stderr, "facescan-server: %s\n", wire::securitySummary(p.domain).c_str());
    std::fprintf(stderr, "facescan-server: files: %s\n", wire::kFileProtectionSummary);
    int sig = 0;
    sigwait(&stop_signals, &sig);
    std::fprintf(stderr, "facescan-server: %s: finishing %d open session(s)\n", sig == SIGINT ? "SIGINT" : "SIGTERM",
                 (*server)->openSessions());
    (*server)->shutdown();
    for (const auto& s : (*server)->sessions()) {
        const std::string tracked_only =
            s.frames_tracked_only > 0 ? ", " + std::to_string(s.frames_tracked_only) + " more tracked only" : "";
        std::fprintf(stderr, "  %s: %s, %u frames integrated%s (%s)\n", s.session_id.c_str(),
                     service::sessionStateName(s.state), s.frames_integrated, tracked_only.c_str(), s.detail.c_str());
    }
    return 0;
}
