#include "service/replication.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "recon/parallel.hpp"
#include "service/failpoint.hpp"
#include "service/frame_load.hpp"
#include "service/server.hpp"
#include "service/session_store.hpp"

namespace facescan::service {
namespace {

constexpr int64_t kStatsEveryNs = 5'000'000'000;  // a log line about replication this often (when it did work)
constexpr auto kCaptureTimeout = std::chrono::milliseconds(2000);
// How long a server that lost every other server from view keeps its confirmations back (confirmable()): the
// lease for the others to see it go, their witness wait (up to two leases), their claim, and the agent's view of it.
constexpr double kAloneWaitLeases = 4.0;
constexpr double kAloneWaitMinS = 10.0;  // seconds, for short leases on a loaded host

double msSince(int64_t t0) { return static_cast<double>(steadyNowNs() - t0) * 1e-6; }

}  // namespace

struct Replicator::Outgoing {
    uint32_t epoch = 0;
    uint32_t round = 0;          // the last round made (1, 2, ...)
    std::string standby;         // empty: none (the data dir alone confirms, see confirmable())
    int64_t alone_since_ns = 0;  // steady clock since when it has had no standby (0: it has one)
    bool need_full = true;
    int rounds_since_full = 0;
    int64_t next_due_ns = 0;
    std::map<uint32_t, uint32_t> sent;  // rounds sent to the standby and not acknowledged yet -> their next_seq
    uint32_t acked_next_seq = 0;        // the standby holds every frame before this
    uint32_t disk_next_seq = 0;         // the data dir holds every frame before this
    std::unique_ptr<ReplicaLog> log;
    int64_t error_logged_ns = 0;
};

Replicator::Replicator(const ServerParams& params, Cluster& cluster, OwnedList owned)
    : params_(params), cluster_(cluster), owned_(std::move(owned)) {}

Replicator::~Replicator() { stop(); }

StatusOr<std::unique_ptr<Replicator>> Replicator::create(const wire::Participant& p, const ServerParams& params,
                                                         Cluster& cluster, OwnedList owned) {
    std::unique_ptr<Replicator> r(new Replicator(params, cluster, std::move(owned)));
    if (auto file = failpointArg("replication-stall-when-file")) r->stall_file_ = *file;
    const std::string mine = wire::serverPartition(params.server_id);
    ASSIGN_OR_RETURN(r->replica_topic_, wire::Topic<facescan_wire_SessionReplica>::create(p));
    ASSIGN_OR_RETURN(r->ack_topic_, wire::Topic<facescan_wire_ReplicaAck>::create(p));
    ASSIGN_OR_RETURN(r->replica_reader_,
                     wire::Reader<facescan_wire_SessionReplica>::create(*r->replica_topic_, nullptr, mine));
    ASSIGN_OR_RETURN(r->ack_reader_, wire::Reader<facescan_wire_ReplicaAck>::create(*r->ack_topic_, nullptr, mine));
    return r;
}

void Replicator::start() {
    running_ = true;
    thread_ = std::thread([this] { loop(); });
    receive_thread_ = std::thread([this] { receiveLoop(); });
}

void Replicator::stop() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
    if (receive_thread_.joinable()) receive_thread_.join();
}

void Replicator::receiveLoop() {
    recon::nameThisThread("fs-replica-in");
    // Its own thread, at the sessions' priority, that does nothing slow: Cyclone (0.10) delivers a sample to a full
    // keep-all reader by retrying on the process's receive thread, so a replica reader left full (its limit is
    // what holds a fast owner back) would stop every other delivery to this server, its own scans' frames and
    // their ends included. Taken on the replication thread, behind its rounds (an encoding, a write that waits for
    // a slow standby: seconds on a loaded machine, at a background priority), it did.
    while (running_) {
        replica_reader_->waitForData(std::chrono::milliseconds(100));
        takeReplicas();
    }
}

void Replicator::poll() {
    takeReplicas();
    takeAcks();
}

