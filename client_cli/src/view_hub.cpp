// The viewer's shared state (client/view_hub.hpp).
#include "client/view_hub.hpp"

#include <cstdio>

#include "client/status_json.hpp"

namespace facescan::client {

std::string millisecondsText(int64_t ns) {
    const bool negative = ns < 0;
    const uint64_t magnitude = negative ? 0 - static_cast<uint64_t>(ns) : static_cast<uint64_t>(ns);
    char text[40];
    std::snprintf(text, sizeof(text), "%s%llu.%06llu", negative ? "-" : "",
                  static_cast<unsigned long long>(magnitude / 1'000'000),
                  static_cast<unsigned long long>(magnitude % 1'000'000));
    return text;
}

std::shared_ptr<const FramedSnapshot> frameSnapshot(const MeshSnapshotData& snapshot) {
    auto framed = std::make_shared<FramedSnapshot>();
    framed->session_id = snapshot.session_id;
    framed->seq = snapshot.seq;
    framed->created_ns = snapshot.created_ns;
    char numbers[200];
    std::snprintf(numbers, sizeof(numbers),
                  ",\"seq\":%u,\"frames_integrated\":%u,\"vertex_count\":%u,\"triangle_count\":%u,\"created_ms\":",
                  snapshot.seq, snapshot.frames_integrated, snapshot.vertex_count, snapshot.triangle_count);
    const std::string header =
        "{\"session\":" + jsonString(snapshot.session_id) + numbers + millisecondsText(snapshot.created_ns) + "}";
    const uint32_t n = static_cast<uint32_t>(header.size());
    framed->message.reserve(4 + header.size() + snapshot.draco.size());
    for (int i = 0; i < 4; ++i) framed->message.push_back(static_cast<char>((n >> (8 * i)) & 0xffu));
    framed->message += header;
    framed->draco_offset = framed->message.size();
    framed->message.append(reinterpret_cast<const char*>(snapshot.draco.data()), snapshot.draco.size());
    return framed;
}

namespace {

std::string sessionsMessage(const std::map<std::string, SessionStatus>& statuses) {
    std::string json = "{\"type\":\"sessions\",\"sessions\":[";
    bool first = true;
    for (const auto& [id, status] : statuses) {
        if (!first) json += ',';
        json += statusJson(status, /*with_alive=*/true);
        first = false;
    }
    return json + "]}";
}

}  // namespace

ViewHub::ViewHub() : sessions_json_(std::make_shared<const std::string>(sessionsMessage({}))) {}

void ViewHub::updateStatuses(const std::map<std::string, SessionStatus>& all) {
    std::map<std::string, SessionStatus> statuses = all;
    {
        std::lock_guard lock(mutex_);
        for (const std::string& id : erased_) statuses.erase(id);
    }
    auto json = std::make_shared<const std::string>(sessionsMessage(statuses));
    {
        std::lock_guard lock(mutex_);
        if (*json == *sessions_json_) return;
        statuses_ = std::move(statuses);
        sessions_json_ = std::move(json);
        ++sessions_version_;
    }
    changed_.notify_all();
}

void ViewHub::putSnapshot(std::shared_ptr<const FramedSnapshot> snapshot) {
    if (!snapshot) return;
    {
        std::lock_guard lock(mutex_);
        if (erased_.count(snapshot->session_id)) return;  // a late sample of an erased scan
        Held& held = snapshots_[snapshot->session_id];
        // A reset session starts again at seq 0 with a newer creation time: newer means either.
        if (held.snapshot && snapshot->seq <= held.snapshot->seq && snapshot->created_ns <= held.snapshot->created_ns) {
            return;
        }
        held.snapshot = std::move(snapshot);
        held.version = next_snapshot_version_++;
    }
    changed_.notify_all();
}

bool ViewHub::erase(const std::string& session_id) {
    bool held = false;
    {
        std::lock_guard lock(mutex_);
        erased_.insert(session_id);
        held = statuses_.erase(session_id) + snapshots_.erase(session_id) > 0;
        if (held) {
            sessions_json_ = std::make_shared<const std::string>(sessionsMessage(statuses_));
            ++sessions_version_;
        }
    }
    if (held) changed_.notify_all();
    return held;
}

std::vector<SessionStatus> ViewHub::sessions() const {
    std::lock_guard lock(mutex_);
    std::vector<SessionStatus> out;
    for (const auto& [id, status] : statuses_) out.push_back(status);
    return out;
}

std::optional<SessionStatus> ViewHub::session(const std::string& session_id) const {
    std::lock_guard lock(mutex_);
    const auto it = statuses_.find(session_id);
    if (it == statuses_.end()) return std::nullopt;
    return it->second;
}

std::shared_ptr<const FramedSnapshot> ViewHub::snapshot(const std::string& session_id) const {
    std::lock_guard lock(mutex_);
    const auto it = snapshots_.find(session_id);
    return it == snapshots_.end() ? nullptr : it->second.snapshot;
}

StatusOr<std::vector<uint8_t>> ViewHub::snapshotMesh(const std::string& session_id) const {
    const auto held = snapshot(session_id);
    if (!held) {
        return notFound(session(session_id) ? "session '" + session_id + "' has no snapshot yet"
                                            : "unknown session '" + session_id + "'");
    }
    const std::string_view bytes = held->draco();
    return std::vector<uint8_t>(bytes.begin(), bytes.end());
}

std::shared_ptr<const std::string> ViewHub::sessionsJson() const {
    std::lock_guard lock(mutex_);
    return sessions_json_;
}

void ViewHub::follow(Cursor& cursor, const std::string& session_id) {
    {
        std::lock_guard lock(mutex_);
        cursor.session = session_id;
        cursor.snapshot_version = 0;
    }
    changed_.notify_all();
}

void ViewHub::close(Cursor& cursor) {
    {
        std::lock_guard lock(mutex_);
        cursor.closed = true;
    }
    changed_.notify_all();
}

void ViewHub::closeAll() {
    {
        std::lock_guard lock(mutex_);
        all_closed_ = true;
    }
    changed_.notify_all();
}

bool ViewHub::hasNews(const Cursor& cursor) const {
    if (cursor.closed || all_closed_ || cursor.sessions_version < sessions_version_) return true;
    const auto it = snapshots_.find(cursor.session);
    return it != snapshots_.end() && it->second.version > cursor.snapshot_version;
}

ViewHub::Update ViewHub::next(Cursor& cursor, std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    changed_.wait_for(lock, timeout, [&] { return hasNews(cursor); });
    Update update;
    if (cursor.closed || all_closed_) {
        update.closed = true;
        return update;
    }
    if (cursor.sessions_version < sessions_version_) {
        update.sessions_json = sessions_json_;
        cursor.sessions_version = sessions_version_;
    }
    if (const auto it = snapshots_.find(cursor.session);
        it != snapshots_.end() && it->second.version > cursor.snapshot_version) {
        update.snapshot = it->second.snapshot;
        cursor.snapshot_version = it->second.version;
    }
    return update;
}

}  // namespace facescan::client
