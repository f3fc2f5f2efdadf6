// `facescan watch [SESSION] [--save DIR]`: follows one scan live until it is finished.
#include <sys/ioctl.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <optional>

#include "client/mesh_file.hpp"
#include "client/watch_panel.hpp"
#include "command_util.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::client::detail {
namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// The newest live scan: not finished, its server alive, and the fewest frames received (ScanStatus carries no
// start time; at the same frame rate the scan that started last has received the fewest). Ties: by id.
std::string newestLiveSession(const std::map<std::string, SessionStatus>& statuses) {
    const SessionStatus* best = nullptr;
    for (const auto& [id, s] : statuses) {
        if (!s.alive || s.state == facescan_wire_STATE_FINISHED) continue;
        if (!best || s.frames_received < best->frames_received) best = &s;
    }
    return best ? best->session_id : std::string();
}

// Draws the panel in place on a terminal (cursor up, clear line), or prints a log line.
class Display {
 public:
    explicit Display(bool tty) : tty_(tty) {}

    void draw(const WatchView& view) {
        if (!tty_) {
            std::printf("%s\n", logLine(view).c_str());
            std::fflush(stdout);
            return;
        }
        winsize ws{};
        const size_t width = ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 0 ? ws.ws_col : 120;
        const std::vector<std::string> lines = panelLines(view);
        if (drawn_lines_ > 0) std::printf("\x1b[%dA", drawn_lines_);  // back to the panel's first line
        for (const std::string& line : lines) {
            // Clipped to the terminal: a wrapped line would break the cursor arithmetic.
            std::printf("\x1b[2K%s\n", line.substr(0, width - 1).c_str());
        }
        drawn_lines_ = static_cast<int>(lines.size());
        std::fflush(stdout);
    }

    // A message above (and outside) the panel.
    void message(const std::string& text) {
        if (tty_ && drawn_lines_ > 0) {
            std::printf("\x1b[%dA\x1b[J", drawn_lines_);
            drawn_lines_ = 0;
        }
        std::printf("%s\n", text.c_str());
        std::fflush(stdout);
    }

    bool tty() const { return tty_; }

 private:
    bool tty_;
    int drawn_lines_ = 0;
};

Status saveSnapshot(const MeshSnapshotData& snap, const fs::path& dir, const std::string& format) {
    char name[32];
    std::snprintf(name, sizeof(name), "-%05u.", snap.seq);
    const fs::path path = dir / (snap.session_id + name + format);
    if (format == "drc") {
        return writeFileAtomically(
            path, std::string_view(reinterpret_cast<const char*>(snap.draco.data()), snap.draco.size()));
    }
    ASSIGN_OR_RETURN(const recon::IndexedMesh mesh, wire::decodeIndexedMesh(snap.draco.data(), snap.draco.size()));
    return writeMeshFile(mesh, path);
}

}  // namespace