void Replicator::loop() {
    recon::nameThisThread("fs-replicate");
    // A round's encoding can wait a few milliseconds for the sessions' frames; the agents keep the frames until it
    // is done (keep_frames), so nothing is lost while it waits.
    runThisThreadInBackground();
    const auto interval_ns = static_cast<int64_t>(params_.replica_interval_s * 1e9);
    int64_t stats_due_ns = steadyNowNs() + kStatsEveryNs;
    ReplicationStats last;
    while (running_) {
        // The replicas that come in are receiveLoop's; this thread takes the acknowledgements of its own rounds.
        ack_reader_->waitForData(std::chrono::milliseconds(20));
        takeAcks();
        std::map<std::string, bool> live;
        // Held one at a time, each for its own round only: a session given up meanwhile ends on the retiring
        // thread once nobody else holds it (Server::retireOwned), and a list held through every round (seconds
        // each on a loaded machine) would keep it waiting.
        std::vector<std::weak_ptr<OwnedSession>> list;
        for (const auto& o : owned_()) list.push_back(o);
        for (const auto& weak : list) {
            const std::shared_ptr<OwnedSession> o = weak.lock();
            if (!o) continue;
            const OwnedSession::Phase phase = o->phase;
            // Only sessions that receive frames: a claimed session that never gets one (a bogus id) leaves no
            // replica and no folder behind.
            if (!o->session || phase != OwnedSession::Phase::kActive) continue;
            live[o->id] = true;
            std::unique_ptr<Outgoing>& out = outgoing_[o->id];
            if (!out || out->epoch != o->epoch) {
                out = std::make_unique<Outgoing>();
                out->epoch = o->epoch;
                out->next_due_ns = steadyNowNs() + interval_ns;  // the session was just restored or created
            }
            if (steadyNowNs() < out->next_due_ns) continue;
            out->next_due_ns = steadyNowNs() + interval_ns;
            replicate(*o, *out);
        }
        for (auto it = outgoing_.begin(); it != outgoing_.end();)
            it = live.count(it->first) ? std::next(it) : outgoing_.erase(it);
        forgetStaleCopies();
        if (steadyNowNs() >= stats_due_ns) {
            stats_due_ns = steadyNowNs() + kStatsEveryNs;
            const ReplicationStats now = stats();
            const uint64_t rounds = now.rounds - last.rounds;
            if (rounds > 0) {
                const double s = static_cast<double>(kStatsEveryNs) * 1e-9;
                std::fprintf(stderr,
                             "facescan-server: replication: %llu rounds (%llu full) in %.0f s: %.3f MB/s to standbys, "
                             "%.3f MB/s to disk; per round capture %.1f ms, encode %.1f ms, disk %.1f ms\n",
                             static_cast<unsigned long long>(rounds),
                             static_cast<unsigned long long>(now.full_rounds - last.full_rounds), s,
                             static_cast<double>(now.bytes_sent - last.bytes_sent) / s * 1e-6,
                             static_cast<double>(now.bytes_on_disk - last.bytes_on_disk) / s * 1e-6,
                             (now.capture_ms - last.capture_ms) / static_cast<double>(rounds),
                             (now.encode_ms - last.encode_ms) / static_cast<double>(rounds),
                             (now.disk_ms - last.disk_ms) / static_cast<double>(rounds));
            }
            last = now;
        }
    }
}

void Replicator::failpoint() {
    std::error_code ec;
    if (!std::filesystem::exists(stall_file_, ec)) return;
    std::fprintf(stderr, "facescan-server: failpoint: the replication thread stops in a round while %s exists\n",
                 stall_file_.c_str());
    while (running_ && std::filesystem::exists(stall_file_, ec))
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::fprintf(stderr, "facescan-server: failpoint: the replication thread goes on\n");
}

