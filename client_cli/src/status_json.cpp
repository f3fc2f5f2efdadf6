// JSON of the client's outputs (client/status_json.hpp).
#include "client/status_json.hpp"

#include <cmath>
#include <cstdio>

namespace facescan::client {

std::string jsonString(const std::string& s) {
    std::string out = "\"";
    for (const char c : s) {
        if (c == '"' || c == '\\') {
            out += '\\';
            out += c;
        } else if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof(buf), "\\u%04x", c);
            out += buf;
        } else {
            out += c;
        }
    }
    return out + "\"";
}

namespace {
// JSON has no NaN or infinity: a value a peer sent as such reads as 0.
double finite(float x) { return std::isfinite(x) ? x : 0.0; }
}  // namespace

Ownership ownershipOf(const SessionStatus& s, const std::map<std::string, OwnerInfo>& owners) {
    Ownership o{s.server_id, s.standby_id, s.owner_epoch, s.alive};
    if (const auto it = owners.find(s.session_id); it != owners.end()) {
        o = {it->second.owner_id, it->second.standby_id, it->second.epoch, it->second.alive};
    }
    return o;
}

std::string statusJson(const SessionStatus& s, bool with_alive, const Ownership* owner) {
    const Ownership o = owner ? *owner : Ownership{s.server_id, s.standby_id, s.owner_epoch, s.alive};
    char numbers[768];
    std::snprintf(numbers, sizeof(numbers),
                  "\"frames_received\":%u,\"frames_integrated\":%u,\"frames_rejected\":%u,\"frames_skipped\":%u,"
                  "\"frames_dropped\":%u,\"every_frame\":%s,\"fps\":%.2f,\"ms\":{\"detect\":%.3f,\"segment\":%.3f,"
                  "\"filter\":%.3f,\"icp\":%.3f,\"integrate\":%.3f,\"raycast\":%.3f,\"mesh\":%.3f},"
                  "\"latency_p95_ms\":%.2f,\"snapshot_seq\":%u,\"epoch\":%u,\"owner_alive\":%s,\"failovers\":%u,"
                  "\"last_takeover_ms\":%.1f,\"behind\":%s,\"frames_tracked_only\":%u",
                  s.frames_received, s.frames_integrated, s.frames_rejected, s.frames_skipped, s.frames_dropped,
                  s.every_frame ? "true" : "false", finite(s.fps), finite(s.ms_detect), finite(s.ms_segment),
                  finite(s.ms_filter), finite(s.ms_icp), finite(s.ms_integrate), finite(s.ms_raycast),
                  finite(s.ms_mesh), finite(s.latency_p95_ms), s.snapshot_seq, o.epoch, o.alive ? "true" : "false",
                  s.failovers, finite(s.last_takeover_ms), s.behind ? "true" : "false", s.frames_tracked_only);
    return "{\"session\":" + jsonString(s.session_id) + ",\"server\":" + jsonString(s.server_id) +
           ",\"owner\":" + jsonString(o.owner) + ",\"standby\":" + jsonString(o.standby) +
           ",\"state\":" + jsonString(scanStateName(s.state)) + ",\"detail\":" + jsonString(s.detail) + "," + numbers +
           (with_alive ? (s.alive ? ",\"alive\":true}" : ",\"alive\":false}") : "}");
}

}  // namespace facescan::client