int runWatch(const CliOptions& options) {
    if (!options.save_dir.empty()) {
        std::error_code ec;
        fs::create_directories(options.save_dir, ec);
        if (Status s = checkWritable(fs::path(options.save_dir) / "snapshot.ply"); !s.isOk()) {
            return fail(kExitCannotWrite, "cannot save snapshots in '" + options.save_dir + "': " + s.message());
        }
    }
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    if (Status s = client->waitForServer(); !s.isOk()) return fail(exitCodeForRequest(s), s.message());
    installInterruptHandler();

    Display display(isatty(STDOUT_FILENO) == 1);
    const auto start = Clock::now();
    const double redraw_s = display.tty() ? 0.25 : 1.0;
    std::string session = options.session;
    std::map<std::string, SessionStatus> statuses;
    std::vector<MeshSnapshotData> snapshots;
    WatchView view;
    view.status.session_id = session;
    std::optional<Clock::time_point> snapshot_received;
    std::optional<Clock::time_point> last_draw;
    // A change of state (scanning -> lost -> scanning) is drawn at once: a log line a second could miss a short
    // loss and the advice that came with it ("face lost: come back in front of the camera").
    std::optional<facescan_wire_ScanState> drawn_state;
    bool confirmed = false;  // a server said it owns the session (it may not have published a status yet)
    std::optional<Clock::time_point> owner_lost;  // when the session's status lost its live writer
    if (session.empty()) display.message("waiting for a scan to start (Ctrl-C to stop) ...");

    while (!g_interrupted) {
        snapshots.clear();
        if (Status s = client->poll(std::chrono::milliseconds(100), statuses, session, &snapshots); !s.isOk()) {
            return fail(kExitNoServer, s.message());
        }
        view.elapsed_s = secondsSince(start);
        if (session.empty()) {
            session = newestLiveSession(statuses);
            if (session.empty()) continue;
            view.status.session_id = session;
            display.message("following " + session);
            continue;  // the snapshot reader starts with the next poll
        }
        for (const MeshSnapshotData& snap : snapshots) {
            if (snap.seq < view.snapshot_seq && view.snapshot_age_s) continue;  // an older, late sample
            view.snapshot_seq = snap.seq;
            view.snapshot_triangles = snap.triangle_count;
            view.snapshot_vertices = snap.vertex_count;
            snapshot_received = snap.received;
            if (!options.save_dir.empty()) {
                if (Status s = saveSnapshot(snap, options.save_dir, options.save_format); !s.isOk()) {
                    return fail(s.code() == StatusCode::kUnavailable ? kExitCannotWrite : kExitServerError,
                                "snapshot " + std::to_string(snap.seq) + ": " + s.message());
                }
                ++view.snapshots_saved;
            }
        }
        if (snapshot_received) view.snapshot_age_s = secondsSince(*snapshot_received);
        if (const auto it = statuses.find(session); it != statuses.end()) {
            view.status = it->second;
            view.have_status = true;
        } else if (!confirmed && view.elapsed_s * 1000 > static_cast<double>(options.timeout.count())) {
            // Not on ScanStatus within the timeout: ask whether anybody owns it before giving up.
            auto ping = client->request(session, facescan_wire_CMD_GET_STATUS);
            if (!ping.isOk()) return fail(exitCodeForRequest(ping.status()), ping.status().message());
            confirmed = true;
        }
        const bool finished = view.have_status && view.status.state == facescan_wire_STATE_FINISHED;
        // A dead owner with a standby: the standby takes over within the lease; wait for it a while.
        if (view.have_status && !view.status.alive && !owner_lost) {
            owner_lost = Clock::now();
            if (!view.status.standby_id.empty()) {
                display.message("the server of " + session + " is gone: waiting for its standby '" +
                                view.status.standby_id + "' to take over");
            }
        }
        if (view.have_status && view.status.alive) owner_lost.reset();
        const double takeover_wait_s = view.status.standby_id.empty() ? 0.0 : 15.0;
        const bool gone = owner_lost && secondsSince(*owner_lost) >= takeover_wait_s;
        const bool state_changed = view.have_status && drawn_state != view.status.state;
        if (finished || gone || state_changed || !last_draw || secondsSince(*last_draw) >= redraw_s) {
            display.draw(view);
            last_draw = Clock::now();
            if (view.have_status) drawn_state = view.status.state;
        }
        if (finished) {
            display.message("scan " + session + " finished: " + groupThousands(view.status.frames_integrated) +
                            " frames integrated, " + groupThousands(view.snapshot_triangles) +
                            " triangles in the last snapshot");
            return kExitOk;
        }
        if (gone) return fail(kExitNoServer, "the server of session '" + session + "' is gone");
    }
    display.message("stopped watching " + (session.empty() ? std::string("(no scan started)") : session) +
                    " (the scan goes on)");
    return kExitInterrupted;
}

}  // namespace facescan::client::detail
