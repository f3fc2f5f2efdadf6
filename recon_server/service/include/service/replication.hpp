// Replication of the sessions a server owns, on its own thread:
//   owner side    every --replica-interval-s, each owned session's worker captures its state between two frames
//                 (the blocks changed since the last round, or all of them), the round is encoded
//                 (wire/replica_codec.hpp), appended to the session's folder in the data dir (replica_log.hpp)
//                 and sent to the session's standby, in the standby's DDS partition. The standby's
//                 acknowledgement (or the disk, with no standby) moves the claim's confirmed_seq: the agent may then
//                 drop the frames before it.
//   standby side  replicas for this server are decoded, checked and merged into a full copy per session; each is
//                 acknowledged, and a corrupt, truncated, out-of-order or foreign one is refused with a request
//                 for a full replica. The server takes a session over from this copy when its owner dies.
#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "service/cluster.hpp"
#include "service/replica_log.hpp"
#include "service/server_params.hpp"
#include "service/session.hpp"
#include "wire/replica_codec.hpp"
#include "wire/topics.hpp"

namespace facescan::service {

struct OwnedSession;

// What the replication of this server costs and carries (the bench reads it from the log lines).
struct ReplicationStats {
    uint64_t rounds = 0;
    uint64_t full_rounds = 0;
    uint64_t bytes_sent = 0;     // replica bytes written to standbys
    uint64_t bytes_on_disk = 0;  // replica bytes appended to the data dir
    double capture_ms = 0;       // total: worker time taking the state
    double encode_ms = 0;        // total: encoding and compressing
    double disk_ms = 0;          // total: appending and syncing
    uint64_t rejected = 0;       // replicas received and refused (corrupt, out of order, incompatible)
};

class Replicator {
 public:
    using OwnedList = std::function<std::vector<std::shared_ptr<OwnedSession>>()>;
    static StatusOr<std::unique_ptr<Replicator>> create(const wire::Participant& participant,
                                                        const ServerParams& params, Cluster& cluster, OwnedList owned);
    ~Replicator();  // stop()

    void start();
    void stop();
    // Takes replicas and acknowledgements that arrived: the server calls it while it joins, before start(). Once
    // started, the receiving thread alone takes replicas and the replication thread alone acknowledgements.
    void poll();

    // The standby's full copy of a session (nullopt when this server holds none).
    std::optional<wire::ReplicaData> standbyCopy(const std::string& session_id) const;
    int standbyCount() const;
    size_t standbyBytes() const;  // what the copies' volumes and keyframes hold
    // Steady clock of the last replica received from `server_id` (0: none).
    int64_t lastHeardFrom(const std::string& server_id) const;
    ReplicationStats stats() const;

 private:
    struct Outgoing;  // per owned session: rounds, standby, acknowledgements, the data dir's log
    struct Incoming {
        wire::ReplicaData copy;  // full
        int64_t received_ns = 0;
    };
    Replicator(const ServerParams& params, Cluster& cluster, OwnedList owned);
    void loop();
    void receiveLoop();  // takes the replicas that come in, on a thread of its own
    void takeReplicas();
    void takeAcks();
    void replicate(OwnedSession& owned, Outgoing& out);
    // The frames the agent may drop now: what the data dir and the standby both hold, or the data dir alone.
    uint32_t confirmable(const Outgoing& out) const;
    void ack(const std::string& session_id, const std::string& owner_id, uint32_t epoch, uint32_t round, bool need_full,
             const std::string& error);
    void forgetStaleCopies();
    // FACESCAN_FAILPOINT=replication-stall-when-file:PATH (failpoint.hpp): the replication thread stops in a round,
    // its state captured, while PATH exists, as a round does whose encoding takes long on a loaded machine.
    void failpoint();
    wire::Writer<facescan_wire_SessionReplica>* replicaWriter(const std::string& standby_id);
    wire::Writer<facescan_wire_ReplicaAck>* ackWriter(const std::string& owner_id);

    const ServerParams params_;
    Cluster& cluster_;
    OwnedList owned_;
    std::optional<wire::Topic<facescan_wire_SessionReplica>> replica_topic_;
    std::optional<wire::Topic<facescan_wire_ReplicaAck>> ack_topic_;
    std::optional<wire::Reader<facescan_wire_SessionReplica>> replica_reader_;  // our partition
    std::optional<wire::Reader<facescan_wire_ReplicaAck>> ack_reader_;          // our partition
    // One writer per peer, in that peer's partition: replicas from the replication thread, acknowledgements from
    // the receiving thread.
    std::map<std::string, std::unique_ptr<wire::Writer<facescan_wire_SessionReplica>>> replica_writers_;
    std::map<std::string, std::unique_ptr<wire::Writer<facescan_wire_ReplicaAck>>> ack_writers_;
    std::map<std::string, std::unique_ptr<Outgoing>> outgoing_;  // by session id (replication thread only)
    // Replication thread only: what one round captures and encodes, megabytes, kept from round to round so that
    // no round writes into fresh pages (wire::ReplicaEncoder).
    wire::ReplicaEncoder encoder_{params_.replica_zstd_level};
    ReplicaCapture spare_capture_;
    std::vector<uint8_t> bytes_;

    mutable std::mutex mutex_;  // guards incoming_, heard_, stats_
    std::map<std::string, Incoming> incoming_;
    std::map<std::string, int64_t> heard_;
    std::map<std::string, int64_t> incompatible_logged_;
    ReplicationStats stats_;

    std::string stall_file_;  // the failpoint's file (empty: none)

    std::atomic<bool> running_{false};
    std::thread thread_;
    std::thread receive_thread_;
};

}  // namespace facescan::service
