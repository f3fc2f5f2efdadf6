// Where new sessions go and which server stands by (issue 13). Pure functions of one server's view of the domain
// (announcements and claims): every server computes the same answer from the same view, so placement needs no
// protocol of its own. When views differ for a moment (two servers claim the same session), DDS settles it:
// claims are written with EXCLUSIVE ownership, and every reader sees the same, strongest one.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace facescan::service {

struct ServerLoad {
    std::string server_id;
    int capacity = 0;  // --max-sessions
    int open = 0;      // sessions it owns and has not finished (claims included)
    int standby = 0;   // sessions it holds a replica of
};

struct Candidate {
    std::string session_id;
    int64_t order_key = 0;  // arrival: the CameraInfo's source timestamp (the same on every server)
};

// Greedy in candidate order (arrival, then id): each session goes to the server with the lowest open/capacity
// among those with room, ties broken by a hash of (server, session) and then the id. A server's open count grows
// with each session given to it, so sessions that arrive together spread out. Sessions for which no server has
// room are missing from the result.
std::map<std::string, std::string> assignSessions(std::vector<Candidate> candidates, std::vector<ServerLoad> servers);

// The order in which servers claim `session` when the first choice does not (it died, or it is full): the same
// ranking, without the greedy bookkeeping.
std::vector<std::string> claimOrder(const std::string& session_id, const std::vector<ServerLoad>& servers);

// The owner's choice of standby: another server, the one with the fewest standbys, then the fewest open
// sessions, then the hash. Empty when there is no other server.
std::string chooseStandby(const std::string& session_id, const std::string& owner_id,
                          const std::vector<ServerLoad>& servers);

}  // namespace facescan::service
