// Where new sessions go and which server stands by. Pure functions of one server's view of the domain
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
    // The server whose live claim the session holds already, empty when it has none. Such a session keeps its
    // place in the order (and its claim is counted there, not before every other), so a server that has seen the
    // claim and one that has not yet give the sessions around it the same servers.
    std::string claimed_by;
    // How long an unclaimed session has waited past the batching delay, on this server's clock.
    int64_t overdue_ns = 0;
};

// Greedy in candidate order (arrival, then id): each unclaimed session goes to the server with the lowest
// open/capacity among those with room, ties broken by a hash of (server, session) and then the id. A server's
// open count grows with each session given to it, so sessions that arrive together spread out. `servers`' open
// counts include the claims of claimed candidates (as every server's view has them once it has seen them); those
// count from their place in the order. The result holds the unclaimed sessions only; those for which no server
// has room are missing.
std::map<std::string, std::string> assignSessions(std::vector<Candidate> candidates, std::vector<ServerLoad> servers);

// assignSessions, then without the servers that have not claimed what they were given: a server given a session
// that is overdue by `patience_ns` or more is left out, and the sessions are assigned again (greedy, so the
// sessions of a server left out spread over the others as if it had never been there). Round k leaves out those
// overdue by k * patience_ns, so a second choice that does not claim either is passed over in turn. A session
// that only a server left out has room for stays with it.
std::map<std::string, std::string> placeSessions(const std::vector<Candidate>& candidates,
                                                 const std::vector<ServerLoad>& servers, int64_t patience_ns);

// The order in which servers take over `session` when its owner died before any replica: the same ranking,
// without the greedy bookkeeping.
std::vector<std::string> claimOrder(const std::string& session_id, const std::vector<ServerLoad>& servers);

// The owner's choice of standby: another server, the one with the fewest standbys, then the fewest open
// sessions, then the hash. Empty when there is no other server.
std::string chooseStandby(const std::string& session_id, const std::string& owner_id,
                          const std::vector<ServerLoad>& servers);

}  // namespace facescan::service
