#include "service/placement.hpp"

#include <algorithm>
#include <set>

#include "wire/cluster_codec.hpp"

namespace facescan::service {
namespace {

// a before b: lower load share (open / capacity, compared without division), then the hash, then the id.
bool lessLoaded(const ServerLoad& a, const ServerLoad& b, const std::string& session_id) {
    const int64_t lhs = int64_t{a.open} * std::max(1, b.capacity);
    const int64_t rhs = int64_t{b.open} * std::max(1, a.capacity);
    if (lhs != rhs) return lhs < rhs;
    const uint32_t ha = wire::pairHash(a.server_id, session_id), hb = wire::pairHash(b.server_id, session_id);
    if (ha != hb) return ha > hb;
    return a.server_id < b.server_id;
}

}  // namespace

std::map<std::string, std::string> assignSessions(std::vector<Candidate> candidates, std::vector<ServerLoad> servers) {
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
        return a.order_key != b.order_key ? a.order_key < b.order_key : a.session_id < b.session_id;
    });
    // Room is judged on everything held now (every claim and each session given here); the ranking on what came
    // before the session in the order, so that it does not depend on which later claims this view has seen.
    std::map<std::string, int> held;
    for (const ServerLoad& s : servers) held[s.server_id] = s.open;
    for (const Candidate& c : candidates) {
        if (c.claimed_by.empty()) continue;
        const auto s = std::find_if(servers.begin(), servers.end(),
                                    [&](const ServerLoad& l) { return l.server_id == c.claimed_by; });
        if (s != servers.end()) s->open = std::max(0, s->open - 1);
    }
    std::map<std::string, std::string> out;
    for (const Candidate& c : candidates) {
        if (!c.claimed_by.empty()) {
            for (ServerLoad& s : servers) s.open += s.server_id == c.claimed_by ? 1 : 0;
            continue;
        }
        ServerLoad* best = nullptr;
        for (ServerLoad& s : servers) {
            if (held[s.server_id] >= s.capacity) continue;
            if (!best || lessLoaded(s, *best, c.session_id)) best = &s;
        }
        if (!best) continue;
        ++best->open;
        ++held[best->server_id];
        out[c.session_id] = best->server_id;
    }
    return out;
}

std::map<std::string, std::string> placeSessions(const std::vector<Candidate>& candidates,
                                                 const std::vector<ServerLoad>& servers, int64_t patience_ns) {
    std::map<std::string, std::string> out = assignSessions(candidates, servers);
    std::vector<ServerLoad> left = servers;
    for (int64_t round = 1; round <= static_cast<int64_t>(servers.size()); ++round) {
        std::set<std::string> late;
        for (const Candidate& c : candidates) {
            const auto given = out.find(c.session_id);
            if (c.claimed_by.empty() && given != out.end() && c.overdue_ns >= round * patience_ns) {
                late.insert(given->second);
            }
        }
        if (late.empty()) break;
        std::erase_if(left, [&](const ServerLoad& s) { return late.count(s.server_id) > 0; });
        for (const auto& [session, server] : assignSessions(candidates, left)) out[session] = server;
    }
    return out;
}

std::vector<std::string> claimOrder(const std::string& session_id, const std::vector<ServerLoad>& servers) {
    std::vector<ServerLoad> room;
    for (const ServerLoad& s : servers) {
        if (s.open < s.capacity) room.push_back(s);
    }
    std::sort(room.begin(), room.end(),
              [&](const ServerLoad& a, const ServerLoad& b) { return lessLoaded(a, b, session_id); });
    std::vector<std::string> out;
    for (const ServerLoad& s : room) out.push_back(s.server_id);
    return out;
}

std::string chooseStandby(const std::string& session_id, const std::string& owner_id,
                          const std::vector<ServerLoad>& servers) {
    const ServerLoad* best = nullptr;
    for (const ServerLoad& s : servers) {
        if (s.server_id == owner_id) continue;
        if (!best || s.standby < best->standby || (s.standby == best->standby && lessLoaded(s, *best, session_id))) {
            best = &s;
        }
    }
    return best ? best->server_id : std::string();
}

}  // namespace facescan::service
