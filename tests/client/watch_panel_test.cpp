// The watch panel and log line carry every figure a person watching a scan needs: frames integrated, fps, tracking
// state, triangles and snapshot age.
#include "client/watch_panel.hpp"

#include <gtest/gtest.h>

namespace facescan::client {
namespace {

WatchView scanningView() {
    WatchView view;
    view.have_status = true;
    view.status.session_id = "demo-7";
    view.status.server_id = "box:42";
    view.status.state = facescan_wire_STATE_SCANNING;
    view.status.detail = "face found";
    view.status.frames_received = 151;
    view.status.frames_integrated = 142;
    view.status.frames_rejected = 3;
    view.status.fps = 28.44f;
    view.snapshot_seq = 12;
    view.snapshot_triangles = 1234567;
    view.snapshot_age_s = 0.42;
    view.elapsed_s = 5.0;
    return view;
}

bool contains(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

TEST(WatchPanel, GroupsThousands) {
    EXPECT_EQ(groupThousands(0), "0");
    EXPECT_EQ(groupThousands(999), "999");
    EXPECT_EQ(groupThousands(1000), "1,000");
    EXPECT_EQ(groupThousands(1234567), "1,234,567");
}

TEST(WatchPanel, PanelShowsStateFramesFpsTrianglesAndAge) {
    const std::vector<std::string> lines = panelLines(scanningView());
    ASSERT_EQ(lines.size(), 3u);
    EXPECT_TRUE(contains(lines[0], "demo-7"));
    EXPECT_TRUE(contains(lines[0], "SCANNING - face found"));
    EXPECT_TRUE(contains(lines[1], "142 integrated / 151 received"));
    EXPECT_TRUE(contains(lines[1], "28.4 fps"));
    EXPECT_TRUE(contains(lines[2], "1,234,567 triangles"));
    EXPECT_TRUE(contains(lines[2], "snapshot #12, 0.4 s old"));
}

TEST(WatchPanel, LogLineIsOneLineWithTheSameFigures) {
    const std::string line = logLine(scanningView());
    EXPECT_EQ(line.find('\n'), std::string::npos);
    for (const char* part :
         {"demo-7", "SCANNING", "integrated 142/151", "fps 28.4", "triangles 1,234,567", "0.4 s old", "(face found)"}) {
        EXPECT_TRUE(contains(line, part)) << part << " missing from: " << line;
    }
}

// Frames a loaded server tracked but did not fuse are shown apart from the integrated ones, and only
// when there are any.
TEST(WatchPanel, ShowsFramesTrackedButNotFusedApart) {
    WatchView view = scanningView();
    EXPECT_FALSE(contains(panelLines(view)[1], "tracked only"));
    EXPECT_FALSE(contains(logLine(view), "tracked only"));
    view.status.frames_tracked_only = 1234;
    EXPECT_TRUE(contains(panelLines(view)[1], "142 integrated / 151 received"));
    EXPECT_TRUE(contains(panelLines(view)[1], "+ 1,234 tracked only"));
    EXPECT_TRUE(contains(logLine(view), "tracked only 1234"));
}

// The server puts what the person should do first in the detail; panel and log line show it whole.
TEST(WatchPanel, ShowsWhatThePersonShouldDo) {
    WatchView view = scanningView();
    view.status.state = facescan_wire_STATE_LOST;
    view.status.detail = "face lost: hold still (frame rejected: lost: no fit of the head passed verification)";
    EXPECT_TRUE(contains(panelLines(view)[0], "LOST - face lost: hold still (frame rejected"));
    EXPECT_TRUE(contains(logLine(view), "(face lost: hold still (frame rejected"));
    view.status.detail = "turn back toward the camera (face found)";
    EXPECT_TRUE(contains(panelLines(view)[0], "turn back toward the camera"));
}

TEST(WatchPanel, SaysWhenNothingHasArrivedYetAndWhenTheServerIsGone) {
    WatchView waiting;
    waiting.status.session_id = "s1";
    EXPECT_TRUE(contains(panelLines(waiting)[0], "waiting for session s1"));
    EXPECT_TRUE(contains(logLine(waiting), "waiting for session s1"));
    WatchView gone = scanningView();
    gone.snapshot_age_s.reset();
    gone.status.alive = false;
    EXPECT_TRUE(contains(logLine(gone), "server gone"));
    EXPECT_TRUE(contains(logLine(gone), "no snapshot yet"));
}

}  // namespace
}  // namespace facescan::client
