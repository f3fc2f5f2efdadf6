// JSON of the client's outputs (`sessions --json`, `status --json`, and the web viewer's API), written in one place.
#pragma once

#include <string>

#include "client/scan_client.hpp"

namespace facescan::client {

// A JSON string literal with quotes, backslashes and control characters escaped.
std::string jsonString(const std::string& s);
// One session as a JSON object: session, server, state, detail, frame counts, fps, per-stage ms, latency, snapshot;
// with `alive` (whether its server lives) when `with_alive`.
std::string statusJson(const SessionStatus& s, bool with_alive = false);

}  // namespace facescan::client
