#include "service/server.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <thread>

#include "recon/parallel.hpp"
#include "service/failpoint.hpp"
#include "service/frame_load.hpp"
#include "service/replication.hpp"
#include "service/session_store.hpp"
#include "wire/private_files.hpp"

namespace facescan::service {
namespace {

constexpr double kRetirerStallLimitS = 120.0;  // seconds; see Retirer

constexpr int kBatch = 16;  // samples per take; also the reader's per-instance limit (wire::frameReaderQos)

facescan_wire_ScanState toWire(SessionState s) {
    switch (s) {
        case SessionState::kWaiting: return facescan_wire_STATE_WAITING;
        case SessionState::kScanning: return facescan_wire_STATE_SCANNING;
        case SessionState::kLost: return facescan_wire_STATE_LOST;
        case SessionState::kFinished: return facescan_wire_STATE_FINISHED;
        case SessionState::kRefused: return facescan_wire_STATE_REFUSED;
    }
    return facescan_wire_STATE_WAITING;
}

}  // namespace

StatusOr<std::unique_ptr<Server>> Server::create(const ServerParams& params) {
    RETURN_IF_ERROR(params.validate());
    std::unique_ptr<Server> server(new Server(params));
    RETURN_IF_ERROR(server->start());
    return server;
}

Status Server::start() {
    RETURN_IF_ERROR(checkDataDir(params_.data_dir));
    ASSIGN_OR_RETURN(data_dir_lock_, DataDirLock::acquire(params_.data_dir, params_.server_id));
    // What an older version (or a copy) left readable goes owner-only, like everything the server writes now.
    ASSIGN_OR_RETURN(audit_, wire::AuditLog::open(params_.data_dir / "audit.log"));
    ASSIGN_OR_RETURN(const int made_private, wire::makeTreePrivate(params_.data_dir));
    if (made_private > 0) {
        std::fprintf(stderr, "facescan-server: made %d file(s) and folder(s) in %s readable by this user only\n",
                     made_private, params_.data_dir.c_str());
    }
    using wire::boxed;
    ASSIGN_OR_RETURN(participant_, boxed(wire::Participant::create(params_.domain)));
    const wire::Participant& p = *participant_;
    if (!params_.domain.security.empty()) {
        ASSIGN_OR_RETURN(peers_, wire::PeerIdentities::create(p, params_.domain.security));
    }
    ASSIGN_OR_RETURN(camera_topic_, boxed(wire::Topic<facescan_wire_CameraInfo>::create(p)));
    ASSIGN_OR_RETURN(frame_topic_, boxed(wire::Topic<facescan_wire_RgbdFrame>::create(p)));
    ASSIGN_OR_RETURN(status_topic_, boxed(wire::Topic<facescan_wire_ScanStatus>::create(p)));
    ASSIGN_OR_RETURN(snapshot_topic_, boxed(wire::Topic<facescan_wire_MeshSnapshot>::create(p)));
    ASSIGN_OR_RETURN(command_topic_, boxed(wire::Topic<facescan_wire_ScanCommand>::create(p)));
    ASSIGN_OR_RETURN(reply_topic_, boxed(wire::Topic<facescan_wire_ScanReply>::create(p)));
    ASSIGN_OR_RETURN(camera_reader_, boxed(wire::Reader<facescan_wire_CameraInfo>::create(*camera_topic_)));
    ASSIGN_OR_RETURN(command_reader_, boxed(wire::Reader<facescan_wire_ScanCommand>::create(*command_topic_)));
    ASSIGN_OR_RETURN(status_writer_, boxed(wire::Writer<facescan_wire_ScanStatus>::create(*status_topic_)));
    ASSIGN_OR_RETURN(snapshot_writer_, boxed(wire::Writer<facescan_wire_MeshSnapshot>::create(*snapshot_topic_)));
    ASSIGN_OR_RETURN(reply_writer_, boxed(wire::Writer<facescan_wire_ScanReply>::create(*reply_topic_)));
    if (auto xml = wire::loadProfileXml(params_.domain.profile); xml.isOk()) {
        lease_ns_ = static_cast<int64_t>(wire::profileLeaseS(*xml) * 1e9);
    }
    if (const char* fp = std::getenv("FACESCAN_FAILPOINT")) {
        if (auto file = failpointArg("intake-stall-when-file")) stall_file_ = *file;
        if (auto file = failpointArg("claims-silent-when-file")) claims_silent_file_ = *file;
        std::fprintf(stderr, "facescan-server: FACESCAN_FAILPOINT=%s (fault injection for tests)\n", fp);
    }
    Watchdog::Options watch;
    watch.stall_limit_s = params_.stall_limit_s;
    watch.pause_gap_s = 0.5 * static_cast<double>(lease_ns_) * 1e-9;
    watchdog_ = std::make_unique<Watchdog>(
        watch, [this](const std::string& what) { onStall(what); },
        [this](int64_t gap_ns, int64_t now_ns) { noticePause(gap_ns, now_ns); });
    watchdog_->start();  // before the join: viewFresh() reads its checks
    intake_beat_ = watchdog_->add("the intake thread");
    // Deleting a DDS reader waits for Cyclone's garbage collector, which waits for every reliable write under way in
    // the process (each up to its max_blocking_time): with peers frozen or cut off, seconds. Only memory waits on
    // the retiring thread meanwhile, so it gets longer before it counts as stuck.
    retirer_ = std::make_unique<Retirer>(watchdog_->add("the retiring thread", kRetirerStallLimitS));
    Cluster::Options cluster;
    cluster.server_id = params_.server_id;
    cluster.lease_s = static_cast<double>(lease_ns_) * 1e-9;
    cluster.progressing = [this] { return claimsMayBeWritten(); };
    cluster.max_sessions = params_.max_sessions;
    cluster.join_settle_s = params_.join_settle_s;
    cluster.domain = params_.domain;
    ASSIGN_OR_RETURN(cluster_, Cluster::create(p, cluster));
    // A server whose own sessions are held replicates nothing: they may be another server's by now.
    ASSIGN_OR_RETURN(replicator_, Replicator::create(p, params_, *cluster_, [this] {
                         std::vector<std::shared_ptr<OwnedSession>> free = ownedSessions();
                         std::erase_if(free, [this](const auto& o) { return !sessionFree(o->recording.load()); });
                         return free;
                     }));

    const dds_entity_t ws = dds_create_waitset(p.handle());
    if (ws < 0) return wire::ddsStatus(ws, "create waitset");
    waitset_ = wire::Entity(ws);
    const dds_entity_t wake = dds_create_guardcondition(p.handle());
    if (wake < 0) return wire::ddsStatus(wake, "create guard condition");
    wake_ = wire::Entity(wake);
    // Each owned session's frame reader is attached when the session starts (activate).
    const dds_entity_t conds[] = {dds_create_readcondition(camera_reader_->handle(), DDS_ANY_STATE),
                                  dds_create_readcondition(command_reader_->handle(), DDS_ANY_STATE),
                                  dds_create_readcondition(cluster_->announceReader(), DDS_ANY_STATE),
                                  dds_create_readcondition(cluster_->ownerReader(), DDS_ANY_STATE), wake};
    for (const dds_entity_t c : conds) {
        if (c < 0) return wire::ddsStatus(c, "create read condition");
        const dds_return_t rc = dds_waitset_attach(ws, c, c);
        if (rc < 0) return wire::ddsStatus(rc, "attach condition");
    }
    startRetention();                 // before the resume: an expired replica is erased, not resumed
    RETURN_IF_ERROR(startErasure());  // and so is one the domain asks to erase
    // Before the resume: what a finish cut off by a kill left is no result, and no copy to continue from.
    for (const InterruptedFinish& cut : removeInterruptedFinishes(params_.data_dir, params_.server_id)) {
        std::string files;
        for (const std::string& f : cut.removed) files += (files.empty() ? "" : ", ") + f;
        std::fprintf(stderr,
                     "facescan-server: %s: a finish cut off here (the server was killed or crashed while it wrote) "
                     "left an incomplete result (%s, no summary.json and no replica to continue from): removed\n",
                     cut.dir.c_str(), files.c_str());
    }
    loadResumable();
    RETURN_IF_ERROR(join());
    joined_ = true;
    joined_ns_ = steadyNowNs();
    replicator_->start();
    intake_ = std::thread([this] { intakeLoop(); });
    command_ = std::thread([this] { commandLoop(); });
    snapshot_ = std::thread([this] { snapshotLoop(); });
    status_ = std::thread([this] { statusLoop(); });
    return Status::ok();
}

Status Server::join() {
    // Discovery first: the domain's servers and claims must be known before this server takes any session, and a
    // second server with our id must be found before we use it.
    while (!cluster_->joined()) {
        RETURN_IF_ERROR(cluster_->poll());
        replicator_->poll();  // replicas may already come in for sessions we stand by for
        cluster_->announce(0, standbySessions());
        assertProgress(steadyNowNs());
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    RETURN_IF_ERROR(cluster_->poll());
    cluster_->announce(0, standbySessions(), /*force=*/true);
    return Status::ok();
}

Server::Server(const ServerParams& params) : params_(params), finished_(params.keep_finished, params.keep_finished_s) {}

Server::~Server() { shutdown(); }

void Server::shutdown() {
    if (shut_down_) return;
    shut_down_ = true;
    // Finish every open session to disk first, while the DDS endpoints still answer.
    std::vector<std::shared_ptr<Session>> open;
    for (const auto& o : ownedSessions()) {
        if (o->session && o->session->open()) open.push_back(o->session);
    }
    std::vector<std::future<void>> done;
    for (auto& s : open) {
        auto promise = std::make_shared<std::promise<void>>();
        done.push_back(promise->get_future());
        s->requestFinish("server shutting down", [promise](const Status& st, const MeshResult&) {
            if (!st.isOk()) std::fprintf(stderr, "facescan-server: %s\n", st.toString().c_str());
            promise->set_value();
        });
    }
    // Bounded: a session given up meanwhile (another server owns it now) is not finished here and never answers.
    for (auto& f : done) (void)f.wait_for(std::chrono::seconds(120));

    stopping_ = true;
    if (wake_.valid()) dds_set_guardcondition(wake_.handle(), true);
    command_cv_.notify_all();
    sleep_cv_.notify_all();
    for (std::thread* t : {&intake_, &command_, &snapshot_, &status_}) {
        if (t->joinable()) t->join();
    }
    if (replicator_) replicator_->stop();
    if (watchdog_) watchdog_->stop();
    erasure_.reset();  // its thread forgets erased records, handing their claims to the retiring thread
    endLingering();    // frame readers that still linger go now
    retirer_.reset();  // what was given up ends now, while the participant still exists
    if (!status_writer_) return;
    // The last word on every session: final status and final mesh (durable: late subscribers still get them),
    // and the claims say FINISHED (a standby must not take over a session that ended here).
    for (const SessionStats& s : sessions()) publishStatus(s);
    for (const auto& o : ownedSessions()) {
        if (o->session) {
            if (auto snap = o->session->takeFinalSnapshot()) publishSnapshot(o->id, *snap);
        }
        if (o->claim) {
            const bool finished = o->session && o->session->finished();
            o->claim->update([&](wire::SessionOwnerData& r) {
                r.state = finished ? wire::OwnerState::kFinished : wire::OwnerState::kReleased;
            });
        }
    }
    // A server that refused to start (its id is taken) must not withdraw the other server's announcement.
    if (cluster_ && joined_) cluster_->withdraw();
    (void)status_writer_->waitForAcks(std::chrono::milliseconds(1000));
    (void)snapshot_writer_->waitForAcks(std::chrono::milliseconds(1000));
    (void)reply_writer_->waitForAcks(std::chrono::milliseconds(1000));
}

std::vector<SessionStats> Server::sessions() const {
    std::vector<SessionStats> out;
    std::lock_guard lk(sessions_mutex_);
    for (const auto& [id, o] : owned_) {
        if (o->session) out.push_back(o->session->stats());
    }
    for (SessionStats& s : finished_.stats()) out.push_back(std::move(s));
    for (const auto& [id, r] : refused_) {
        SessionStats s;
        s.session_id = id;
        s.state = SessionState::kRefused;
        s.detail = r.detail;
        out.push_back(s);
    }
    return out;
}

int Server::openSessions() const {
    std::lock_guard lk(sessions_mutex_);
    int n = 0;
    for (const auto& [id, o] : owned_) {
        n += o->phase != OwnedSession::Phase::kFinished && !(o->session && o->session->finished()) ? 1 : 0;
    }
    return n;
}

int Server::standbySessions() const { return replicator_ ? replicator_->standbyCount() : 0; }

std::shared_ptr<OwnedSession> Server::owned(const std::string& session_id) const {
    std::lock_guard lk(sessions_mutex_);
    const auto it = owned_.find(session_id);
    return it == owned_.end() ? nullptr : it->second;
}

std::vector<std::shared_ptr<OwnedSession>> Server::ownedSessions() const {
    std::lock_guard lk(sessions_mutex_);
    std::vector<std::shared_ptr<OwnedSession>> out;
    for (const auto& [id, o] : owned_) out.push_back(o);
    return out;
}

void Server::intakeLoop() {
    recon::nameThisThread("fs-intake");
    bool duplicate_logged = false;
    while (!stopping_) {
        intake_beat_->end();
        dds_attach_t triggered[16];
        (void)dds_waitset_wait(waitset_.handle(), triggered, 16, DDS_MSECS(100));
        intake_beat_->begin();
        dds_set_guardcondition(wake_.handle(), false);
        if (stopping_) break;
        assertProgress(steadyNowNs());
        refreshClaims(steadyNowNs());
        if (const Status s = cluster_->poll(); !s.isOk() && !duplicate_logged) {
            // After the join only a newer server can clash with our id, and that one refuses to start.
            std::fprintf(stderr, "facescan-server: %s\n", s.message().c_str());
            duplicate_logged = true;
        }
        takeCameraInfos();
        clusterTick();
        takeCommands();
        takeFrames();
        drainLingering();
        if (!stall_file_.empty()) failpoint();
    }
    intake_beat_->end();
}

void Server::takeCameraInfos() {
    constexpr size_t kMaxCandidates = 4096;  // a flood of bogus ids costs bounded memory
    auto n = camera_reader_->take(
        [&](const facescan_wire_CameraInfo& msg, const dds_sample_info_t& info) {
            const std::string id = wire::fromDds(msg.session_id);
            if (!info.valid_data) {
                if (auto it = candidates_.find(id); it != candidates_.end() && info.instance_state != DDS_IST_ALIVE) {
                    it->second.writer_alive = false;  // the agent is gone
                }
                return;
            }
            auto camera = wire::fromMessage(msg);
            if (!camera.isOk()) {
                std::fprintf(stderr, "facescan-server: CameraInfo of '%s' rejected: %s\n", id.c_str(),
                             camera.status().toString().c_str());
                return;
            }
            if (candidates_.count(id) == 0 && candidates_.size() >= kMaxCandidates) {
                auto oldest = std::min_element(
                    candidates_.begin(), candidates_.end(),
                    [](const auto& a, const auto& b) { return a.second.first_seen_ns < b.second.first_seen_ns; });
                candidates_.erase(oldest);
            }
            Candidate& c = candidates_[id];
            if (c.first_seen_ns == 0) c.first_seen_ns = steadyNowNs();
            c.camera = std::move(*camera);
            c.writer = info.publication_handle;
            c.order_key = info.source_timestamp;
            c.heard_ns = steadyNowNs();
            c.writer_alive = true;
        },
        256);
    if (!n.isOk()) std::fprintf(stderr, "facescan-server: %s\n", n.status().toString().c_str());
}

void Server::takeFrames() {
    for (const auto& o : ownedSessions()) {
        if (o->frames && o->session) takeFramesOf(*o);
    }
}

void Server::takeFramesOf(OwnedSession& o) {
    const dds_entity_t reader = o.frames->handle();
    Session& session = *o.session;
    void* samples[kBatch];
    dds_sample_info_t infos[kBatch];
    for (;;) {
        const int room = std::min(kBatch, session.roomForFrames());
        if (room <= 0) {
            // Full recording queue: mark what waits as read so that it stops waking the intake; the guard
            // condition wakes us when the worker made room, and the samples are taken then.
            samples[0] = nullptr;
            const dds_return_t n =
                dds_read_mask(reader, samples, infos, kBatch, kBatch,
                              DDS_NOT_READ_SAMPLE_STATE | DDS_ANY_VIEW_STATE | DDS_ANY_INSTANCE_STATE);
            if (n > 0) dds_return_loan(reader, samples, n);
            return;
        }
        samples[0] = nullptr;
        const dds_return_t n = dds_take(reader, samples, infos, static_cast<size_t>(room), static_cast<uint32_t>(room));
        if (n <= 0) return;
        for (int i = 0; i < n; ++i) {
            if (!infos[i].valid_data) {
                if (infos[i].instance_state != DDS_IST_ALIVE) session.noteWriterGone();
                continue;
            }
            const FrameFate fate = session.pushFrame(*static_cast<const facescan_wire_RgbdFrame*>(samples[i]));
            if (fate == FrameFate::kAhead) o.ahead = true;
            if (fate == FrameFate::kAccepted && o.phase == OwnedSession::Phase::kReady) {
                o.phase = OwnedSession::Phase::kActive;
                o.claim->update([](wire::SessionOwnerData& r) { r.state = wire::OwnerState::kActive; });
            }
        }
        dds_return_loan(reader, samples, n);
        if (n < room) return;
    }
}

void Server::publishStatus(const SessionStats& s) {
    wire::ScanStatusData d;
    d.session_id = s.session_id;
    d.server_id = params_.server_id;
    d.state = toWire(s.state);
    d.detail = s.detail;
    d.frames_received = s.frames_received;
    d.frames_integrated = s.frames_integrated;
    d.frames_rejected = s.frames_rejected;
    d.frames_skipped = s.frames_skipped;
    d.frames_dropped = s.frames_dropped;
    d.frames_tracked_only = s.frames_tracked_only;
    d.every_frame = s.every_frame;
    d.fps = s.fps;
    d.ms_detect = s.ms.detect;
    d.ms_segment = s.ms.segment;
    d.ms_filter = s.ms.filter;
    d.ms_icp = s.ms.icp;
    d.ms_integrate = s.ms.integrate;
    d.ms_raycast = s.ms.raycast;
    d.ms_mesh = s.ms.mesh;
    d.latency_p95_ms = s.latency_p95_ms;
    d.snapshot_seq = s.snapshot_seq;
    d.updated_ns = realtimeNowNs();
    d.standby_id = s.standby_id;
    d.owner_epoch = s.epoch;
    d.failovers = s.failovers;
    d.last_takeover_ms = s.last_takeover_ms;
    d.behind = s.behind;
    (void)status_writer_->write(wire::toMessage(d));
}

void Server::publishRefused(const std::string& session_id, const std::string& detail) {
    SessionStats s;
    s.session_id = session_id;
    s.state = SessionState::kRefused;
    s.detail = detail;
    publishStatus(s);
}

void Server::publishSnapshot(const std::string& session_id, const SnapshotResult& snap) {
    // An erased scan's geometry never goes out again, not even the final snapshot of a scan finished to be erased.
    if (isErased(params_.data_dir, session_id)) return;
    facescan_wire_MeshSnapshot m{};
    m.session_id = wire::stringView(session_id);
    m.seq = snap.seq;
    m.frames_integrated = snap.frames_integrated;
    m.vertex_count = snap.mesh.vertex_count;
    m.triangle_count = snap.mesh.triangle_count;
    m.created_ns = realtimeNowNs();
    m.draco = wire::octetView(snap.mesh.draco->data(), snap.mesh.draco->size());
    (void)snapshot_writer_->write(m);
}

bool Server::waitForTick(std::chrono::steady_clock::time_point& next, std::chrono::duration<double> period) {
    // A late tick does not make the next one fire at once: it comes a full period after the late one.
    next = std::max(next, std::chrono::steady_clock::now()) +
           std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
    std::unique_lock lk(sleep_mutex_);
    sleep_cv_.wait_until(lk, next, [&] { return stopping_.load(); });
    return !stopping_;
}

void Server::snapshotLoop() {
    recon::nameThisThread("fs-snapshot");
    runThisThreadInBackground();  // snapshots are a nicety; frames are not
    const auto period = params_.snapshot_hz > 0 ? std::chrono::duration<double>(1.0 / params_.snapshot_hz)
                                                : std::chrono::duration<double>(0.5);
    auto next = std::chrono::steady_clock::now();
    while (waitForTick(next, period)) {
        std::vector<std::shared_ptr<Session>> all;
        for (const auto& o : ownedSessions()) {
            if (o->session && sessionFree(o->recording.load())) all.push_back(o->session);
        }
        for (auto& s : all) {
            if (auto fin = s->takeFinalSnapshot()) {
                publishSnapshot(s->id(), *fin);
            } else if (params_.snapshot_hz > 0) {
                if (auto snap = s->makeSnapshot()) publishSnapshot(s->id(), *snap);
            }
        }
    }
}

void Server::statusLoop() {
    recon::nameThisThread("fs-status");
    const auto period = std::chrono::duration<double>(1.0 / params_.status_hz);
    const int64_t idle_ns = static_cast<int64_t>(params_.idle_timeout_s * 1e9);
    std::map<std::string, bool> final_sent;  // finished sessions: their FINISHED status went out once
    auto next = std::chrono::steady_clock::now();
    while (waitForTick(next, period)) {
        if (!sessionFree(/*recording=*/false)) continue;  // a pause not noticed yet
        std::vector<std::shared_ptr<OwnedSession>> all = ownedSessions();
        std::erase_if(all, [this](const auto& o) { return !sessionFree(o->recording.load()); });
        std::map<std::string, Refused> refused;
        {
            std::lock_guard lk(sessions_mutex_);
            refused = refused_;
        }
        const int64_t now = steadyNowNs();
        for (auto& o : all) {
            if (!o->session) continue;
            Session* s = o->session.get();
            const SessionStats st = s->stats();
            // The claim carries what the agent and the clients need from it (failovers, takeover time).
            o->claim->update([&](wire::SessionOwnerData& r) {
                r.failovers = st.failovers;
                r.last_takeover_ms = st.last_takeover_ms;
            });
            if (st.state == SessionState::kFinished) {
                if (final_sent[st.session_id]) continue;
                final_sent[st.session_id] = true;
            } else if (now - s->lastActivityNs() > idle_ns) {
                finishIdle(*o);
            }
            publishStatus(st);
        }
        for (const auto& [id, r] : refused) publishRefused(id, r.detail);
        all.clear();  // retireFinished frees the sessions it retires
        retireFinished(final_sent);
        returnHeldMemory(now);
        logMemory(now);
    }
}

}  // namespace facescan::service
