// `facescan view`: one DDS subscriber (ScanStatus and MeshSnapshot of every session) feeding the ViewHub, and the
// web server that fans it out to every browser. Mesh downloads go through a second client, so a download never
// holds up the live feed.
#include <spawn.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <thread>

#include "client/view_hub.hpp"
#include "client/view_server.hpp"
#include "command_util.hpp"
#include "wire/private_files.hpp"

extern char** environ;

namespace facescan::client::detail {
namespace {

// Opens `url` with the desktop's browser (xdg-open), without waiting for it.
void openInBrowser(const std::string& url) {
    pid_t pid = 0;
    const char* argv[] = {"xdg-open", url.c_str(), nullptr};
    if (::posix_spawnp(&pid, "xdg-open", nullptr, nullptr, const_cast<char* const*>(argv), environ) != 0) {
        std::fprintf(stderr, "facescan view: cannot run xdg-open; open %s in a browser\n", url.c_str());
        return;
    }
    std::thread([pid] { ::waitpid(pid, nullptr, 0); }).detach();  // reaped when it is done, never a zombie
}

// $XDG_STATE_HOME/facescan/view-audit.log, else ~/.local/state/facescan/view-audit.log (the XDG default), else
// ./facescan-view-audit.log.
std::filesystem::path defaultViewAudit() {
    if (const char* state = std::getenv("XDG_STATE_HOME"); state != nullptr && *state == '/') {
        return std::filesystem::path(state) / "facescan" / "view-audit.log";
    }
    if (const char* home = std::getenv("HOME"); home != nullptr && *home == '/') {
        return std::filesystem::path(home) / ".local" / "state" / "facescan" / "view-audit.log";
    }
    return std::filesystem::current_path() / "facescan-view-audit.log";
}

}  // namespace

int runView(const CliOptions& options) {
    auto web_root = findWebRoot();
    if (!web_root.isOk()) return fail(kExitCannotServe, web_root.status().message());
    int code = kExitOk;
    // The live feed only reads (status and snapshots); downloads go through a client of their own.
    auto live = connectOrFail(options, code, /*commands=*/false);
    if (!live) return code;
    ViewHub hub;
    std::unique_ptr<ScanClient> commands;
    auto connected = ScanClient::connect(clientConfig(options));
    if (connected.isOk()) {
        if (Status s = (*connected)->enableCommands(); !s.isOk()) connected = s;
    }
    if (connected.isOk()) {
        commands = std::move(connected).value();
    } else {
        // An identity that may only read (the viewer role of a secured site) cannot publish ScanCommand.
        std::printf(
            "facescan view: cannot ask servers for meshes (%s): downloads are each session's latest "
            "snapshot, the final mesh once the scan is finished\n",
            connected.status().message().c_str());
    }
    std::mutex commands_mutex;  // a ScanClient runs one request at a time
    MeshFetcher fetch_mesh = [&](const std::string& session, bool want_texture) -> StatusOr<FetchedMesh> {
        FetchedMesh fetched;
        if (!commands) {
            ASSIGN_OR_RETURN(fetched.draco, hub.snapshotMesh(session));
            return fetched;
        }
        std::lock_guard lock(commands_mutex);
        ASSIGN_OR_RETURN(CommandReply reply, commands->request(session, facescan_wire_CMD_GET_MESH, want_texture));
        if (reply.payload.empty()) return notFound("session '" + session + "' has no mesh yet (nothing integrated)");
        fetched.draco = std::move(reply.payload);
        fetched.texture_png = std::move(reply.texture);
        return fetched;
    };
    ViewServerConfig config;
    config.bind = options.view_bind;
    config.port = options.view_port;
    config.web_root = *web_root;
    config.insecure_http = options.view_insecure_http;
    config.tls_dir = options.view_tls;
    config.audit_file = options.view_audit.empty() ? defaultViewAudit() : std::filesystem::path(options.view_audit);
    if (Status s = wire::createPrivateDir(config.audit_file.parent_path()); !s.isOk()) {
        return fail(kExitCannotServe, "the audit trail's folder: " + s.message());
    }
    auto server = ViewServer::start(config, hub, fetch_mesh);
    if (!server.isOk()) return fail(kExitCannotServe, server.status().message());
    // Before the first line that says it serves: a Ctrl-C from then on stops it cleanly.
    installInterruptHandler();
    const std::string url = (*server)->url();
    std::printf("facescan view: serving %s (%s; Ctrl-C stops)\n", url.c_str(), options.domain.describe().c_str());
    std::printf("facescan view: web files from %s; audit trail %s\n", web_root->c_str(), config.audit_file.c_str());
    if (!options.view_tls.empty()) {
        std::printf(
            "facescan view: HTTPS and WSS with the certificate and logins of %s; browsers must trust the "
            "site's CA (identity_ca.pem)\n",
            options.view_tls.c_str());
    }
    if (isLoopbackAddress(options.view_bind)) {
        std::printf("facescan view: this machine only; for others, --bind their network's address with --tls\n");
    }
    if (options.view_insecure_http) {
        std::fprintf(
            stderr,
            "facescan view: WARNING: --insecure-http: plain HTTP without a login%s: whoever reaches this port sees "
            "and downloads every scan, and the network carries the faces unencrypted\n",
            isLoopbackAddress(options.view_bind) ? " (on this machine only, for now)" : "");
    }
    std::fflush(stdout);
    if (options.view_open) openInBrowser(url);

    std::map<std::string, SessionStatus> statuses;
    std::vector<MeshSnapshotData> snapshots;
    bool erasures_heard = true;
    while (!g_interrupted) {
        // Erasures first: a scan deleted on the domain leaves this viewer's memory and every page.
        if (erasures_heard) {
            auto erased = live->takeErased();
            if (!erased.isOk()) {
                erasures_heard = false;
                std::fprintf(stderr,
                             "facescan view: WARNING: cannot hear facescan delete (%s): an erased scan stays on these "
                             "pages until the viewer restarts; with DDS Security, enrol its identity again "
                             "(site.sh add)\n",
                             erased.status().message().c_str());
            } else {
                for (const std::string& id : *erased) {
                    statuses.erase(id);
                    if (hub.erase(id)) {
                        std::printf("facescan view: scan %s was erased on the domain: dropped from this viewer\n",
                                    id.c_str());
                        std::fflush(stdout);
                    }
                }
            }
        }
        snapshots.clear();
        if (Status s = live->poll(std::chrono::milliseconds(200), statuses, kAllSessions, &snapshots); !s.isOk()) {
            (*server)->stop();
            return fail(kExitNoServer, s.message());
        }
        hub.updateStatuses(statuses);
        for (const MeshSnapshotData& snapshot : snapshots) hub.putSnapshot(frameSnapshot(snapshot));
    }
    (*server)->stop();
    std::printf("facescan view: stopped\n");
    return kExitOk;
}

}  // namespace facescan::client::detail
