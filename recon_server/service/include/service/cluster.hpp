// One server's membership in the cluster (docs/design.md section 8), over DDS only:
//   - it announces itself on facescan/ServerAnnounce (durable, ~2 Hz and on every change); a killed server's
//     instance loses its liveliness within the profile's lease, so everybody sees who is alive;
//   - it follows facescan/SessionOwner, where each session's owner holds a claim written with EXCLUSIVE
//     ownership (Claim): readers only see the strongest live claim of every session, so all of them agree on the
//     owner, and a dead owner's claim lapses with its liveliness (instance NOT_ALIVE_NO_WRITERS);
//   - it refuses to run beside another live server with its --server-id.
// The view is thread-safe: the intake thread polls it, the replication and status threads read it.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "service/placement.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/topics.hpp"

namespace facescan::service {

// The last claim seen for a session, and whether a live writer still holds it.
// A claim in one of these states holds its session (an owner is scanning it, or about to).
inline bool holdsSession(wire::OwnerState s) {
    return s == wire::OwnerState::kClaiming || s == wire::OwnerState::kReady || s == wire::OwnerState::kActive;
}

struct OwnerView {
    wire::SessionOwnerData data;
    bool alive = false;     // a live server holds the claim (false: its owner died, or released it)
    bool disposed = false;  // the owner withdrew the claim on purpose
    int64_t seen_ns = 0;    // steady clock when it last changed
};

struct PeerView {
    wire::ServerAnnounceData announce;
    bool alive = false;
    int64_t seen_ns = 0;                // steady clock of the last change (an announcement, or its liveliness lapsing)
    int64_t heard_ns = 0;               // steady clock of the last announcement
    int64_t incarnation_since_ns = 0;   // steady clock of the first announcement of its current incarnation
    uint64_t previous_incarnation = 0;  // the process of this id before (a restart), and when it was last heard
    int64_t previous_heard_ns = 0;
};

// A claim on one session: its own DDS writer, whose ownership strength grows with the epoch. Writing the record
// (any thread) publishes the owner's current state; destroying the Claim withdraws it without disposing (other
// readers see NOT_ALIVE_NO_WRITERS, as if this server had died) unless release() disposed it first.
class Claim {
 public:
    // `progressing`, when set, says whether the server's work makes progress: a write renews the claim's liveliness
    // (MANUAL_BY_TOPIC, wire::withClaimLiveliness), so a claim's change made by another thread (replication's
    // confirmed frames, the status's counters) while the intake is stuck waits unpublished instead of keeping a
    // stuck server's sessions alive.
    Claim(wire::Writer<facescan_wire_SessionOwner> writer, wire::SessionOwnerData record,
          std::function<bool()> progressing = nullptr);
    wire::SessionOwnerData record() const;
    // Applies `change` to the record and publishes it when something changed (or always when forced).
    template <typename Fn>
    void update(Fn&& change, bool force = false) {
        std::lock_guard lk(mutex_);
        const wire::SessionOwnerData before = record_;
        change(record_);
        if (force || changed(before)) publishLocked();
    }
    void release();  // state RELEASED, then disposed: nobody owns the session any more
    // The claim at a later epoch (Cluster::raise): `writer`, of that epoch's strength, publishes the record from now
    // on, resuming at `resume_seq`. Returns the old writer, to be deleted on the retiring thread: withdrawn, not
    // disposed, since the new writer holds the instance.
    wire::Writer<facescan_wire_SessionOwner> raise(wire::Writer<facescan_wire_SessionOwner> writer, uint32_t epoch,
                                                   uint32_t resume_seq);

 private:
    bool changed(const wire::SessionOwnerData& before) const;
    void publishLocked();

    mutable std::mutex mutex_;
    wire::Writer<facescan_wire_SessionOwner> writer_;
    wire::SessionOwnerData record_;
    std::function<bool()> progressing_;
};

class Cluster {
 public:
    struct Options {
        std::string server_id;
        int max_sessions = 4;
        double join_settle_s = 2.0;  // seconds of discovery before this server takes sessions
        // seconds: the DDS profile's lease. The announcement and the claims lose their liveliness this long after
        // the server last asserted its progress (Server::intakeLoop), as they would if the process had died.
        double lease_s = 10.0;
        std::function<bool()> progressing;  // for the claims (Claim)
        wire::DomainConfig domain;          // for messages
    };
    static StatusOr<std::unique_ptr<Cluster>> create(const wire::Participant& participant, const Options& options);
    ~Cluster();

