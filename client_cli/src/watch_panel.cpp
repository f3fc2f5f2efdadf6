// Formatting of `facescan watch`: the terminal panel and the log line.
#include "client/watch_panel.hpp"

#include <cstdio>

namespace facescan::client {
namespace {

std::string format(const char* fmt, auto... args) {
    char buf[512];
    std::snprintf(buf, sizeof(buf), fmt, args...);
    return buf;
}

std::string ageText(const WatchView& view) {
    if (!view.snapshot_age_s) return "no snapshot yet";
    return format("snapshot #%u, %.1f s old", view.snapshot_seq, *view.snapshot_age_s);
}

std::string stateText(const SessionStatus& s) {
    std::string text = scanStateName(s.state);
    if (!s.alive) text += " (server gone)";
    if (!s.detail.empty()) text += " - " + s.detail;
    return text;
}

}  // namespace

std::string groupThousands(uint64_t value) {
    const std::string digits = std::to_string(value);
    std::string out;
    out.reserve(digits.size() + digits.size() / 3);
    for (size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
        out += digits[i];
    }
    return out;
}

std::vector<std::string> panelLines(const WatchView& view) {
    const SessionStatus& s = view.status;
    if (!view.have_status) {
        return {format("waiting for session %s ... (%.0f s)", s.session_id.c_str(), view.elapsed_s), "", ""};
    }
    std::vector<std::string> lines;
    lines.push_back(format("%-10s %s   %s", s.session_id.c_str(), stateText(s).c_str(),
                           s.server_id.empty() ? "" : ("on " + s.server_id).c_str()));
    lines.push_back(format("frames     %s integrated / %s received  (%u rejected, %u skipped, %u dropped)  %.1f fps%s",
                           groupThousands(s.frames_integrated).c_str(), groupThousands(s.frames_received).c_str(),
                           s.frames_rejected, s.frames_skipped, s.frames_dropped, s.fps,
                           s.every_frame ? "  [recording: every frame]" : ""));
    if (s.frames_tracked_only > 0) {
        lines.back() += format("  + %s tracked only", groupThousands(s.frames_tracked_only).c_str());
    }
    std::string mesh =
        format("mesh       %s triangles, %s", groupThousands(view.snapshot_triangles).c_str(), ageText(view).c_str());
    if (view.snapshots_saved > 0) mesh += format("  (%d saved)", view.snapshots_saved);
    lines.push_back(mesh);
    return lines;
}

std::string logLine(const WatchView& view) {
    const SessionStatus& s = view.status;
    if (!view.have_status) return format("[%6.1f s] waiting for session %s", view.elapsed_s, s.session_id.c_str());
    std::string line =
        format("[%6.1f s] %s %s  integrated %u/%u  rejected %u  fps %.1f  triangles %s  %s", view.elapsed_s,
               s.session_id.c_str(), scanStateName(s.state), s.frames_integrated, s.frames_received, s.frames_rejected,
               s.fps, groupThousands(view.snapshot_triangles).c_str(), ageText(view).c_str());
    if (s.frames_tracked_only > 0) line += format("  tracked only %u", s.frames_tracked_only);
    if (!s.alive) line += "  (server gone)";
    if (!s.detail.empty()) line += "  (" + s.detail + ")";
    return line;
}

}  // namespace facescan::client
