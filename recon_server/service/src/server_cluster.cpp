// The server's part in the cluster, on the intake thread: which new session to claim, when a claim has
// settled, when to give one up, when to resume from the data dir (taking over from a dead owner is
// server_takeover.cpp). Every decision
// is a function of the view that DDS gives (announcements with liveliness, claims with EXCLUSIVE ownership and
// instance states); there is no protocol of our own beyond writing and reading those topics.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <set>
#include <thread>
#include <utility>

#include "recon/parallel.hpp"
#include "service/finished_sessions.hpp"
#include "service/frame_load.hpp"
#include "service/lingering_reader.hpp"
#include "service/replica_log.hpp"
#include "service/replication.hpp"
#include "service/server.hpp"
#include "service/session_store.hpp"
#include "service/takeover.hpp"

namespace facescan::service {
namespace {

constexpr int64_t kClaimBatchNs = 150'000'000;    // CameraInfos that arrive together are placed together
constexpr int64_t kReplayRepeatNs = 300'000'000;  // at most this often a new request to resend frames

}  // namespace

void Server::clusterTick() {
    int open = 0;
    for (const auto& o : ownedSessions()) {
        open += o->phase != OwnedSession::Phase::kFinished ? 1 : 0;
        o->agent_alive = agentLives(o->id);
    }
    cluster_->announce(open, standbySessions());
    const std::map<std::string, OwnerView> owners = cluster_->owners();
    settleClaims(owners);  // while the view is stale, only to give up what another server owns now
    dropSupersededResults(owners);
    if (!viewFresh()) return;
    // A server back from a cut-off sees the agents again before the other servers' claims: every session would
    // look unplaced, and a claim on one that another server is scanning wins on its tie-break and splits the
    // scan (the other server gives up the frames it integrated, which the agent has already dropped). So it
    // places nothing either until it has re-observed the cluster.
    if (!rejoining()) {
        takeOverOrphans(owners);
        placeNewSessions(owners);
    }
    requestReplays();
    releaseStale();
}

void Server::placeNewSessions(const std::map<std::string, OwnerView>& owners) {
    // Agents that are gone take their candidates with them; what they had dropped stays (bounded).
    constexpr size_t kMaxGoneAgents = 4096;
    for (auto it = candidates_.begin(); it != candidates_.end();) {
        if (it->second.writer_alive) {
            ++it;
            continue;
        }
        if (it->second.camera.dropped_before_seq > 0) {
            if (gone_agents_dropped_before_.size() >= kMaxGoneAgents) {
                gone_agents_dropped_before_.erase(gone_agents_dropped_before_.begin());
            }
            uint32_t& dropped = gone_agents_dropped_before_[it->first];
            dropped = std::max(dropped, it->second.camera.dropped_before_seq);
        }
        it = candidates_.erase(it);
    }
    std::erase_if(tombstones_, [&](const auto& t) { return !candidates_.count(t.first); });
    // Flood control: one agent writer (a CameraInfo publication) gets one session placed at a time; its next one
    // waits until the previous one received frames or was released. A real agent writes one session.
    std::map<dds_instance_handle_t, const std::string*> next_of_writer;
    std::set<dds_instance_handle_t> busy_writers;
    // Its sessions claimed here count at once, before this server's own claim is back in its view.
    for (const auto& o : ownedSessions()) {
        const OwnedSession::Phase phase = o->phase;
        if (phase == OwnedSession::Phase::kClaiming || phase == OwnedSession::Phase::kReady) {
            busy_writers.insert(o->camera_writer);
        }
    }
    std::vector<service::Candidate> eligible;
    for (const auto& [id, c] : candidates_) {
        const auto view = owners.find(id);
        // A released claim (no frame came in time) is placed again while its agent lives, at a higher epoch.
        const bool released =
            view != owners.end() && !view->second.alive && view->second.data.state == wire::OwnerState::kReleased;
        if (view != owners.end() && !released) {
            const wire::OwnerState st = view->second.data.state;
            if (view->second.alive && (st == wire::OwnerState::kClaiming || st == wire::OwnerState::kReady)) {
                busy_writers.insert(c.writer);
            }
            // Claimed once: never placed again (a dead owner's session waits for its standby). A live claim
            // keeps its place in the order, so that this server places the sessions around it as every other
            // server does, whether or not they have seen the claim yet.
            if (view->second.alive && holdsSession(st))
                eligible.push_back({id, c.order_key, view->second.data.owner_id});
            continue;
        }
        if (owned(id) || resumable_.count(id)) continue;
        if (refuseReusedId(id)) continue;
        if (!placeableAsNew(id, c)) continue;  // no claim in view, or a released one: both start from scratch
        const std::string*& first = next_of_writer[c.writer];
        if (!first || c.order_key < candidates_.at(*first).order_key) first = &id;
    }
    const int64_t now = steadyNowNs();
    bool unclaimed = false;
    for (const auto& [writer, id] : next_of_writer) {
        if (busy_writers.count(writer)) continue;
        eligible.push_back(
            {*id, candidates_.at(*id).order_key, {}, now - candidates_.at(*id).first_seen_ns - kClaimBatchNs});
        unclaimed = true;
    }
    if (!unclaimed) return;
    const std::vector<ServerLoad> loads = cluster_->liveLoads();
    // No server in view, not even this one (its own announcement lapsed in its view for a moment on a loaded
    // machine): nothing can be placed, and nothing is full either. The next tick places it.
    if (loads.empty()) return;
    // A chosen server that lives claims within three leases: it may have stalled for up to one (longer, and its
    // liveliness lapses: it leaves the view, and its sessions are placed again without it at once), then it
    // re-observes the cluster for two before it places anything. Only past that is it passed over: sooner, a
    // server that was descheduled for a moment on a loaded machine would lose its turn, and the spread its balance.
    const std::map<std::string, std::string> assigned = placeSessions(eligible, loads, 3 * lease_ns_);
    const bool responder = cluster_->responder() == params_.server_id;
    for (const service::Candidate& e : eligible) {
        if (!e.claimed_by.empty()) continue;
        const Candidate& c = candidates_.at(e.session_id);
        const auto target = assigned.find(e.session_id);
        if (target == assigned.end()) {
            // No live server has room: the responder says so in the session's status until one has.
            std::lock_guard lk(sessions_mutex_);
            if (responder && !refused_.count(e.session_id)) {
                int capacity = 0;
                for (const ServerLoad& l : loads) capacity += l.capacity;
                const std::string detail = "refused: all " + std::to_string(loads.size()) + " server(s) are full (" +
                                           std::to_string(capacity) + " sessions, --max-sessions " +
                                           std::to_string(params_.max_sessions) + " here)";
                refused_[e.session_id] = {detail};
                std::fprintf(stderr, "facescan-server: session %s %s\n", e.session_id.c_str(), detail.c_str());
            }
            continue;
        }
        if (target->second != params_.server_id || e.overdue_ns < 0) continue;
        if (e.overdue_ns >= 3 * lease_ns_) {
            std::fprintf(stderr,
                         "facescan-server: session %s: the server it was placed on has not claimed it within %.0f s: "
                         "claiming it here\n",
                         e.session_id.c_str(), static_cast<double>(3 * lease_ns_) * 1e-9);
        }
        auto o = std::make_shared<OwnedSession>();
        o->camera = c.camera;
        o->camera_writer = c.writer;
        const auto before = owners.find(e.session_id);
        const wire::SessionOwnerData previous = before != owners.end() ? before->second.data : wire::SessionOwnerData{};
        // Above any epoch the agent followed too: a claim from before it that this server never saw may still be
        // out there (its owner frozen or cut off), and must not win over this one.
        const uint32_t epoch =
            std::max(before != owners.end() ? before->second.data.epoch + 1 : 1u, c.camera.followed_epoch + 1);
        if (const Status s = claimSession(e.session_id, epoch, o, previous); !s.isOk()) {
            std::fprintf(stderr, "facescan-server: cannot claim %s: %s\n", e.session_id.c_str(), s.toString().c_str());
        }
    }
}

bool Server::placeableAsNew(const std::string& session_id, const Candidate& c) {
    if (c.camera.serving_epoch > 0) {
        // The agent streams to an owner whose claim this server does not see: a cut between the servers (or a view
        // still filling in). A claim here would take the scan from that owner.
        sayOnce("session " + session_id + ": its agent streams to an owner (epoch " +
                std::to_string(c.camera.serving_epoch) +
                ") whose claim this server does not see (a cut between the servers, or its view still filling in): "
                "not placed here");
        return false;
    }
    if (c.camera.followed_epoch == 0) return true;  // never owned (or an older agent): a new session
    // Owned once, and no claim of it in view: this server joined after its owner's claim was gone (a restart), or
    // its view is still filling in. Two leases after the join a live claim would be in view.
    if (steadyNowNs() - joined_ns_ < 2 * lease_ns_) return false;
    if (c.camera.dropped_before_seq == 0) return true;  // the agent still holds every frame: start over safely
    // The agent dropped frames that an owner had confirmed: only a server holding the copy of them (as standby, or
    // in its data dir after a restart) can continue the scan. Starting it over from the first frame here would
    // lose them for good.
    const std::string why = "session " + session_id + ": its agent dropped frames 0-" +
                            std::to_string(c.camera.dropped_before_seq - 1) + ", which an owner (epoch " +
                            std::to_string(c.camera.followed_epoch) +
                            ") had confirmed, and no claim of it is in view: this server holds no copy of them and "
                            "leaves the scan to the server that does (a restart of that server resumes it)";
    sayOnce(why);
    return false;
}

void Server::sayOnce(const std::string& line) {
    if (refusals_logged_.insert(line).second) std::fprintf(stderr, "facescan-server: %s\n", line.c_str());
}

bool Server::refuseReusedId(const std::string& session_id) {
    if (tombstones_.count(session_id)) return true;
    const std::optional<std::filesystem::path> dir =
        findFinishedSessionDir(params_.data_dir, session_id, params_.server_id);
    if (!dir) return false;
    // A claim that says FINISHED, as the scan's owner once wrote it: no server places the new one, and its agent
    // says why and stops, instead of a second scan under the same id next to (or over) this one.
    wire::SessionOwnerData record;
    record.session_id = session_id;
    record.owner_id = params_.server_id;
    const auto previous = readSessionOwner(*dir);
    record.epoch = previous ? previous->second + 1 : 1;
    record.state = wire::OwnerState::kFinished;
    auto claim = cluster_->claim(record);
    if (!claim.isOk()) return false;
    tombstones_[session_id] = std::move(*claim);
    std::fprintf(stderr,
                 "facescan-server: session %s: refused: the id names a scan that finished here (%s); a new scan needs "
                 "a new --session id, and that scan's files stay as they are\n",
                 session_id.c_str(), dir->c_str());
    return true;
}

Status Server::claimSession(const std::string& session_id, uint32_t epoch, std::shared_ptr<OwnedSession> o,
                            const wire::SessionOwnerData& previous) {
    wire::SessionOwnerData record;
    record.session_id = session_id;
    record.owner_id = params_.server_id;
    record.epoch = epoch;
    record.state = wire::OwnerState::kClaiming;
    if (o->restore_from) record.resume_seq = record.confirmed_seq = o->restore_from->next_seq;
    record.failovers = previous.failovers;
    record.last_takeover_ms = previous.last_takeover_ms;
    o->id = session_id;
    o->epoch = epoch;
    o->claimed_ns = steadyNowNs();
    ASSIGN_OR_RETURN(o->claim, cluster_->claim(record));
    {
        std::lock_guard lk(sessions_mutex_);
        owned_[session_id] = o;
        refused_.erase(session_id);
    }
    buildEngine(*o);
    return Status::ok();
}

void Server::buildEngine(OwnedSession& o) {
    const wire::ReplicaData* replica = o.restore_from ? &*o.restore_from : nullptr;
    if (!replica && !o.camera) return;  // activate() says what is missing
    // Copies of what the build reads, but the replica: a model's worth of blocks, which o keeps until the build is
    // done (the future's destructor waits for it) and activate() has taken it.
    const dds_entity_t wake = wake_.valid() ? wake_.handle() : 0;
    try {
        const bool takeover = o.takeover_from_ns != 0;
        o.engine = std::async(std::launch::async, [params = params_, camera = replica ? replica->camera : *o.camera,
                                                   replica, wake, takeover] {
            recon::nameThisThread("fs-engine");
            // The build (cascade parsed, buffers touched: 30-45 ms of CPU) lands as a session joins busy
            // ones; the claim settles for claim_settle_s meanwhile, so it is rarely waited for. A takeover's
            // build is what its live scan waits for (it also restores the model from the replica): at the
            // priority of frames, or a loaded machine starves it for seconds.
            if (!takeover) runThisThreadInBackground();
            StatusOr<SessionEngine> engine = SessionEngine::build(params, camera, replica);
            if (wake > 0) (void)dds_set_guardcondition(wake, true);  // activate() on the intake thread's next turn
            return engine;
        });
    } catch (const std::system_error&) {
        // No thread to be had: activate() builds it on the intake thread, as before.
    }
}

void Server::settleClaims(const std::map<std::string, OwnerView>& owners) {
    const int64_t settle_ns = static_cast<int64_t>(params_.claim_settle_s * 1e9);
    for (const auto& o : ownedSessions()) {
        const auto it = owners.find(o->id);
        const OwnerView* view = it == owners.end() ? nullptr : &it->second;
        const bool ours =
            view && view->alive && view->data.owner_id == params_.server_id && view->data.epoch == o->epoch;
        // Only a claim at least as strong: a later epoch, or this epoch won by another server on the tie-break. The
        // reader shows a weaker live claim while this server's own new claim has not reached it yet, or an old owner
        // woken from a freeze writes its claim again before it sees this one: yielding to that left the session
        // with no owner (the old owner yields to this claim meanwhile), to be placed again from the first frame.
        const bool beaten =
            view && view->alive && !ours &&
            (view->data.epoch > o->epoch || (view->data.epoch == o->epoch && view->data.owner_id != params_.server_id));
        if (o->phase == OwnedSession::Phase::kClaiming) {
            if (beaten) {
                yield(o->id,
                      "server '" + view->data.owner_id + "' claimed it too (epoch " + std::to_string(view->data.epoch) +
                          ")",
                      *view);
            } else if (ours && viewFresh() && steadyNowNs() - o->claimed_ns >= settle_ns &&
                       (!o->engine.valid() ||
                        o->engine.wait_for(std::chrono::seconds(0)) == std::future_status::ready)) {
                if (const Status s = activate(*o); !s.isOk()) {
                    std::fprintf(stderr, "facescan-server: cannot start session %s: %s\n", o->id.c_str(),
                                 s.toString().c_str());
                    retireOwned(o, /*dispose_claim=*/true);
                }
            }
        } else if (beaten && holdsFullerSession(*o, *view)) {
            claimFullerSession(*o, view->data);
        } else if (beaten) {
            // A stronger claim: a takeover that happened while this server could not be seen (split brain), or
            // a claim made at the same moment from another view. The other one continues; this one stops.
            yield(o->id,
                  "server '" + view->data.owner_id + "' owns it (epoch " + std::to_string(view->data.epoch) +
                      ", this server's epoch " + std::to_string(o->epoch) + ")",
                  *view);
        }
    }
}

Status Server::activate(OwnedSession& o) {
    auto session = std::make_shared<Session>(o.id, params_, [this] {
        if (wake_.valid()) dds_set_guardcondition(wake_.handle(), true);
    });
    session->setOwnership(params_.server_id, o.epoch);
    o.recording = o.restore_from ? o.restore_from->camera.every_frame : !o.camera || o.camera->every_frame;
    session->setWatch(watchdog_->add("the worker of session " + o.id),
                      [this, recording = o.recording.load()] { return !sessionFree(recording); });
    SessionEngine engine;
    if (o.engine.valid()) {
        ASSIGN_OR_RETURN(engine, o.engine.get());
    }
    if (o.restore_from) {
        RETURN_IF_ERROR(session->restore(*o.restore_from, o.takeover_from_ns, std::move(engine)));
    } else {
        if (!o.camera) return internalError("no CameraInfo for session '" + o.id + "'");
        RETURN_IF_ERROR(session->setCamera(*o.camera, std::move(engine)));
        if (o.takeover_from_ns != 0) session->noteTakeoverFromFirstFrame(o.failovers_before, o.takeover_from_ns);
    }
    const wire::Qos qos = wire::frameReaderQos();
    ASSIGN_OR_RETURN(o.frames, wire::boxed(wire::Reader<facescan_wire_RgbdFrame>::create(
                                   *frame_topic_, &qos, wire::sessionPartition(o.id))));
    o.frame_condition = dds_create_readcondition(
        o.frames->handle(), DDS_NOT_READ_SAMPLE_STATE | DDS_ANY_VIEW_STATE | DDS_ANY_INSTANCE_STATE);
    if (o.frame_condition < 0) return wire::ddsStatus(o.frame_condition, "create read condition");
    if (const dds_return_t rc = dds_waitset_attach(waitset_.handle(), o.frame_condition, o.frame_condition); rc < 0) {
        return wire::ddsStatus(rc, "attach read condition");
    }
    o.session = session;
    o.ready_ns = steadyNowNs();
    o.phase = OwnedSession::Phase::kReady;
    const uint32_t next = session->nextSeq();
    o.claim->update([&](wire::SessionOwnerData& r) {
        r.state = wire::OwnerState::kReady;
        r.resume_seq = next;
        r.confirmed_seq = next;
    });
    std::string resumed;
    if (next > 0) resumed = ", resuming at frame " + std::to_string(next);
    if (o.restore_from && o.restore_from->has_keyframes) {
        resumed += " with " + std::to_string(o.restore_from->keyframes.size()) + " texture keyframes";
    }
    o.restore_from.reset();  // the state lives in the session now
    std::fprintf(stderr, "facescan-server: owns session %s (epoch %u%s, %.0f ms after the claim)\n", o.id.c_str(),
                 o.epoch.load(), resumed.c_str(), static_cast<double>(steadyNowNs() - o.claimed_ns) * 1e-6);
    return Status::ok();
}

void Server::yield(const std::string& session_id, const std::string& why, const OwnerView& winner) {
    std::shared_ptr<OwnedSession> o = owned(session_id);
    if (!o) return;
    // The stronger claim continues the scan from its replica and from the frames the agent keeps until they are
    // confirmed, so nothing is lost if this server stops here. Writing what it integrated would split the scan
    // (two results for one session), so it writes, replicates and answers nothing more for it.
    const uint32_t integrated = o->session ? o->session->stats().frames_integrated : 0;
    const uint32_t next_seq = o->session ? o->session->nextSeq() : 0;
    // Finished here while this server was frozen or cut off, and taken over meanwhile: the new owner finishes it
    // again from the replica and the frames the agent keeps (an agent follows the strongest claim, so it waits for
    // that owner's result, not this one's). This server's files would be a second result for one scan: they go.
    // Without the agent, the new owner has only the replica, and these files may be the whole scan: they stay,
    // unless the new owner has finished the scan with every frame this server had.
    const std::filesystem::path written = o->session ? o->session->filesDir() : std::filesystem::path();
    const bool agent_lives = agentLives(session_id);
    const bool superseded = resultSuperseded(winner, o->epoch, next_seq);
    // A finish still writing decides as written files do below, once its files are there (Session::abandon).
    if (o->session) o->session->abandon(/*discard_written=*/agent_lives || superseded);
    retireOwned(o, /*dispose_claim=*/false);
    if (!agent_lives && !superseded) given_up_results_[session_id] = {o->epoch, next_seq, steadyNowNs()};
    if (!written.empty() && (agent_lives || superseded)) {
        removeResultFiles(session_id, written, "gave it up, " + why);
        return;
    }
    if (!written.empty()) {
        std::fprintf(stderr,
                     "facescan-server: session %s: gave it up, %s; it had finished here meanwhile, and its files in %s "
                     "stay (its agent is gone: they may hold frames the new owner never gets)\n",
                     session_id.c_str(), why.c_str(), written.c_str());
        return;
    }
    if (agent_lives) keepCopyInCase(session_id, winner);
    if (o->session && o->session->finishing()) {
        // Its finish goes on until it would write: it writes nothing then, or, already writing, carries out the
        // rule above for written files itself (Session::abandon), and says which.
        std::fprintf(stderr, "facescan-server: session %s: gave it up, %s, while finishing it here\n",
                     session_id.c_str(), why.c_str());
        return;
    }
    std::fprintf(
        stderr, "facescan-server: session %s: gave it up, %s; nothing written for it here%s\n", session_id.c_str(),
        why.c_str(),
        integrated > 0 ? (" (the " + std::to_string(integrated) + " frames integrated here are dropped)").c_str() : "");
}

void Server::keepCopyInCase(const std::string& session_id, const OwnerView& winner) {
    // The new owner may have continued from an older copy than this server's (a standby that missed rounds), and
    // may die before its own copy reaches anyone: the frames between the two, which the agent dropped once this
    // server had them confirmed, then exist in this data dir only. So a recording's copy here is kept ready as a
    // restarted server keeps one (takeOverOrphans continues it if that owner fails too), until the scan finishes.
    const std::filesystem::path dir = params_.data_dir / session_id;
    std::error_code ec;
    if (!std::filesystem::exists(dir / "replica.log", ec)) return;
    std::string warning;
    auto copy = loadReplicaLog(dir, &warning);
    if (!copy.isOk() || copy->session_id != session_id || !copy->camera.every_frame) return;
    if (!copy->state.validate().isOk()) return;  // taken before the first frame: nothing to continue from
    uint32_t& held = held_elsewhere_[session_id];
    held = std::max(held, winner.data.epoch);
    resumable_[session_id] = std::move(*copy);
}

void Server::retireOwned(const std::shared_ptr<OwnedSession>& o, bool dispose_claim) {
    {
        std::lock_guard lk(sessions_mutex_);
        if (auto it = owned_.find(o->id); it != owned_.end() && it->second == o) owned_.erase(it);
    }
    o->phase = OwnedSession::Phase::kGivenUp;
    if (dispose_claim && o->claim) o->claim->release();
    // Its last status and mesh from here leave the writers' histories: a session given up (yielded, released for
    // want of frames, or unable to start) would otherwise stay listed on this server for as long as it runs, as a
    // stale "waiting for frames" or "scanning" beside the owner's own statuses.
    unlist(o->id);
    // Other threads may still hold the OwnedSession for a while (the replication thread, through a round that takes
    // seconds on a loaded machine): the retiring thread waits until it holds the last reference, so the endpoints
    // end there and in this order. It waits for as long as that takes: its claim and session, reset under a round
    // still using them, crashed a server. A holder that never lets go is a stuck server, which the retiring
    // thread's watchdog ends. No more frames for this session here (only this thread uses its reader).
    retireFrameReader(std::move(o->frames), std::exchange(o->frame_condition, 0));
    retirer_->retire([this, held = o]() mutable {
        retirer_->note("waiting for the other threads to let go of a session");
        while (held.use_count() > 1) std::this_thread::sleep_for(std::chrono::milliseconds(5));
        retirer_->note("deleting a session's claim writer");
        held->claim.reset();  // withdrawn (or released above)
        retirer_->note("stopping a session's worker");
        held->session.reset();  // its worker stops; joined here, never on itself
        held.reset();
    });
}

void Server::retireFrameReader(std::unique_ptr<wire::Reader<facescan_wire_RgbdFrame>> frames, dds_entity_t condition) {
    if (!frames) {
        if (condition > 0) (void)dds_waitset_detach(waitset_.handle(), condition);
        return;
    }
    // Not deleted while its agent may still write to it (service/lingering_reader.hpp): drained here, on the intake
    // thread, whenever data comes (its read condition stays on the intake's waitset), until no writer is matched;
    // then ended on the retiring thread. Drained here and not there: while the retiring thread waits in a deletion,
    // another lingering reader that it was to drain would fill, and that deletion would never end (a soak's
    // retiring thread hung so).
    lingering_frames_.push_back({std::move(frames), condition});
    lingering_count_ = static_cast<int>(lingering_frames_.size());
}

void Server::drainLingering() {
    for (auto it = lingering_frames_.begin(); it != lingering_frames_.end();) {
        if (!drainedAndUnwritten(it->reader->handle())) {
            ++it;
            continue;
        }
        if (it->condition > 0) (void)dds_waitset_detach(waitset_.handle(), it->condition);
        retirer_->retire(
            [reader = std::shared_ptr<wire::Reader<facescan_wire_RgbdFrame>>(std::move(it->reader)), this]() mutable {
                retirer_->note("deleting a frame reader that no writer writes to any more");
                reader.reset();
            });
        it = lingering_frames_.erase(it);
    }
    lingering_count_ = static_cast<int>(lingering_frames_.size());
}

void Server::endLingering() {
    // On shutdown: nothing is left to drain them, and the process is ending. Each is drained once more first.
    for (LingeringReader& l : lingering_frames_) (void)drainedAndUnwritten(l.reader->handle());
    lingering_frames_.clear();
    lingering_count_ = 0;
}

void Server::requestReplays() {
    for (const auto& o : ownedSessions()) {
        if (!o->ahead || !o->session || steadyNowNs() - o->last_replay_request_ns < kReplayRepeatNs) continue;
        o->ahead = false;
        o->last_replay_request_ns = steadyNowNs();
        const uint32_t next = o->session->nextSeq();
        o->claim->update([&](wire::SessionOwnerData& r) {
            r.resume_seq = next;
            ++r.replay_request;
        });
    }
}

void Server::releaseStale() {
    const int64_t first_frame_ns = static_cast<int64_t>(params_.first_frame_timeout_s * 1e9);
    for (const auto& o : ownedSessions()) {
        // A takeover from the first frame waits for as long as its agent lives: that agent streamed before, and its
        // writes may be held up by the old owner's reader until that one's lease lapses everywhere. Releasing it
        // would leave the scan with no owner. A new session that gets no frame is released (a flood of bogus
        // sessions must not hold places), and placed again while its agent lives.
        const bool agent_lives = agentLives(o->id);
        if (o->phase == OwnedSession::Phase::kReady && steadyNowNs() - o->ready_ns > first_frame_ns && o->session &&
            o->session->stats().frames_received == 0 && o->session->nextSeq() == 0 &&
            !(o->takeover_from_ns != 0 && agent_lives)) {
            std::fprintf(stderr, "facescan-server: session %s: released, no frame came within %.0f s\n", o->id.c_str(),
                         static_cast<double>(params_.first_frame_timeout_s));
            retireOwned(o, /*dispose_claim=*/true);
            continue;
        }
        if (o->phase != OwnedSession::Phase::kFinished && o->session && o->session->finished()) {
            // Done: its frames are no longer read, and the claim says FINISHED (standbys drop their copies).
            retireFrameReader(std::move(o->frames), std::exchange(o->frame_condition, 0));
            o->phase = OwnedSession::Phase::kFinished;
            // How far the scan got whole: a server that finished it too, unseen (cut off), compares
            // (resultSuperseded). A scan that lost frames on the way (a takeover from a copy older than what the
            // agent still held) says 0: it supersedes no other result, which may hold those frames.
            const SessionStats done = o->session->stats();
            const uint32_t last = done.frames_dropped == 0 ? done.next_seq : 0;
            o->claim->update([last](wire::SessionOwnerData& r) {
                r.state = wire::OwnerState::kFinished;
                r.resume_seq = last;
            });
        }
    }
}

void Server::loadResumable() {
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(params_.data_dir, ec)) {
        if (!entry.is_directory() || !std::filesystem::exists(entry.path() / "replica.log")) continue;
        if (std::filesystem::exists(entry.path() / "summary.json")) {
            removeReplicaLog(entry.path());  // finished after its last replica: nothing to resume
            continue;
        }
        std::string warning;
        auto replica = loadReplicaLog(entry.path(), &warning);
        if (!warning.empty()) std::fprintf(stderr, "facescan-server: %s\n", warning.c_str());
        if (!replica.isOk()) {
            std::fprintf(stderr, "facescan-server: cannot resume from %s: %s\n", entry.path().c_str(),
                         replica.status().message().c_str());
            continue;
        }
        if (!replica->state.validate().isOk()) {
            // Written before the first frame was integrated: nothing to continue from, and nothing was confirmed
            // from it (its agent still holds every frame).
            std::fprintf(stderr, "facescan-server: %s holds no frame yet: nothing to resume from it\n",
                         entry.path().c_str());
            continue;
        }
        std::fprintf(stderr, "facescan-server: found session %s in %s (frame %u, %u frames integrated)\n",
                     replica->session_id.c_str(), entry.path().c_str(), replica->next_seq,
                     replica->counters.frames_integrated);
        resumable_[replica->session_id] = std::move(*replica);
    }
}

}  // namespace facescan::service
