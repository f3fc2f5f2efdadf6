// Which state a server continues a session from when its owner is gone: a pure function of the claim it last saw
// and the copies it holds (as the named standby, and in its own data dir), so the rule can be read and tested alone.
#pragma once

#include <optional>
#include <string>

#include "wire/cluster_codec.hpp"
#include "wire/replica_codec.hpp"

namespace facescan::service {

struct TakeoverChoice {
    enum class Kind {
        kFromCopy,        // continue from `copy` at `epoch`
        kFromFirstFrame,  // no copy anywhere, the agent still keeps every frame (or a live scan): start over
        kWait,            // nothing usable here: another server (or a later view) continues it
        kRefuse,          // a copy says the view is behind or the copy is too old: `why` says which
    };
    Kind kind = Kind::kWait;
    const wire::ReplicaData* copy = nullptr;  // points into the arguments
    uint32_t epoch = 0;                       // the new claim's epoch
    std::string why;                          // kRefuse: one line for the log
};

// The newest copy (epoch, then frames) of the standby's and the data dir's. Refused when:
//   - it belongs to a later epoch than the last claim seen: an owner newer than the one this server saw dead held the
//     session (this server's view lags, as after a pause), so its data is left untouched until the view catches up;
//   - it is older than the frames the agent still keeps (confirmed_seq): frames between them exist nowhere any more.
// Without a copy, a scan starts over from the first frame when the agent still keeps every one, else it waits for a
// server that holds a copy. A live scan (live_scan) never waits for frames it missed, since its agent sends only its
// newest: an older copy still continues it, and without any copy it starts over from the frames that come now.
TakeoverChoice chooseTakeover(const wire::SessionOwnerData& last_claim, const wire::ReplicaData* standby_copy,
                              const wire::ReplicaData* disk_copy, bool live_scan);

}  // namespace facescan::service
