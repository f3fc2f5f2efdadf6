// The server's part in the cluster, on the intake thread: which new session to claim, when a claim has
// settled, when to give one up, when to take over from a dead owner or resume from the data dir. Every decision
// is a function of the view that DDS gives (announcements with liveliness, claims with EXCLUSIVE ownership and
// instance states); there is no protocol of our own beyond writing and reading those topics.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <set>
#include <thread>

#include "recon/parallel.hpp"
#include "service/finished_sessions.hpp"
#include "service/frame_load.hpp"
#include "service/replica_log.hpp"
#include "service/replication.hpp"
#include "service/server.hpp"
#include "service/session_store.hpp"
#include "service/takeover.hpp"

namespace facescan::service {
namespace {

constexpr int64_t kClaimBatchNs = 150'000'000;    // CameraInfos that arrive together are placed together
constexpr int64_t kFallbackNs = 2'000'000'000;    // a takeover: the next server in line claims after this per rank
constexpr int64_t kReplayRepeatNs = 300'000'000;  // at most this often a new request to resend frames

bool holding(wire::OwnerState s) {
    return s == wire::OwnerState::kClaiming || s == wire::OwnerState::kReady || s == wire::OwnerState::kActive;
}

}  // namespace

void Server::clusterTick() {
    int open = 0;
    for (const auto& o : ownedSessions()) open += o->phase != OwnedSession::Phase::kFinished ? 1 : 0;
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
    // Agents that are gone take their candidates with them.
    for (auto it = candidates_.begin(); it != candidates_.end();) {
        it = it->second.writer_alive ? std::next(it) : candidates_.erase(it);
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
            if (view->second.alive && holding(st)) eligible.push_back({id, c.order_key, view->second.data.owner_id});
            continue;
        }
        if (owned(id) || resumable_.count(id)) continue;
        if (refuseReusedId(id)) continue;
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
        const uint32_t epoch = before != owners.end() ? before->second.data.epoch + 1 : 1;
        if (const Status s = claimSession(e.session_id, epoch, o, previous); !s.isOk()) {
            std::fprintf(stderr, "facescan-server: cannot claim %s: %s\n", e.session_id.c_str(), s.toString().c_str());
        }
    }
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
        const bool beaten =
            view && view->alive && !ours && (view->data.owner_id != params_.server_id || view->data.epoch > o->epoch);
        // Our own claim, current, that reads as not alive: a weaker writer of the same instance (an old owner back
        // from a partition, which then withdraws) can leave readers with no live writer although ours still
        // writes. The agent would wait for a standby, and this server would never settle the claim. Writing it
        // again makes the instance alive for every reader; a stronger claim still wins on ownership strength.
        const bool unseen = view && !view->alive && !view->disposed && view->data.owner_id == params_.server_id &&
                            view->data.epoch == o->epoch && o->phase != OwnedSession::Phase::kFinished;
        if (unseen && viewFresh() && steadyNowNs() - o->last_reassert_ns >= lease_ns_ / 2) {
            o->last_reassert_ns = steadyNowNs();
            if (o->claim) o->claim->update([](wire::SessionOwnerData&) {}, /*force=*/true);
        }
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
    session->setWatch(watchdog_->add("the worker of session " + o.id), [this] { return !ownSessionsFree(); });
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
    o.restore_from.reset();  // the state lives in the session now
    std::fprintf(stderr, "facescan-server: owns session %s (epoch %u%s, %.0f ms after the claim)\n", o.id.c_str(),
                 o.epoch, next > 0 ? (", resuming at frame " + std::to_string(next)).c_str() : "",
                 static_cast<double>(steadyNowNs() - o.claimed_ns) * 1e-6);
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
    if (o->session) o->session->abandon();
    retireOwned(o, /*dispose_claim=*/false);
    unlist(session_id);
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
    std::fprintf(
        stderr, "facescan-server: session %s: gave it up, %s; nothing written for it here%s\n", session_id.c_str(),
        why.c_str(),
        integrated > 0 ? (" (the " + std::to_string(integrated) + " frames integrated here are dropped)").c_str() : "");
}

