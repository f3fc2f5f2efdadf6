// What `facescan watch` shows: a small panel redrawn in place on a terminal, or one plain line per second when
// the output is a log or a pipe (demo, CI). Pure formatting, tested without a terminal.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "client/scan_client.hpp"

namespace facescan::client {

struct WatchView {
    SessionStatus status;
    bool have_status = false;
    uint32_t snapshot_seq = 0;
    uint32_t snapshot_triangles = 0;
    uint32_t snapshot_vertices = 0;
    std::optional<double> snapshot_age_s;  // seconds since the latest snapshot arrived; none yet: nullopt
    int snapshots_saved = 0;
    double elapsed_s = 0;  // since watching began
};

// The panel of a terminal: three lines, no trailing newlines.
std::vector<std::string> panelLines(const WatchView& view);
// One line for logs.
std::string logLine(const WatchView& view);
// 1234567 -> "1,234,567".
std::string groupThousands(uint64_t value);

}  // namespace facescan::client
