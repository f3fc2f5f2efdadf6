// The one-shot commands of `facescan` (sessions, status, mesh, preview, trajectory, finish, reset) and the
// program's entry point. `watch` lives in watch_command.cpp.
#include "client/commands.hpp"

#include <csignal>
#include <cstdio>
#include <iostream>

#include "client/mesh_file.hpp"
#include "client/status_json.hpp"
#include "client/textured_mesh_file.hpp"
#include "command_util.hpp"
#include "facescan/version.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::client {
namespace detail {

std::atomic<bool> g_interrupted{false};

namespace {
extern "C" void onInterrupt(int) { g_interrupted = true; }
}  // namespace

void installInterruptHandler() {
    struct sigaction action {};
    action.sa_handler = onInterrupt;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
}

int fail(int code, const std::string& message) {
    std::fprintf(stderr, "facescan: error: %s\n", message.c_str());
    return code;
}

int exitCodeForRequest(const Status& status) {
    switch (status.code()) {
        case StatusCode::kDeadlineExceeded:
        case StatusCode::kUnavailable: return kExitNoServer;
        case StatusCode::kPermissionDenied: return kExitNotAllowed;
        default: return kExitServerError;
    }
}

ClientConfig clientConfig(const CliOptions& options) {
    ClientConfig config;
    config.domain = options.domain;
    config.timeout = options.timeout;
    return config;
}

std::unique_ptr<ScanClient> connectOrFail(const CliOptions& options, int& exit_code, bool commands) {
    ClientConfig config = clientConfig(options);
    config.commands = commands;
    auto client = ScanClient::connect(config);
    if (client.isOk()) return std::move(client).value();
    // A profile or identity that does not exist or does not parse is the user's command line; a refused identity
    // (DDS Security) is not allowed; anything else is DDS.
    const StatusCode code = client.status().code();
    exit_code = fail(code == StatusCode::kNotFound || code == StatusCode::kInvalidArgument ? kExitUsage
                     : code == StatusCode::kPermissionDenied                               ? kExitNotAllowed
                                                                                           : kExitNoServer,
                     client.status().message());
    return nullptr;
}

}  // namespace detail