    // Intake thread: takes new announcements and claims. An error means this server must stop: another live
    // server on the domain uses its id (the message says which and what to do).
    Status poll();
    // True once the join period is over (discovery had time to show the domain's servers and claims).
    bool joined() const;
    // Publishes this server's announcement when the counts changed or a second passed (force: now).
    void announce(int open_sessions, int standby_sessions, bool force = false);
    // Withdraws the announcement (a clean shutdown): the others see this server gone at once.
    void withdraw();
    dds_entity_t announceReader() const { return announce_reader_->handle(); }
    dds_entity_t ownerReader() const { return owner_reader_->handle(); }

    const std::string& serverId() const { return options_.server_id; }
    double leaseS() const { return options_.lease_s; }
    int64_t startedNs() const { return self_.started_ns; }

    // The view (copies).
    std::vector<PeerView> peers() const;
    // Alive as DDS liveliness says (a killed server stays alive here until its lease lapses).
    bool serverAlive(const std::string& server_id) const;
    // A server whose announced process of this host no longer exists: a restart here need not wait for its lease.
    bool diedOnThisHost(const std::string& server_id) const;
    // Steady clock of the last announcement heard from a server (0: never).
    int64_t lastHeard(const std::string& server_id) const;
    // The same for one process of that id: the current one or the one before (0: neither).
    int64_t lastHeard(const std::string& server_id, uint64_t incarnation) const;
    // Whether the process that announced itself as `server_id` with `incarnation` has been replaced: another process
    // of that id (a restart) announces, and has been the only one heard for a second. A server id names one server
    // (its data dir is locked, and a second process of the id refuses to run beside the first), so the old process
    // is gone, and its claims with it, although its lease has not lapsed yet. False for 0 (an older server).
    bool replaced(const std::string& server_id, uint64_t incarnation) const;
    // Whether more than half of the servers known (alive now, or seen within the last minutes) are alive in this
    // server's view, itself included: false for a server cut off from the others.
    bool seesMajority() const;
    int othersAlive() const;  // other servers alive in this server's view
    int othersKnown() const;  // other servers alive, or seen within the last minutes
    // Other servers alive whose announcement arrived at or after `since_ns` (steady clock): proof that the network
    // still carries their messages to this server, which a liveliness not yet lapsed is not.
    int othersHeardSince(int64_t since_ns) const;
    // Live, joined, compatible servers with their load: self included once joined. Open counts come from the
    // claims (the same on every server), capacities and standbys from the announcements.
    std::vector<ServerLoad> liveLoads() const;
    std::optional<OwnerView> owner(const std::string& session_id) const;
    std::map<std::string, OwnerView> owners() const;
    // The server that answers commands for sessions nobody owns (unknown, refused): the lowest live id.
    std::string responder() const;

    // Raises a claim of this server to `epoch` (Claim::raise), through a new writer with that epoch's strength.
    StatusOr<wire::Writer<facescan_wire_SessionOwner>> raise(Claim& claim, uint32_t epoch, uint32_t resume_seq);
    // Writes a claim on a session at the record's epoch (a new DDS writer with that strength).
    StatusOr<std::unique_ptr<Claim>> claim(const wire::SessionOwnerData& initial);

 private:
    explicit Cluster(Options options);
    // A claim's DDS writer at `epoch`'s ownership strength (wire::claimStrength).
    StatusOr<wire::Writer<facescan_wire_SessionOwner>> claimWriter(uint32_t epoch, const std::string& session_id) const;
    Status takeAnnouncements();
    void takeOwners();
    // Another live server with our id that has the older right to it: the refusal, else ok.
    Status checkDuplicate(const wire::ServerAnnounceData& other) const;

    Options options_;
    wire::ServerAnnounceData self_;
    int64_t joined_after_ns_ = 0;  // steady clock
    std::optional<wire::Topic<facescan_wire_ServerAnnounce>> announce_topic_;
    std::optional<wire::Topic<facescan_wire_SessionOwner>> owner_topic_;
    std::optional<wire::Writer<facescan_wire_ServerAnnounce>> announce_writer_;
    std::optional<wire::Reader<facescan_wire_ServerAnnounce>> announce_reader_;
    std::optional<wire::Reader<facescan_wire_SessionOwner>> owner_reader_;

    mutable std::mutex mutex_;  // guards the view and the announcement state below
    std::map<std::string, PeerView> peers_;
    std::map<std::string, OwnerView> owners_;
    std::map<std::string, int64_t> incompatible_logged_;  // server id -> when we said so
    int last_open_ = -1, last_standby_ = -1;
    bool last_joining_ = true;
    int64_t last_announce_ns_ = 0;
    int64_t cpu_last_ns_ = 0;  // CPU time of this process at the last announcement (for cpu_load)
    int64_t cpu_wall_ns_ = 0;
};

}  // namespace facescan::service