void Server::retireOwned(const std::shared_ptr<OwnedSession>& o, bool dispose_claim) {
    {
        std::lock_guard lk(sessions_mutex_);
        if (auto it = owned_.find(o->id); it != owned_.end() && it->second == o) owned_.erase(it);
    }
    o->phase = OwnedSession::Phase::kGivenUp;
    if (o->frame_condition > 0) (void)dds_waitset_detach(waitset_.handle(), o->frame_condition);
    o->frame_condition = 0;
    if (dispose_claim && o->claim) o->claim->release();
    // The replication thread may still hold the OwnedSession for a moment (it copies the list each turn): the
    // retiring thread waits until it holds the last reference, so the endpoints end there and in this order.
    retirer_->retire([held = o]() mutable {
        for (int i = 0; i < 1000 && held.use_count() > 1; ++i)
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        held->frames.reset();   // no more frames for this session here
        held->claim.reset();    // withdrawn (or released above)
        held->session.reset();  // its worker stops; joined here, never on itself
        held.reset();
    });
}

void Server::takeOverOrphans(const std::map<std::string, OwnerView>& owners) {
    // 1. Sessions whose owner is gone (its claim lapsed with its liveliness, or it is a dead process of this
    //    host) and that this server can continue: as their named standby, or from its own data dir after a
    //    restart. The new claim's epoch is higher, so it beats the old one even before that one lapses.
    for (const auto& [id, view] : owners) {
        if (view.disposed || !holding(view.data.state) || owned(id)) continue;
        // Gone: its claim lapsed with its liveliness. A server restarted on the dead owner's data dir need not wait
        // for the lease when the owner was an earlier process with its id, or a dead process of this host.
        const bool restart = resumable_.count(id) > 0;
        const bool stale_self = restart && view.data.owner_id == params_.server_id;
        const bool gone = !view.alive || stale_self || (restart && cluster_->diedOnThisHost(view.data.owner_id));
        if (!gone) {
            owner_gone_since_ns_.erase(id);
            continue;
        }
        const int64_t gone_since_ns = owner_gone_since_ns_.try_emplace(id, steadyNowNs()).first->second;
        if (!witnessed(id, steadyNowNs() - gone_since_ns)) continue;
        std::optional<wire::ReplicaData> standby;
        if (view.data.standby_id == params_.server_id) standby = replicator_->standbyCopy(id);
        const auto disk = resumable_.find(id);
        const TakeoverChoice choice = chooseTakeover(view.data, standby ? &*standby : nullptr,
                                                     disk != resumable_.end() ? &disk->second : nullptr);
        if (choice.kind == TakeoverChoice::Kind::kFromFirstFrame) {
            // Nobody holds a replica (the owner died before its first one reached a standby or its disk), and the
            // agent still keeps every frame from the first: the scan starts over from there and loses nothing.
            takeOverFromFirstFrame(id, view);
            continue;
        }
        if (choice.kind == TakeoverChoice::Kind::kRefuse) {
            if (refusals_logged_.insert(id + ":" + choice.why).second) {
                std::fprintf(stderr, "facescan-server: %s\n", choice.why.c_str());
            }
            continue;
        }
        if (choice.kind == TakeoverChoice::Kind::kWait) continue;  // a server that has its replica continues it
        std::optional<wire::ReplicaData> copy = *choice.copy;
        if (disk != resumable_.end()) resumable_.erase(disk);
        held_elsewhere_.erase(id);
        auto o = std::make_shared<OwnedSession>();
        // The takeover time runs from the old owner's last sign of life (an announcement or a replica).
        const int64_t heard =
            std::max(replicator_->lastHeardFrom(view.data.owner_id), cluster_->lastHeard(view.data.owner_id));
        o->takeover_from_ns = heard > 0 ? heard : steadyNowNs();
        const uint32_t epoch = choice.epoch;
        std::fprintf(
            stderr,
            "facescan-server: session %s: owner '%s' is gone; taking over at frame %u (epoch %u, %.0f ms after "
            "its last sign of life)\n",
            id.c_str(), view.data.owner_id.c_str(), copy->next_seq, epoch,
            static_cast<double>(steadyNowNs() - o->takeover_from_ns) * 1e-6);
        o->restore_from = std::move(copy);
        if (const Status s = claimSession(id, epoch, o, view.data); !s.isOk()) {
            std::fprintf(stderr, "facescan-server: cannot take over %s: %s\n", id.c_str(), s.toString().c_str());
        }
    }
    // 2. Replicas in the data dir of sessions with no claim left anywhere (their owner's lapsed long ago): resumed
    //    while their agent streams, or by a lone server whatever the agent does. Those that finished stay on disk. One
    //    that another live server continues is kept ready as well: if that server fails too before its own copy reached
    //    a standby, this copy is the only one left of the frames the agent has dropped (a restart of each server in
    //    turn lost them).
    for (auto it = resumable_.begin(); it != resumable_.end();) {
        const auto view = owners.find(it->first);
        const auto elsewhere = held_elsewhere_.find(it->first);
        if (view == owners.end() && cluster_->othersKnown() > 0) {
            // No claim in view, in a cluster. Right after the join the other servers' claims may still be on their
            // way: a resume then would compete with the scan's live owner. And once the agent is gone too, the
            // scan ended somewhere (finished there, its claim since retired) or cannot go on: resuming this copy
            // would write a second, partial result beside the real one. So only a scan whose agent still streams,
            // and only once the view had two leases to fill in, is resumed from the data dir.
            if (steadyNowNs() - joined_ns_ < 2 * lease_ns_) {
                ++it;
                continue;
            }
            if (!agentLives(it->first)) {
                std::fprintf(stderr,
                             "facescan-server: session %s: no server owns it and its agent is gone (it ended "
                             "elsewhere or cannot go on): the replica in %s stays as it is\n",
                             it->first.c_str(), params_.data_dir.c_str());
                held_elsewhere_.erase(it->first);
                it = resumable_.erase(it);
                continue;
            }
        }
        if (view == owners.end()) {
            auto o = std::make_shared<OwnedSession>();
            o->takeover_from_ns = steadyNowNs();
            // Above every epoch this session had, including those of the servers that continued it meanwhile.
            const uint32_t epoch =
                std::max(it->second.epoch, elsewhere != held_elsewhere_.end() ? elsewhere->second : 0u) + 1;
            held_elsewhere_.erase(it->first);
            std::fprintf(stderr, "facescan-server: session %s: resuming from %s at frame %u (epoch %u)\n",
                         it->first.c_str(), params_.data_dir.c_str(), it->second.next_seq, epoch);
            o->restore_from = std::move(it->second);
            wire::SessionOwnerData previous;
            previous.failovers = o->restore_from->counters.failovers;
            if (const Status s = claimSession(it->first, epoch, o, previous); !s.isOk()) {
                std::fprintf(stderr, "facescan-server: cannot resume %s: %s\n", it->first.c_str(),
                             s.toString().c_str());
            }
            it = resumable_.erase(it);
            continue;
        }
        if (!view->second.alive && !view->second.disposed && holding(view->second.data.state)) {
            ++it;  // its owner is gone: the takeover above decides (it may be waiting for its view to catch up)
            continue;
        }
        const wire::SessionOwnerData& claim = view->second.data;
        if (view->second.alive && holding(claim.state) && claim.owner_id != params_.server_id) {
            const bool first = elsewhere == held_elsewhere_.end();
            uint32_t& held_epoch = held_elsewhere_[it->first];
            held_epoch = std::max(held_epoch, claim.epoch);
            if (first) {
                std::fprintf(stderr,
                             "facescan-server: session %s is %s on server '%s': this server keeps its replica in %s "
                             "(frame %u) in case that one fails too\n",
                             it->first.c_str(), wire::ownerStateName(claim.state), claim.owner_id.c_str(),
                             params_.data_dir.c_str(), it->second.next_seq);
            }
            ++it;
            continue;
        }
        std::fprintf(stderr, "facescan-server: session %s is %s on server '%s': the replica in %s stays as it is\n",
                     it->first.c_str(), wire::ownerStateName(claim.state), claim.owner_id.c_str(),
                     params_.data_dir.c_str());
        held_elsewhere_.erase(it->first);
        it = resumable_.erase(it);
    }
}

