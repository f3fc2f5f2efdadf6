#include "service/takeover.hpp"

namespace facescan::service {

TakeoverChoice chooseTakeover(const wire::SessionOwnerData& last_claim, const wire::ReplicaData* standby_copy,
                              const wire::ReplicaData* disk_copy, bool live_scan) {
    TakeoverChoice c;
    const wire::ReplicaData* copy = standby_copy;
    if (disk_copy && (!copy || disk_copy->epoch > copy->epoch ||
                      (disk_copy->epoch == copy->epoch && disk_copy->next_seq > copy->next_seq))) {
        copy = disk_copy;
    }
    if (!copy) {
        c.kind = last_claim.confirmed_seq == 0 || live_scan ? TakeoverChoice::Kind::kFromFirstFrame
                                                            : TakeoverChoice::Kind::kWait;
        c.epoch = last_claim.epoch + 1;
        return c;
    }
    const std::string& id = last_claim.session_id;
    if (copy->epoch > last_claim.epoch) {
        c.kind = TakeoverChoice::Kind::kRefuse;
        c.why = "session " + id + ": the replica " + (copy == disk_copy ? "in the data dir" : "held as standby") +
                " belongs to epoch " + std::to_string(copy->epoch) + ", later than the last claim seen (server '" +
                last_claim.owner_id + "', epoch " + std::to_string(last_claim.epoch) +
                "): this server's view is behind; it leaves that data untouched and takes nothing over until it "
                "sees the newer owner";
        return c;
    }
    if (copy->next_seq < last_claim.confirmed_seq && !live_scan) {
        c.kind = TakeoverChoice::Kind::kRefuse;
        c.why = "session " + id + ": this server's replica (frame " + std::to_string(copy->next_seq) +
                ") is older than what the agent still keeps (from frame " + std::to_string(last_claim.confirmed_seq) +
                "): not taking it over";
        return c;
    }
    c.kind = TakeoverChoice::Kind::kFromCopy;
    c.copy = copy;
    c.epoch = last_claim.epoch + 1;
    return c;
}

}  // namespace facescan::service