void Replicator::replicate(OwnedSession& o, Outgoing& out) {
    // The standby: kept while it lives, else the least busy other server (none: the data dir alone).
    std::string standby = out.standby;
    if (!standby.empty() && !cluster_.serverAlive(standby)) standby.clear();
    if (standby.empty()) standby = chooseStandby(o.id, params_.server_id, cluster_.liveLoads());
    if (standby.empty() && out.alone_since_ns == 0) out.alone_since_ns = steadyNowNs();
    if (!standby.empty()) out.alone_since_ns = 0;
    if (standby != out.standby) {
        out.standby = standby;
        out.need_full = true;
        out.sent.clear();
        out.acked_next_seq = 0;
        o.session->setStandby(standby);
        o.claim->update([&](wire::SessionOwnerData& r) { r.standby_id = standby; });
    }
    const bool full = out.need_full || out.round == 0 || out.rounds_since_full >= params_.replica_full_every;
    ReplicaCapture cap = std::move(spare_capture_);  // the last round's buffers, capacity and all
    int64_t t0 = steadyNowNs();
    if (!o.session->captureReplica(full, cap, kCaptureTimeout).isOk()) return;  // finished meanwhile
    const double capture_ms = msSince(t0);
    if (!stall_file_.empty()) failpoint();
    wire::ReplicaData r;
    r.session_id = o.id;
    r.owner_id = params_.server_id;
    r.epoch = o.epoch;
    r.round = out.round + 1;
    r.base_round = cap.state.full ? 0 : out.round;  // the core sends everything after a reset on its own
    r.next_seq = cap.next_seq;
    r.camera = std::move(cap.camera);
    r.counters = cap.counters;
    r.state = std::move(cap.state);
    r.has_keyframes = cap.has_keyframes;
    r.keyframes = std::move(cap.keyframes);
    std::vector<uint8_t>& bytes = bytes_;
    t0 = steadyNowNs();
    Status status = encoder_.encode(r, bytes);
    const double encode_ms = msSince(t0);
    spare_capture_.state = std::move(r.state);  // encoded: only its buffers are wanted again
    if (o.phase == OwnedSession::Phase::kGivenUp) {
        // Given up while it was encoded (another server's stronger claim): this server writes, replicates and
        // confirms nothing more for it (Server::yield).
        std::fprintf(stderr, "facescan-server: session %s: replication round %u dropped: the session was given up\n",
                     o.id.c_str(), out.round + 1);
        return;
    }
    if (!status.isOk()) {
        std::fprintf(stderr, "facescan-server: session %s: cannot encode its replica: %s\n", o.id.c_str(),
                     status.toString().c_str());
        out.need_full = true;
        return;
    }
    out.need_full = false;
    out.round = r.round;
    out.rounds_since_full = r.full() ? 1 : out.rounds_since_full + 1;

    // The data dir first: a restart resumes from it, and with no standby it alone confirms the frames.
    t0 = steadyNowNs();
    if (!out.log) {
        std::string note;
        auto dir = claimSessionDir(params_.data_dir, o.id, params_.server_id, o.epoch, &note);
        if (!note.empty()) std::fprintf(stderr, "facescan-server: %s\n", note.c_str());
        if (dir.isOk()) {
            o.dir = *dir;
            out.log = std::make_unique<ReplicaLog>(o.dir);
        }
        status = dir.status();
    }
    if (out.log) status = out.log->append(bytes, r.full());
    const double disk_ms = msSince(t0);
    if (status.isOk()) {
        out.disk_next_seq = r.next_seq;
    } else {
        out.need_full = true;
        if (steadyNowNs() - out.error_logged_ns > kStatsEveryNs) {
            std::fprintf(stderr, "facescan-server: session %s: replica not written: %s\n", o.id.c_str(),
                         status.toString().c_str());
            out.error_logged_ns = steadyNowNs();
        }
    }
    uint64_t sent_bytes = 0;
    if (!standby.empty()) {
        wire::Writer<facescan_wire_SessionReplica>* writer = replicaWriter(standby);
        if (!writer || writer->matchedReaders() == 0) {
            out.need_full = true;  // the standby is not reachable yet: it gets a full one when it is
        } else {
            facescan_wire_SessionReplica m{};
            m.session_id = wire::stringView(o.id);
            m.target_id = wire::stringView(standby);
            m.source_id = wire::stringView(params_.server_id);
            m.epoch = r.epoch;
            m.round = r.round;
            m.base_round = r.base_round;
            m.next_seq = r.next_seq;
            m.payload = wire::octetView(bytes.data(), bytes.size());
            if (writer->write(m).isOk()) {
                out.sent[r.round] = r.next_seq;
                sent_bytes = bytes.size();
            } else {
                out.need_full = true;
            }
        }
    }
    {
        std::lock_guard lk(mutex_);
        ++stats_.rounds;
        stats_.full_rounds += r.full() ? 1 : 0;
        stats_.bytes_sent += sent_bytes;
        stats_.bytes_on_disk += status.isOk() ? bytes.size() : 0;
        stats_.capture_ms += capture_ms;
        stats_.encode_ms += encode_ms;
        stats_.disk_ms += disk_ms;
    }
    // What the agent may drop: frames both on disk and at the standby (on disk alone without a standby).
    const uint32_t confirmed = confirmable(out);
    o.claim->update([&](wire::SessionOwnerData& rec) { rec.confirmed_seq = std::max(rec.confirmed_seq, confirmed); });
}

