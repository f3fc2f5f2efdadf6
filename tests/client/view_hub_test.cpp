// The viewer's shared state without a network: the snapshot frame, exact milliseconds, latest-wins cursors,
// late and reset snapshots, and sessions JSON that stays valid whatever numbers a peer sends.
#include "client/view_hub.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <thread>

namespace facescan::client {
namespace {

using namespace std::chrono_literals;

MeshSnapshotData snap(const std::string& session, uint32_t seq, int64_t created_ns,
                      std::vector<uint8_t> draco = {1, 2}) {
    MeshSnapshotData s;
    s.session_id = session;
    s.seq = seq;
    s.created_ns = created_ns;
    s.draco = std::move(draco);
    return s;
}

TEST(ViewHub, FrameIsLengthHeaderThenTheBytesAsTheyAre) {
    const auto framed = frameSnapshot(snap("a", 3, 1'700'000'000'123'456'789, {9, 8, 7}));
    const std::string& m = framed->message;
    const uint32_t n = uint8_t(m[0]) | uint8_t(m[1]) << 8 | uint8_t(m[2]) << 16 | uint32_t(uint8_t(m[3])) << 24;
    EXPECT_EQ(m.substr(4, n),
              "{\"session\":\"a\",\"seq\":3,\"frames_integrated\":0,\"vertex_count\":0,\"triangle_count\":0,"
              "\"created_ms\":1700000000123.456789}");
    EXPECT_EQ(framed->draco(), std::string("\x09\x08\x07"));
    EXPECT_EQ(millisecondsText(-1'500'000), "-1.500000");
    EXPECT_EQ(millisecondsText(0), "0.000000");
}

TEST(ViewHub, ACursorGetsTheLatestOnlyAndNothingOlder) {
    ViewHub hub;
    ViewHub::Cursor cursor;
    auto first = hub.next(cursor, 0ms);  // the (empty) sessions list, once
    ASSERT_TRUE(first.sessions_json);
    EXPECT_EQ(*first.sessions_json, "{\"type\":\"sessions\",\"sessions\":[]}");
    EXPECT_FALSE(hub.next(cursor, 0ms).sessions_json);

    hub.follow(cursor, "a");
    for (uint32_t seq = 1; seq <= 5; ++seq) hub.putSnapshot(frameSnapshot(snap("a", seq, 1000 + seq)));
    hub.putSnapshot(frameSnapshot(snap("b", 9, 5000)));  // another session's
    hub.putSnapshot(frameSnapshot(snap("a", 2, 1002)));  // a late, older sample
    const auto update = hub.next(cursor, 0ms);
    ASSERT_TRUE(update.snapshot);
    EXPECT_EQ(update.snapshot->seq, 5u) << "a slow browser skips to the newest";
    EXPECT_FALSE(hub.next(cursor, 10ms).snapshot) << "nothing newer";

    // A reset session starts at seq 0 again, created later: that is newer.
    hub.putSnapshot(frameSnapshot(snap("a", 0, 9000)));
    const auto reset = hub.next(cursor, 0ms);
    ASSERT_TRUE(reset.snapshot);
    EXPECT_EQ(reset.snapshot->seq, 0u);

    // Following another session sends its latest at once.
    hub.follow(cursor, "b");
    EXPECT_EQ(hub.next(cursor, 0ms).snapshot->seq, 9u);
}

TEST(ViewHub, NextWakesOnNewsAndEndsOnClose) {
    ViewHub hub;
    ViewHub::Cursor cursor;
    hub.next(cursor, 0ms);
    hub.follow(cursor, "a");
    std::thread feeder([&] {
        std::this_thread::sleep_for(50ms);
        hub.putSnapshot(frameSnapshot(snap("a", 1, 1)));
    });
    const auto t0 = std::chrono::steady_clock::now();
    const auto update = hub.next(cursor, 5s);
    feeder.join();
    EXPECT_TRUE(update.snapshot);
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 2s);
    std::thread closer([&] {
        std::this_thread::sleep_for(50ms);
        hub.close(cursor);
    });
    EXPECT_TRUE(hub.next(cursor, 5s).closed);
    closer.join();
}

TEST(ViewHub, SessionsJsonChangesOnlyWithThePictureAndStaysValid) {
    ViewHub hub;
    ViewHub::Cursor cursor;
    hub.next(cursor, 0ms);
    SessionStatus s;
    s.session_id = "a";
    s.server_id = "srv \"1\"";
    s.detail = "move closer\n";
    s.fps = std::nanf("");
    s.ms_icp = INFINITY;
    hub.updateStatuses({{"a", s}});
    const auto update = hub.next(cursor, 0ms);
    ASSERT_TRUE(update.sessions_json);
    const std::string& json = *update.sessions_json;
    EXPECT_NE(json.find("\"server\":\"srv \\\"1\\\"\""), std::string::npos) << json;
    EXPECT_NE(json.find("\"detail\":\"move closer\\u000a\""), std::string::npos) << json;
    EXPECT_NE(json.find("\"fps\":0.00"), std::string::npos) << json;
    EXPECT_EQ(json.find("nan"), std::string::npos) << json;
    EXPECT_EQ(json.find("inf"), std::string::npos) << json;
    hub.updateStatuses({{"a", s}});  // the same picture: nothing to send
    EXPECT_FALSE(hub.next(cursor, 0ms).sessions_json);
    ASSERT_TRUE(hub.session("a"));
    EXPECT_FALSE(hub.session("b"));

    // A read-only viewer's download: the latest snapshot's bytes, or why there is none.
    EXPECT_EQ(hub.snapshotMesh("a").status().message(), "session 'a' has no snapshot yet");
    EXPECT_EQ(hub.snapshotMesh("zz").status().message(), "unknown session 'zz'");
    hub.putSnapshot(frameSnapshot(snap("a", 4, 10, {5, 6, 7})));
    ASSERT_TRUE(hub.snapshotMesh("a").isOk());
    EXPECT_EQ(*hub.snapshotMesh("a"), (std::vector<uint8_t>{5, 6, 7}));
}

// facescan delete: an erased scan leaves the hub's memory and every page (a sessions message without it), and
// what still arrives of it (a late snapshot, a status from the map the DDS side keeps) is dropped.
TEST(ViewHub, AnErasedScanLeavesMemoryAndThePagesAndStaysGone) {
    ViewHub hub;
    SessionStatus a, b;
    a.session_id = "a";
    b.session_id = "b";
    hub.updateStatuses({{"a", a}, {"b", b}});
    hub.putSnapshot(frameSnapshot(snap("a", 1, 10, {5, 6})));
    hub.putSnapshot(frameSnapshot(snap("b", 1, 10)));
    ViewHub::Cursor cursor;
    hub.follow(cursor, "a");
    const auto before = hub.next(cursor, 0ms);
    ASSERT_TRUE(before.sessions_json && before.snapshot);
    ASSERT_NE(before.sessions_json->find("\"session\":\"a\""), std::string::npos);

    EXPECT_TRUE(hub.erase("a"));
    const auto after = hub.next(cursor, 0ms);
    ASSERT_TRUE(after.sessions_json) << "the pages are told at once";
    EXPECT_EQ(after.sessions_json->find("\"session\":\"a\""), std::string::npos) << *after.sessions_json;
    EXPECT_NE(after.sessions_json->find("\"session\":\"b\""), std::string::npos) << *after.sessions_json;
    EXPECT_FALSE(after.snapshot);
    EXPECT_FALSE(hub.session("a"));
    EXPECT_FALSE(hub.snapshot("a"));
    EXPECT_EQ(hub.snapshotMesh("a").status().code(), StatusCode::kNotFound);
    EXPECT_TRUE(hub.snapshot("b")) << "other scans stay";

    // Late arrivals of the erased scan are dropped; erasing again holds nothing.
    hub.putSnapshot(frameSnapshot(snap("a", 2, 20)));
    hub.updateStatuses({{"a", a}, {"b", b}});
    EXPECT_FALSE(hub.snapshot("a"));
    EXPECT_FALSE(hub.session("a"));
    EXPECT_EQ(hub.sessionsJson()->find("\"session\":\"a\""), std::string::npos);
    EXPECT_FALSE(hub.erase("a"));
}

}  // namespace
}  // namespace facescan::client
