// What `facescan view` shows, between its one DDS subscriber (view_command.cpp) and every browser (view_server.cpp):
// the latest ScanStatus of each session and each session's latest MeshSnapshot, already framed as the message a
// browser receives. A snapshot is framed once however many browsers watch; each browser's sender waits here for
// what is newer than what it has sent, so a slow browser skips to the latest and never holds up the others.
// No DDS, no HTTP.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "client/scan_client.hpp"

namespace facescan::client {

// One MeshSnapshot as the browsers get it: a binary WebSocket message
//   [u32 little-endian header length][header: JSON, UTF-8][the Draco bytes of MeshSnapshot.draco, as received]
// The header: {"session","seq","frames_integrated","vertex_count","triangle_count","created_ms"}; created_ms is
// the server's CLOCK_REALTIME in milliseconds (a double: exact to well under a microsecond).
struct FramedSnapshot {
    std::string session_id;
    uint32_t seq = 0;
    int64_t created_ns = 0;
    std::string message;      // the whole WebSocket message
    size_t draco_offset = 0;  // where the Draco bytes start in `message`

    std::string_view draco() const { return std::string_view(message).substr(draco_offset); }
};
std::shared_ptr<const FramedSnapshot> frameSnapshot(const MeshSnapshotData& snapshot);
// Nanoseconds as milliseconds with six decimals, exactly ("1700000000002.000000"): a double of 1.7e18 ns would not be.
std::string millisecondsText(int64_t ns);

class ViewHub {
 public:
    // What one browser has been sent. Owned by the caller, read and written only inside the hub (under its lock).
    struct Cursor {
        std::string session;            // the session whose snapshots it wants ("" = none)
        uint64_t sessions_version = 0;  // the sessions list it has
        uint64_t snapshot_version = 0;  // the snapshot of `session` it has
        bool closed = false;
    };
    // What is newer than a cursor; empty members are unchanged.
    struct Update {
        std::shared_ptr<const std::string> sessions_json;
        std::shared_ptr<const FramedSnapshot> snapshot;
        bool closed = false;
    };

    ViewHub();

    // The DDS side. `statuses` is the whole picture (ScanClient::poll's map); the sessions message changes only
    // when the picture does. A snapshot older than the one held (a late sample) is ignored.
    void updateStatuses(const std::map<std::string, SessionStatus>& statuses);
    void putSnapshot(std::shared_ptr<const FramedSnapshot> snapshot);
    // The scan was erased on the domain (`facescan delete`): its status and meshes leave memory and every page
    // (the sessions message goes out without it), and what still arrives of it is dropped. True when it was held.
    bool erase(const std::string& session_id);

    // The web side.
    std::vector<SessionStatus> sessions() const;
    std::optional<SessionStatus> session(const std::string& session_id) const;
    std::shared_ptr<const FramedSnapshot> snapshot(const std::string& session_id) const;
    // The latest snapshot's Draco bytes as a mesh download (the final mesh once a scan is finished: its server
    // publishes it as the last snapshot), for a viewer that may not send commands. NotFound when there is none.
    StatusOr<std::vector<uint8_t>> snapshotMesh(const std::string& session_id) const;
    // {"type":"sessions","sessions":[...]}: every session's status JSON (client/status_json.hpp) with "alive".
    std::shared_ptr<const std::string> sessionsJson() const;

    // Subscribes `cursor` to a session's snapshots (its latest is then sent at once).
    void follow(Cursor& cursor, const std::string& session_id);
    // Ends a cursor's waits for good (the browser went away, or the viewer stops).
    void close(Cursor& cursor);
    void closeAll();
    // Blocks until something is newer than `cursor`, it is closed, or `timeout` passes; advances the cursor.
    Update next(Cursor& cursor, std::chrono::milliseconds timeout);

 private:
    bool hasNews(const Cursor& cursor) const;  // under mutex_

    mutable std::mutex mutex_;
    std::condition_variable changed_;
    std::map<std::string, SessionStatus> statuses_;
    std::shared_ptr<const std::string> sessions_json_;
    uint64_t sessions_version_ = 1;
    struct Held {
        std::shared_ptr<const FramedSnapshot> snapshot;
        uint64_t version = 0;
    };
    std::map<std::string, Held> snapshots_;
    uint64_t next_snapshot_version_ = 1;
    bool all_closed_ = false;
    std::set<std::string> erased_;  // never shown again
};

}  // namespace facescan::client