uint32_t Replicator::confirmable(const Outgoing& out) const {
    if (!out.standby.empty()) return std::min(out.disk_next_seq, out.acked_next_seq);
    // No standby in view. A lone server's data dir is all there is, and it confirms. But a server that knows other
    // servers and sees none may be the one cut off from them while its agent still reaches it: they then take the
    // scan over from their last copy, and the frames this server confirmed on its disk alone would be gone from the
    // agent, lost to the new owner's result. So it confirms nothing new until the others have had the time to take
    // the session over and its agent to follow their claim (it then ignores this server's confirmations): a few
    // leases. After that they are taken to be gone, and the disk confirms, so that a recording whose agent waits
    // for room (it keeps a bounded number of frames) goes on.
    const double lease_s = cluster_.leaseS();
    const auto wait_ns = static_cast<int64_t>(std::max(kAloneWaitLeases * lease_s, kAloneWaitMinS) * 1e9);
    if (cluster_.othersKnown() > 0 && steadyNowNs() - out.alone_since_ns < wait_ns) return out.acked_next_seq;
    return out.disk_next_seq;
}

void Replicator::takeAcks() {
    auto n = ack_reader_->take(
        [&](const facescan_wire_ReplicaAck& m, const dds_sample_info_t& info) {
            if (!info.valid_data) return;
            const std::string session = wire::fromDds(m.session_id), standby = wire::fromDds(m.standby_id);
            const auto it = outgoing_.find(session);
            if (it == outgoing_.end() || it->second->epoch != m.epoch || it->second->standby != standby) return;
            Outgoing& out = *it->second;
            if (m.need_full) {
                out.need_full = true;
                out.sent.clear();
                std::fprintf(stderr,
                             "facescan-server: session %s: standby '%s' refused round %u (%s): sending a full "
                             "replica\n",
                             session.c_str(), standby.c_str(), m.round, wire::fromDds(m.error).c_str());
                return;
            }
            const auto sent = out.sent.find(m.round);
            if (sent == out.sent.end()) return;
            out.acked_next_seq = std::max(out.acked_next_seq, sent->second);
            out.sent.erase(out.sent.begin(), std::next(sent));
            // The agent may drop what both the standby and the disk hold: now rather than at the next round.
            const uint32_t confirmed = confirmable(out);
            for (const auto& o : owned_()) {
                if (o->id != session || !o->claim) continue;
                o->claim->update(
                    [&](wire::SessionOwnerData& r) { r.confirmed_seq = std::max(r.confirmed_seq, confirmed); });
            }
        },
        64);
    if (!n.isOk()) std::fprintf(stderr, "facescan-server: %s\n", n.status().toString().c_str());
}

void Replicator::takeReplicas() {
    auto n = replica_reader_->take(
        [&](const facescan_wire_SessionReplica& m, const dds_sample_info_t& info) {
            if (!info.valid_data) return;
            const std::string session = wire::fromDds(m.session_id), source = wire::fromDds(m.source_id);
            {
                std::lock_guard lk(mutex_);
                heard_[source] = steadyNowNs();
            }
            wire::ReplicaData r;
            Status s = m.payload._length > 0 && !m.payload._buffer
                           ? dataLoss("replica without bytes")
                           : wire::decodeReplica(m.payload._buffer, m.payload._length, r);
            if (s.isOk() && (r.session_id != session || r.owner_id != source || r.epoch != m.epoch ||
                             r.round != m.round || r.base_round != m.base_round)) {
                s = dataLoss("the replica's header and its payload disagree");
            }
            if (s.isOk()) {
                std::lock_guard lk(mutex_);
                Incoming& in = incoming_[session];
                if (r.full()) {
                    in.copy = std::move(r);
                } else if (in.copy.round == 0) {
                    s = invalidArgument("a delta (round " + std::to_string(r.round) + ") without a full replica first");
                } else {
                    s = wire::mergeReplica(in.copy, r);
                }
                if (s.isOk()) in.received_ns = steadyNowNs();
                if (!s.isOk() && in.copy.round == 0) incoming_.erase(session);
            }
            if (!s.isOk()) {
                bool log = true;
                {
                    std::lock_guard lk(mutex_);
                    ++stats_.rejected;
                    if (s.code() == StatusCode::kUnimplemented) {  // another version: said once per server
                        log = incompatible_logged_[source]++ == 0;
                    }
                }
                if (log) {
                    std::fprintf(stderr, "facescan-server: refusing replica round %u of session %s from '%s': %s\n",
                                 m.round, session.c_str(), source.c_str(), s.message().c_str());
                }
                ack(session, source, m.epoch, 0, /*need_full=*/true, s.message());
                return;
            }
            ack(session, source, m.epoch, m.round, false, "");
        },
        4);
    if (!n.isOk()) std::fprintf(stderr, "facescan-server: %s\n", n.status().toString().c_str());
}