namespace {

using namespace detail;

int runSessions(const CliOptions& options) {
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    auto sessions = client->sessions(std::chrono::milliseconds(1000));
    if (!sessions.isOk()) return fail(exitCodeForRequest(sessions.status()), sessions.status().message());
    auto owners = client->owners(std::chrono::milliseconds(200));
    if (!owners.isOk()) return fail(exitCodeForRequest(owners.status()), owners.status().message());
    if (options.json) {
        for (const SessionStatus& s : *sessions) {
            const Ownership o = ownershipOf(s, *owners);
            std::printf("%s\n", statusJson(s, false, &o).c_str());
        }
        return kExitOk;
    }
    if (sessions->empty()) {
        std::printf("no sessions on domain %u (a server is running; start an agent to scan)\n",
                    options.domain.domain_id);
        return kExitOk;
    }
    std::printf("%-24s %-9s %10s %10s %8s %6s  %-20s %s\n", "SESSION", "STATE", "INTEGRATED", "RECEIVED", "REJECTED",
                "FPS", "OWNER", "STANDBY");
    for (const SessionStatus& s : *sessions) {
        const Ownership o = ownershipOf(s, *owners);
        const std::string owner = o.alive ? o.owner : o.owner + " (gone)";
        // A session that cannot keep up is named as such; `facescan status` says by how much.
        std::printf("%-24s %-9s %10u %10u %8u %6.1f  %-20s %s%s\n", s.session_id.c_str(), scanStateName(s.state),
                    s.frames_integrated, s.frames_received, s.frames_rejected, s.fps, owner.c_str(),
                    o.standby.empty() ? "-" : o.standby.c_str(), s.behind ? "  BEHIND" : "");
    }
    return kExitOk;
}

std::string uptimeText(int64_t started_ns) {
    const auto now_ns =
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
            .count();
    const int64_t s = std::max<int64_t>(0, (now_ns - started_ns) / 1'000'000'000);
    char buf[32];
    if (s >= 3600) {
        std::snprintf(buf, sizeof(buf), "%lldh%02lldm", static_cast<long long>(s / 3600),
                      static_cast<long long>(s / 60 % 60));
    } else {
        std::snprintf(buf, sizeof(buf), "%lldm%02llds", static_cast<long long>(s / 60), static_cast<long long>(s % 60));
    }
    return buf;
}

int runServers(const CliOptions& options) {
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    auto servers =
        client->servers(std::chrono::milliseconds(std::min<int64_t>(1000, options.timeout.count())), options.timeout);
    if (!servers.isOk()) return fail(exitCodeForRequest(servers.status()), servers.status().message());
    if (options.json) {
        for (const ServerInfo& s : *servers) {
            std::printf(
                "{\"server\":%s,\"host\":%s,\"pid\":%u,\"open_sessions\":%u,\"max_sessions\":%u,"
                "\"standby_sessions\":%u,\"cpu_load\":%.2f,\"started_ns\":%lld,\"joining\":%s,"
                "\"protocol\":%u,\"software\":%s,\"responding\":%s}\n",
                jsonString(s.server_id).c_str(), jsonString(s.host).c_str(), s.pid, s.open_sessions, s.max_sessions,
                s.standby_sessions, s.cpu_load, static_cast<long long>(s.started_ns), s.joining ? "true" : "false",
                s.protocol_version, jsonString(s.software).c_str(), s.responding ? "true" : "false");
        }
        return kExitOk;
    }
    std::printf("%-24s %-16s %9s %8s %6s %8s  %s\n", "SERVER", "HOST", "SESSIONS", "STANDBY", "LOAD", "UPTIME",
                "VERSION");
    for (const ServerInfo& s : *servers) {
        const std::string sessions = std::to_string(s.open_sessions) + "/" + std::to_string(s.max_sessions);
        std::string version = s.software;
        if (s.protocol_version != wire::kClusterProtocolVersion) version += " (other protocol: not a peer)";
        if (s.joining) version += " (joining)";
        if (!s.responding) version += " (NOT RESPONDING: frozen or overloaded; its scans move if it stays so)";
        std::printf("%-24s %-16s %9s %8u %6.2f %8s  %s\n", s.server_id.c_str(), s.host.c_str(), sessions.c_str(),
                    s.standby_sessions, s.cpu_load, uptimeText(s.started_ns).c_str(), version.c_str());
    }
    return kExitOk;
}

int runStatus(const CliOptions& options) {
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    // The ping says who owns the session (or that nobody does); the state itself is on ScanStatus.
    auto ping = client->request(options.session, facescan_wire_CMD_GET_STATUS);
    if (!ping.isOk()) return fail(exitCodeForRequest(ping.status()), ping.status().message());
    auto sessions = client->sessions(std::chrono::milliseconds(600));
    if (!sessions.isOk()) return fail(exitCodeForRequest(sessions.status()), sessions.status().message());
    const SessionStatus* found = nullptr;
    for (const SessionStatus& s : *sessions) {
        if (s.session_id == options.session) found = &s;
    }
    if (!found) {
        if (options.json) {
            std::printf("{\"session\":%s,\"server\":%s,\"state\":null}\n", jsonString(options.session).c_str(),
                        jsonString(ping->server_id).c_str());
        } else {
            std::printf("%s: owned by %s; no status published yet\n", options.session.c_str(), ping->server_id.c_str());
        }
        return kExitOk;
    }
    const SessionStatus& s = *found;
    auto owners = client->owners(std::chrono::milliseconds(100));
    const Ownership o = ownershipOf(s, owners.isOk() ? *owners : std::map<std::string, OwnerInfo>{});
    if (options.json) {
        std::printf("%s\n", statusJson(s, false, &o).c_str());
        return kExitOk;
    }
    std::printf("session     %s\n", s.session_id.c_str());
    std::printf("owner       %s (epoch %u%s)\n", o.owner.c_str(), o.epoch, o.alive ? "" : ", gone");
    std::printf("standby     %s\n", o.standby.empty() ? "none" : o.standby.c_str());
    if (s.failovers > 0) {
        std::printf("failovers   %u (last takeover %.0f ms)\n", s.failovers, static_cast<double>(s.last_takeover_ms));
    } else {
        std::printf("failovers   0\n");
    }
    std::printf("state       %s%s%s\n", scanStateName(s.state), s.detail.empty() ? "" : " - ", s.detail.c_str());
    std::printf("mode        %s\n", s.every_frame ? "recording (every frame processed)" : "live (newest frame)");
    std::printf("frames      %u received, %u integrated, %u rejected, %u skipped, %u dropped\n", s.frames_received,
                s.frames_integrated, s.frames_rejected, s.frames_skipped, s.frames_dropped);
    if (s.frames_tracked_only > 0) {
        std::printf("            %u more tracked but not fused (the server was loaded: it fused every other frame)\n",
                    s.frames_tracked_only);
    }
    std::printf("speed       %.1f fps, latency p95 %.1f ms\n", s.fps, s.latency_p95_ms);
    std::printf(
        "stages ms   detect %.2f  segment %.2f  filter %.2f  icp %.2f  integrate %.2f  raycast %.2f  "
        "mesh %.2f\n",
        s.ms_detect, s.ms_segment, s.ms_filter, s.ms_icp, s.ms_integrate, s.ms_raycast, s.ms_mesh);
    std::printf("snapshot    #%u\n", s.snapshot_seq);
    return kExitOk;
}

std::string sizeText(size_t bytes) {
    char buf[32];
    if (bytes >= (1u << 20)) {
        std::snprintf(buf, sizeof(buf), "%.1f MB", static_cast<double>(bytes) / (1 << 20));
    } else {
        std::snprintf(buf, sizeof(buf), "%.1f kB", static_cast<double>(bytes) / 1024);
    }
    return buf;
}

// A finished model with its texture (textured_mesh_file.hpp): the files written, and what they hold.
int writeTextured(const CliOptions& options, const CommandReply& reply) {
    auto textured = decodeTexturedMesh(reply.payload, reply.texture);
    if (!textured.isOk()) {
        return fail(kExitServerError, "the server's textured model cannot be decoded: " + textured.status().message() +
                                          " (--vertex-colours fetches the mesh without its texture)");
    }
    auto written = writeTexturedMeshFiles(*textured, options.output);
    if (!written.isOk()) {
        return fail(written.status().code() == StatusCode::kUnavailable ? kExitCannotWrite : kExitServerError,
                    written.status().message());
    }
    std::string names;
    size_t bytes = 0;
    for (const std::filesystem::path& path : *written) {
        std::error_code ec;
        bytes += static_cast<size_t>(std::filesystem::file_size(path, ec));
        names += (names.empty() ? "" : ", ") + path.string();
    }
    std::printf("wrote %s: %s vertices, %s triangles, textured (%d x %d texture%s) (%s)\n", names.c_str(),
                std::to_string(textured->mesh.vertexCount()).c_str(),
                std::to_string(textured->mesh.triangleCount()).c_str(), textured->atlas_bgr.cols,
                textured->atlas_bgr.rows,
                textured->mesh.hasColours() && meshFormatFor(options.output).value() != MeshFormat::kGlb
                    ? ", vertex colours kept"
                    : "",
                sizeText(bytes).c_str());
    return kExitOk;
}

int runMesh(const CliOptions& options) {
    // Fail before any network work when the result could not be written anyway.
    if (Status s = checkWritable(options.output); !s.isOk()) return fail(kExitCannotWrite, s.message());
    const MeshFormat format = meshFormatFor(options.output).value();  // checked by parseArgs
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    if (options.finish) {
        auto finished = client->request(options.session, facescan_wire_CMD_FINISH);
        if (!finished.isOk()) return fail(exitCodeForRequest(finished.status()), finished.status().message());
        std::printf("finished %s on %s: %s triangles\n", options.session.c_str(), finished->server_id.c_str(),
                    std::to_string(finished->triangle_count).c_str());
    }
    // The texture when the file can hold it; finishing here works on the vertex-coloured mesh.
    const bool want_texture = formatHasTexture(format) && !options.vertex_colours && !options.finish_here;
    auto reply = client->request(options.session, facescan_wire_CMD_GET_MESH, want_texture);
    if (!reply.isOk()) return fail(exitCodeForRequest(reply.status()), reply.status().message());
    if (reply->payload.empty()) {
        return fail(kExitServerError,
                    "the server sent no mesh for '" + options.session + "' (nothing integrated yet?)");
    }
    if (!reply->texture.empty()) return writeTextured(options, *reply);
    // Decoded even for .drc: the bytes are checked before they land in a file, and the counts are reported.
    auto mesh = wire::decodeIndexedMesh(reply->payload.data(), reply->payload.size());
    if (!mesh.isOk()) return fail(kExitServerError, "the server's mesh cannot be decoded: " + mesh.status().message());
    if (options.finish_here) {
        // The options were validated by parseArgs: finishing cannot refuse here. The user always gets a model.
        auto report = recon::finishMesh(*mesh, options.finish_params);
        if (!report.isOk()) return fail(kExitUsage, report.status().message());
        std::printf("finished here: %s\n", report->summary().c_str());
        if (mesh->triangles.empty()) {
            return fail(kExitUsage, "nothing of the model is left to write (is the --crop box where the head is?)");
        }
    }
    // The server's Draco bytes are the file only while the mesh is the server's.
    if (Status s = writeMeshFile(*mesh, options.output, options.finish_here ? nullptr : &reply->payload); !s.isOk()) {
        return fail(s.code() == StatusCode::kUnavailable ? kExitCannotWrite : kExitServerError, s.message());
    }
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(options.output, ec);
    std::printf("wrote %s: %s vertices, %s triangles, %s (%s)\n", options.output.c_str(),
                std::to_string(mesh->vertexCount()).c_str(), std::to_string(mesh->triangleCount()).c_str(),
                formatHasColours(format) && mesh->hasColours()
                    ? (want_texture ? "vertex colours (no texture: the scan is not finished, or had no colour)"
                                    : "with colours")
                    : "no colours",
                sizeText(ec ? 0 : bytes).c_str());
    return kExitOk;
}

// preview and trajectory: the reply's payload is the file.
int runPayloadCommand(const CliOptions& options, facescan_wire_CommandKind kind) {
    const bool to_stdout = options.output.empty() || options.output == "-";
    if (!to_stdout) {
        if (Status s = checkWritable(options.output); !s.isOk()) return fail(kExitCannotWrite, s.message());
    }
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    auto reply = client->request(options.session, kind);
    if (!reply.isOk()) return fail(exitCodeForRequest(reply.status()), reply.status().message());
    const std::vector<uint8_t>& payload = reply->payload;
    if (kind == facescan_wire_CMD_GET_PREVIEW) {
        static constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
        if (payload.size() < 8 || !std::equal(kPngSignature, kPngSignature + 8, payload.begin())) {
            return fail(kExitServerError,
                        "the server's preview is not a PNG picture (" + std::to_string(payload.size()) + " bytes)");
        }
    }
    const std::string_view bytes(reinterpret_cast<const char*>(payload.data()), payload.size());
    if (to_stdout) {
        std::fwrite(bytes.data(), 1, bytes.size(), stdout);
        return std::fflush(stdout) == 0 ? kExitOk : fail(kExitCannotWrite, "cannot write to standard output");
    }
    if (Status s = writeFileAtomically(options.output, bytes); !s.isOk()) return fail(kExitCannotWrite, s.message());
    std::printf("wrote %s (%s)\n", options.output.c_str(), sizeText(payload.size()).c_str());
    return kExitOk;
}

int runSimpleCommand(const CliOptions& options, facescan_wire_CommandKind kind) {
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    auto reply = client->request(options.session, kind);
    if (!reply.isOk()) return fail(exitCodeForRequest(reply.status()), reply.status().message());
    if (kind == facescan_wire_CMD_FINISH) {
        std::printf("finished %s on %s: %u vertices, %u triangles\n", options.session.c_str(), reply->server_id.c_str(),
                    reply->vertex_count, reply->triangle_count);
    } else {
        std::printf("reset %s on %s: scanning starts again\n", options.session.c_str(), reply->server_id.c_str());
    }
    return kExitOk;
}

}  // namespace

int runCommand(const CliOptions& options) {
    if (options.version) {
        printVersion("facescan");
        return kExitOk;
    }
    if (options.help) {
        std::fputs(usageText(options.help_topic).c_str(), stdout);
        return kExitOk;
    }
    switch (options.command) {
        case Command::kSessions: return runSessions(options);
        case Command::kWatch: return runWatch(options);
        case Command::kStatus: return runStatus(options);
        case Command::kMesh: return runMesh(options);
        case Command::kPreview: return runPayloadCommand(options, facescan_wire_CMD_GET_PREVIEW);
        case Command::kTrajectory: return runPayloadCommand(options, facescan_wire_CMD_GET_TRAJECTORY);
        case Command::kFinish: return runSimpleCommand(options, facescan_wire_CMD_FINISH);
        case Command::kReset: return runSimpleCommand(options, facescan_wire_CMD_RESET);
        case Command::kView: return runView(options);
        case Command::kServers: return runServers(options);
        case Command::kAudit: return runAudit(options);
        case Command::kDelete: return runDelete(options);
    }
    return kExitUsage;
}

int facescanMain(int argc, char** argv) {
    std::vector<std::string> args(argv + 1, argv + argc);
    auto options = parseArgs(args);
    if (!options.isOk()) {
        // One line and where to read more: the full usage would bury the message.
        std::string command;
        for (const std::string& a : args) {
            if (!usageText(a).starts_with("Usage: facescan [OPTIONS]")) {
                command = a;
                break;
            }
        }
        std::fprintf(stderr, "facescan: %s\nTry 'facescan %s--help'.\n", options.status().message().c_str(),
                     command.empty() ? "" : (command + " ").c_str());
        return kExitUsage;
    }
    return runCommand(*options);
}

}  // namespace facescan::client
