// Conversions of the cluster's messages, and the id rules shared with messages.cpp. No DDS calls here (only the
// generated types), so the fuzzers compile it without the transport.
#include "wire/cluster_codec.hpp"

#include <cmath>
#include <cstring>

#include "wire/messages.hpp"

namespace facescan::wire {
namespace {

constexpr size_t kMaxHostChars = 255;
constexpr size_t kMaxSoftwareChars = 64;
constexpr uint32_t kMaxSessions = 1024;  // an announced capacity above this is not believed

// Ids become DDS keys, partition names and file names.
Status validateId(const char* what, const std::string& id) {
    if (id.empty() || id.size() > 64) {
        return invalidArgument(std::string(what) + " must be 1-64 characters, got " + std::to_string(id.size()));
    }
    if (id == "." || id == "..") return invalidArgument(std::string(what) + " may not be '.' or '..'");
    for (const char c : id) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' ||
                        c == '_' || c == '.';
        if (!ok)
            return invalidArgument(std::string(what) + " '" + id + "' may only use letters, digits, '.', '-', '_'");
    }
    return Status::ok();
}

}  // namespace

Status validateSessionId(const std::string& session_id) { return validateId("session id", session_id); }
Status validateServerId(const std::string& server_id) { return validateId("server id", server_id); }

facescan_wire_ServerAnnounce toMessage(const ServerAnnounceData& a) {
    facescan_wire_ServerAnnounce m{};
    m.server_id = stringView(a.server_id);
    m.host = stringView(a.host);
    m.pid = a.pid;
    m.protocol_version = a.protocol_version;
    m.incarnation = a.incarnation;
    m.started_ns = a.started_ns;
    m.max_sessions = a.max_sessions;
    m.open_sessions = a.open_sessions;
    m.standby_sessions = a.standby_sessions;
    m.cpu_load = a.cpu_load;
    m.joining = a.joining;
    m.software = stringView(a.software);
    return m;
}

StatusOr<ServerAnnounceData> fromMessage(const facescan_wire_ServerAnnounce& m) {
    ServerAnnounceData a;
    a.server_id = fromDds(m.server_id);
    RETURN_IF_ERROR(validateServerId(a.server_id));
    a.host = fromDds(m.host);
    a.software = fromDds(m.software);
    if (a.host.size() > kMaxHostChars || a.software.size() > kMaxSoftwareChars) {
        return invalidArgument("announcement of '" + a.server_id + "': host or software name too long");
    }
    if (m.max_sessions > kMaxSessions || m.open_sessions > kMaxSessions || m.standby_sessions > kMaxSessions * 64) {
        return invalidArgument("announcement of '" + a.server_id + "': implausible session counts");
    }
    if (!std::isfinite(m.cpu_load) || m.cpu_load < 0 || m.cpu_load > 4096) {
        return invalidArgument("announcement of '" + a.server_id + "': implausible load");
    }
    a.pid = m.pid;
    a.protocol_version = m.protocol_version;
    a.incarnation = m.incarnation;
    a.started_ns = m.started_ns;
    a.max_sessions = m.max_sessions;
    a.open_sessions = m.open_sessions;
    a.standby_sessions = m.standby_sessions;
    a.cpu_load = m.cpu_load;
    a.joining = m.joining;
    return a;
}

static_assert(static_cast<int>(OwnerState::kReady) == facescan_wire_OWNER_READY &&
              static_cast<int>(OwnerState::kReleased) == facescan_wire_OWNER_RELEASED);

const char* ownerStateName(OwnerState state) {
    switch (state) {
        case OwnerState::kClaiming: return "claiming";
        case OwnerState::kReady: return "ready";
        case OwnerState::kActive: return "active";
        case OwnerState::kFinished: return "finished";
        case OwnerState::kReleased: return "released";
    }
    return "?";
}

facescan_wire_SessionOwner toMessage(const SessionOwnerData& o) {
    facescan_wire_SessionOwner m{};
    m.session_id = stringView(o.session_id);
    m.owner_id = stringView(o.owner_id);
    m.standby_id = stringView(o.standby_id);
    m.epoch = o.epoch;
    m.state = static_cast<facescan_wire_OwnerState>(o.state);
    m.resume_seq = o.resume_seq;
    m.replay_request = o.replay_request;
    m.confirmed_seq = o.confirmed_seq;
    m.failovers = o.failovers;
    m.last_takeover_ms = o.last_takeover_ms;
    m.updated_ns = o.updated_ns;
    m.owner_incarnation = o.owner_incarnation;
    return m;
}

StatusOr<SessionOwnerData> fromMessage(const facescan_wire_SessionOwner& m) {
    SessionOwnerData o;
    o.session_id = fromDds(m.session_id);
    RETURN_IF_ERROR(validateSessionId(o.session_id));
    o.owner_id = fromDds(m.owner_id);
    RETURN_IF_ERROR(validateServerId(o.owner_id));
    o.standby_id = fromDds(m.standby_id);
    if (!o.standby_id.empty()) RETURN_IF_ERROR(validateServerId(o.standby_id));
    if (m.epoch == 0 || m.epoch > 0x7fff) return invalidArgument("owner of '" + o.session_id + "': bad epoch");
    // Read as the 32 bits that arrived: a value outside the enum must be refused, not loaded as the enum type.
    uint32_t state = 0;
    static_assert(sizeof(state) == sizeof(m.state));
    std::memcpy(&state, &m.state, sizeof(state));
    if (state > static_cast<uint32_t>(facescan_wire_OWNER_RELEASED)) {
        return invalidArgument("owner of '" + o.session_id + "': unknown state " + std::to_string(state));
    }
    if (!std::isfinite(m.last_takeover_ms) || m.last_takeover_ms < 0) {
        return invalidArgument("owner of '" + o.session_id + "': bad takeover time");
    }
    o.epoch = m.epoch;
    o.state = static_cast<OwnerState>(state);
    o.resume_seq = m.resume_seq;
    o.replay_request = m.replay_request;
    o.confirmed_seq = m.confirmed_seq;
    o.failovers = m.failovers;
    o.last_takeover_ms = m.last_takeover_ms;
    o.updated_ns = m.updated_ns;
    o.owner_incarnation = m.owner_incarnation;
    return o;
}

uint32_t pairHash(const std::string& server_id, const std::string& session_id) {
    uint32_t h = 2166136261u;
    auto mix = [&](const std::string& s) {
        for (const char c : s) h = (h ^ static_cast<uint8_t>(c)) * 16777619u;
        h = (h ^ 0x2fu) * 16777619u;  // separator: ("ab","c") and ("a","bc") differ
    };
    mix(server_id);
    mix(session_id);
    return h ^ (h >> 16);
}

int32_t claimStrength(uint32_t epoch, const std::string& server_id, const std::string& session_id) {
    return static_cast<int32_t>((std::min<uint32_t>(epoch, 0x7fff) << 16) | (pairHash(server_id, session_id) & 0xffff));
}

}  // namespace facescan::wire