bool Server::rejoining() {
    // A server that sees no other server and no agent any more, after it had seen other servers, is cut off from
    // the network. When it comes back, its view of the others' claims lags behind its view of the agents for a
    // moment: every owner still looks gone while the agents look alive again, and a takeover then would be a split.
    // So it takes nothing over and places nothing until it has re-observed the cluster for two leases after the
    // cut, as a server that was frozen does. (A server whose peers died keeps seeing its agents, and takes their
    // sessions over.)
    const int64_t now = steadyNowNs();
    const int others = cluster_->othersAlive();
    bool agents = false;
    for (const auto& [id, c] : candidates_) agents = agents || c.writer_alive;
    if (others > 0) had_peers_ = true;
    if (had_peers_ && others == 0 && !agents) {
        if (cut_off_since_ns_ == 0) cut_off_since_ns_ = now;
        rejoin_until_ns_ = now + 2 * lease_ns_;
    } else if (cut_off_since_ns_ != 0) {
        std::fprintf(stderr,
                     "facescan-server: this server saw no other server and no agent for %.1f s (cut off from the "
                     "network): re-observing the cluster for %.1f s before taking over or placing any session\n",
                     static_cast<double>(now - cut_off_since_ns_) * 1e-9,
                     static_cast<double>(rejoin_until_ns_ - now) * 1e-9);
        cut_off_since_ns_ = 0;
    }
    return now < rejoin_until_ns_;
}

