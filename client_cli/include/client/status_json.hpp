// JSON of the client's outputs (`sessions --json`, `status --json`, and the web viewer's API), written in one place.
#pragma once

#include <map>
#include <string>

#include "client/scan_client.hpp"

namespace facescan::client {

// A JSON string literal with quotes, backslashes and control characters escaped.
std::string jsonString(const std::string& s);

// Who owns a session: the claims on facescan/SessionOwner, which every server, agent and client follow.
struct Ownership {
    std::string owner, standby;
    uint32_t epoch = 0;
    bool alive = true;  // false: its owner died and nobody took it over yet
};
// From the claims when `owners` has the session, else from the status itself (its server, standby, epoch).
Ownership ownershipOf(const SessionStatus& s, const std::map<std::string, OwnerInfo>& owners);

// One session as a JSON object: session, server, owner, standby, epoch, failovers, last takeover ms, state, detail,
// frame counts, fps, per-stage ms, latency, snapshot; with `alive` (whether its server lives) when `with_alive`.
// `owner`: the claims' view (ownershipOf); null = what the status says.
std::string statusJson(const SessionStatus& s, bool with_alive = false, const Ownership* owner = nullptr);

}  // namespace facescan::client