void Replicator::ack(const std::string& session_id, const std::string& owner_id, uint32_t epoch, uint32_t round,
                     bool need_full, const std::string& error) {
    if (wire::validateServerId(owner_id).isOk() == false) return;  // no partition to answer in
    wire::Writer<facescan_wire_ReplicaAck>* writer = ackWriter(owner_id);
    if (!writer) return;
    facescan_wire_ReplicaAck a{};
    a.session_id = wire::stringView(session_id);
    a.standby_id = wire::stringView(params_.server_id);
    a.epoch = epoch;
    a.round = round;
    a.need_full = need_full;
    a.error = wire::stringView(error);
    (void)writer->write(a);
}

void Replicator::forgetStaleCopies() {
    std::map<std::string, int64_t> copies;  // session -> when its last replica came
    {
        std::lock_guard lk(mutex_);
        for (const auto& [id, in] : incoming_) copies[id] = in.received_ns;
    }
    for (const auto& [id, received_ns] : copies) {
        const auto view = cluster_.owner(id);
        if (!view) continue;
        const wire::OwnerState st = view->data.state;
        const bool over = st == wire::OwnerState::kFinished || st == wire::OwnerState::kReleased || view->disposed;
        // The live owner names another standby in a record newer than our copy (or this server owns it now): the
        // copy is of no use any more. (A dead owner's copy is what a takeover needs: kept.)
        const bool elsewhere = view->alive && view->data.standby_id != params_.server_id && view->seen_ns > received_ns;
        if (over || elsewhere) {
            std::lock_guard lk(mutex_);
            incoming_.erase(id);
        }
    }
}

wire::Writer<facescan_wire_SessionReplica>* Replicator::replicaWriter(const std::string& standby_id) {
    auto& w = replica_writers_[standby_id];
    if (!w) {
        auto made = wire::Writer<facescan_wire_SessionReplica>::create(*replica_topic_, nullptr,
                                                                       wire::serverPartition(standby_id));
        if (!made.isOk()) return nullptr;
        w = std::make_unique<wire::Writer<facescan_wire_SessionReplica>>(std::move(made).value());
    }
    return w.get();
}

wire::Writer<facescan_wire_ReplicaAck>* Replicator::ackWriter(const std::string& owner_id) {
    auto& w = ack_writers_[owner_id];
    if (!w) {
        auto made =
            wire::Writer<facescan_wire_ReplicaAck>::create(*ack_topic_, nullptr, wire::serverPartition(owner_id));
        if (!made.isOk()) return nullptr;
        w = std::make_unique<wire::Writer<facescan_wire_ReplicaAck>>(std::move(made).value());
    }
    return w.get();
}

std::optional<wire::ReplicaData> Replicator::standbyCopy(const std::string& session_id) const {
    std::lock_guard lk(mutex_);
    const auto it = incoming_.find(session_id);
    // A copy taken before the first frame was integrated has no volume yet: nothing to continue from.
    if (it == incoming_.end() || it->second.copy.round == 0 || !it->second.copy.state.validate().isOk()) {
        return std::nullopt;
    }
    return it->second.copy;
}

int Replicator::standbyCount() const {
    std::lock_guard lk(mutex_);
    return static_cast<int>(incoming_.size());
}

size_t Replicator::standbyBytes() const {
    std::lock_guard lk(mutex_);
    size_t bytes = 0;
    for (const auto& [id, in] : incoming_) {
        const recon::ReconState& st = in.copy.state;
        bytes +=
            st.blocks.voxels.capacity() * sizeof(recon::Voxel) + st.blocks.coords.capacity() * sizeof(Eigen::Vector3i);
        bytes += st.trajectory.capacity() * sizeof(st.trajectory[0]);
        for (const wire::ReplicaKeyframe& k : in.copy.keyframes) bytes += k.jpeg.capacity();
    }
    return bytes;
}

int64_t Replicator::lastHeardFrom(const std::string& server_id) const {
    std::lock_guard lk(mutex_);
    const auto it = heard_.find(server_id);
    return it == heard_.end() ? 0 : it->second;
}

ReplicationStats Replicator::stats() const {
    std::lock_guard lk(mutex_);
    return stats_;
}

}  // namespace facescan::service