bool Server::witnessed(const std::string& session_id, int64_t owner_gone_for_ns) const {
    // A server cut off from the network sees every other server and every agent go. A takeover on that view would
    // win when the network heals (its epoch is higher) over the owner that went on scanning, and would ask the
    // agent for frames that it dropped once that owner had them confirmed: the scan would stall for good. So a
    // takeover needs a witness that the owner, not this server, is the one gone: most of the servers this one knows
    // still in view (a server cut off never has that), or else the session's agent still heard half a lease after
    // the owner's claim lapsed. An agent's lease lapses later than a claim's (its participant goes only once
    // Cyclone has collected it, slower on a loaded machine); the wait is what a server cut off needs to see it go,
    // and what a cluster of two, where the survivor never has a majority, pays on every takeover.
    //
    // Losing every one of two or more other servers at once is, seen from inside, what a cut-off looks like (two
    // failures at the same moment are rare). The agent then goes from this server's view too, but Cyclone can
    // take seconds longer to notice it than the claim's lapse (in a chaos run a server cut off took a
    // session over 2.4 s after the owner's lapse, its agent still in view, and split the scan). So that case waits
    // two leases for the agent to go; a single lost peer (a cluster of two) keeps the short wait.
    if (cluster_->seesMajority()) return true;
    const bool lost_all = cluster_->othersAlive() == 0 && cluster_->othersKnown() >= 2;
    if (owner_gone_for_ns < (lost_all ? 2 * lease_ns_ : lease_ns_ / 2)) return false;
    return agentLives(session_id);
}

bool Server::agentLives(const std::string& session_id) const {
    const auto agent = candidates_.find(session_id);
    return agent != candidates_.end() && agent->second.writer_alive;
}

void Server::takeOverFromFirstFrame(const std::string& session_id, const OwnerView& view) {
    const auto c = candidates_.find(session_id);
    if (c == candidates_.end()) return;  // its agent is gone too: nothing to start from
    // One server takes it: its named standby while that one lives (its replica may be on the way), else the
    // first in claim order, and the next in line after kFallbackNs per rank.
    const int64_t now = steadyNowNs();
    const std::string& standby = view.data.standby_id;
    if (!standby.empty() && cluster_->serverAlive(standby)) {
        if (standby != params_.server_id) return;
    } else {
        const std::vector<std::string> order = claimOrder(session_id, cluster_->liveLoads());
        const auto me = std::find(order.begin(), order.end(), params_.server_id);
        if (me == order.end()) return;  // no room here
        const int64_t since = orphaned_since_ns_.try_emplace(session_id, now).first->second;
        if (now - since < static_cast<int64_t>(me - order.begin()) * kFallbackNs) return;
    }
    orphaned_since_ns_.erase(session_id);
    auto o = std::make_shared<OwnedSession>();
    o->camera = c->second.camera;
    o->camera_writer = c->second.writer;
    const int64_t heard = cluster_->lastHeard(view.data.owner_id);
    o->takeover_from_ns = heard > 0 ? heard : now;
    o->failovers_before = view.data.failovers;
    const uint32_t epoch = view.data.epoch + 1;
    std::fprintf(stderr,
                 "facescan-server: session %s: owner '%s' is gone and left no replica; its agent keeps every frame: "
                 "starting over from the first (epoch %u)\n",
                 session_id.c_str(), view.data.owner_id.c_str(), epoch);
    if (const Status s = claimSession(session_id, epoch, o, view.data); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: cannot take over %s: %s\n", session_id.c_str(), s.toString().c_str());
    }
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
            if (o->frame_condition > 0) (void)dds_waitset_detach(waitset_.handle(), o->frame_condition);
            o->frame_condition = 0;
            retirer_->retire([reader = std::shared_ptr<wire::Reader<facescan_wire_RgbdFrame>>(
                                  std::move(o->frames))]() mutable { reader.reset(); });
            o->phase = OwnedSession::Phase::kFinished;
            // How far the scan got: a server that finished it too, unseen (cut off), compares (resultSuperseded).
            const uint32_t last = o->session->nextSeq();
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
        std::fprintf(stderr, "facescan-server: found session %s in %s (frame %u, %u frames integrated)\n",
                     replica->session_id.c_str(), entry.path().c_str(), replica->next_seq,
                     replica->counters.frames_integrated);
        resumable_[replica->session_id] = std::move(*replica);
    }
}

}  // namespace facescan::service
