// libFuzzer target: the cluster's public messages as they come out of DDS (ServerAnnounce, SessionOwner: any
// strings, null pointers, any numbers) through their checks (wire/cluster_codec.hpp), and what the servers do
// with the ones that pass: placement of new sessions and the choice of standby (service/placement.hpp).
// Accepted messages must convert back and forth unchanged; placement must never give a server more sessions
// than its capacity or pick a standby that is the owner.
#include <fuzzer/FuzzedDataProvider.h>

#include <cstring>
#include <map>

#include "service/placement.hpp"
#include "wire/cluster_codec.hpp"

namespace {

using namespace facescan;

// A string field as DDS could deliver it: absent (null) or any bytes up to a length.
const char* text(FuzzedDataProvider& in, std::string& keep) {
    if (in.ConsumeBool()) return nullptr;
    keep = in.ConsumeRandomLengthString(300);
    return keep.c_str();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    FuzzedDataProvider in(data, size);
    std::vector<service::ServerLoad> loads;
    std::vector<service::Candidate> candidates;
    std::map<std::string, std::string> owners;
    while (in.remaining_bytes() > 0 && loads.size() < 16) {
        std::string id, host, software, session, owner, standby;
        if (in.ConsumeBool()) {
            facescan_wire_ServerAnnounce m{};
            m.server_id = const_cast<char*>(text(in, id));
            m.host = const_cast<char*>(text(in, host));
            m.software = const_cast<char*>(text(in, software));
            m.pid = in.ConsumeIntegral<uint32_t>();
            m.protocol_version = in.ConsumeIntegral<uint32_t>();
            m.incarnation = in.ConsumeIntegral<uint64_t>();
            m.started_ns = in.ConsumeIntegral<int64_t>();
            m.max_sessions = in.ConsumeIntegral<uint32_t>();
            m.open_sessions = in.ConsumeIntegral<uint32_t>();
            m.standby_sessions = in.ConsumeIntegral<uint32_t>();
            m.cpu_load = in.ConsumeFloatingPoint<float>();
            m.joining = in.ConsumeBool();
            auto a = wire::fromMessage(m);
            if (!a.isOk()) continue;
            auto back = wire::fromMessage(wire::toMessage(*a));
            if (!back.isOk() || back->server_id != a->server_id || back->max_sessions != a->max_sessions) {
                __builtin_trap();
            }
            // One entry per server, the latest announcement (as Cluster::liveLoads keeps them).
            std::erase_if(loads, [&](const service::ServerLoad& l) { return l.server_id == a->server_id; });
            loads.push_back({a->server_id, static_cast<int>(a->max_sessions), static_cast<int>(a->open_sessions),
                             static_cast<int>(a->standby_sessions)});
        } else {
            facescan_wire_SessionOwner m{};
            m.session_id = const_cast<char*>(text(in, session));
            m.owner_id = const_cast<char*>(text(in, owner));
            m.standby_id = const_cast<char*>(text(in, standby));
            m.epoch = in.ConsumeIntegral<uint32_t>();
            const uint32_t state = in.ConsumeIntegral<uint32_t>();  // any 32 bits, as they could arrive
            std::memcpy(&m.state, &state, sizeof(state));
            m.resume_seq = in.ConsumeIntegral<uint32_t>();
            m.replay_request = in.ConsumeIntegral<uint32_t>();
            m.confirmed_seq = in.ConsumeIntegral<uint32_t>();
            m.failovers = in.ConsumeIntegral<uint32_t>();
            m.last_takeover_ms = in.ConsumeFloatingPoint<float>();
            auto o = wire::fromMessage(m);
            if (!o.isOk()) continue;
            auto back = wire::fromMessage(wire::toMessage(*o));
            if (!back.isOk() || back->owner_id != o->owner_id || back->epoch != o->epoch) __builtin_trap();
            candidates.push_back({o->session_id, in.ConsumeIntegral<int64_t>(), std::string(), 0});
            owners[o->session_id] = o->owner_id;
        }
    }
    const auto assigned = service::assignSessions(candidates, loads);
    std::map<std::string, int> given;
    for (const auto& [session, server] : assigned) ++given[server];
    for (const service::ServerLoad& l : loads) {
        if (given[l.server_id] > 0 && l.open + given[l.server_id] > std::max(l.capacity, l.open)) __builtin_trap();
    }
    for (const auto& [session, owner] : owners) {
        if (service::chooseStandby(session, owner, loads) == owner && !owner.empty()) __builtin_trap();
        (void)service::claimOrder(session, loads);
    }
    return 0;
}
