// JSON of the client's outputs (client/status_json.hpp).
#include "client/status_json.hpp"

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

std::string statusJson(const SessionStatus& s, bool with_alive) {
    char numbers[640];
    std::snprintf(numbers, sizeof(numbers),
                  "\"frames_received\":%u,\"frames_integrated\":%u,\"frames_rejected\":%u,\"frames_skipped\":%u,"
                  "\"frames_dropped\":%u,\"every_frame\":%s,\"fps\":%.2f,\"ms\":{\"detect\":%.3f,\"segment\":%.3f,"
                  "\"filter\":%.3f,\"icp\":%.3f,\"integrate\":%.3f,\"raycast\":%.3f,\"mesh\":%.3f},"
                  "\"latency_p95_ms\":%.2f,\"snapshot_seq\":%u",
                  s.frames_received, s.frames_integrated, s.frames_rejected, s.frames_skipped, s.frames_dropped,
                  s.every_frame ? "true" : "false", s.fps, s.ms_detect, s.ms_segment, s.ms_filter, s.ms_icp,
                  s.ms_integrate, s.ms_raycast, s.ms_mesh, s.latency_p95_ms, s.snapshot_seq);
    return "{\"session\":" + jsonString(s.session_id) + ",\"server\":" + jsonString(s.server_id) +
           ",\"state\":" + jsonString(scanStateName(s.state)) + ",\"detail\":" + jsonString(s.detail) + "," + numbers +
           (with_alive ? (s.alive ? ",\"alive\":true}" : ",\"alive\":false}") : "}");
}

}  // namespace facescan::client
