// The server's part in a takeover, on the intake thread: which dead owner's session to continue (as its standby,
// from its own data dir, or from the agent's first frame), whether the view is trustworthy enough to do so (a
// server back from a cut-off, a takeover witnessed by most servers or by the agent), and which server goes first.
// The decision for one session from its copies is takeover.hpp; this is where the cluster's view comes in.
#include <algorithm>
#include <cstdio>
#include <set>

#include "service/replica_log.hpp"
#include "service/replication.hpp"
#include "service/server.hpp"
#include "service/session_store.hpp"
#include "service/takeover.hpp"

namespace facescan::service {
namespace {

constexpr int64_t kFallbackNs = 2'000'000'000;  // a takeover: the next server in line claims after this per rank

}  // namespace

void Server::takeOverOrphans(const std::map<std::string, OwnerView>& owners) {
    // What the loop below remembers of a session whose claim is gone, withdrawn or done goes with it: a server that
    // runs for months sees hundreds of thousands of sessions.
    const auto held = [&](const auto& entry) {
        const auto view = owners.find(entry.first);
        return view != owners.end() && !view->second.disposed && holdsSession(view->second.data.state);
    };
    std::erase_if(owner_gone_since_ns_, [&](const auto& entry) { return !held(entry); });
    std::erase_if(owner_back_since_ns_, [&](const auto& entry) { return !held(entry); });
    std::erase_if(orphaned_since_ns_, [&](const auto& entry) { return !held(entry); });
    // 1. Sessions whose owner is gone (its claim lapsed with its liveliness, or it is a dead process of this
    //    host) and that this server can continue: as their named standby, or from its own data dir after a
    //    restart. The new claim's epoch is higher, so it beats the old one even before that one lapses.
    for (const auto& [id, view] : owners) {
        if (view.disposed || !holdsSession(view.data.state) || owned(id)) continue;
        // Gone: its claim lapsed with its liveliness. A server restarted on the dead owner's data dir need not wait
        // for the lease when the owner was an earlier process with its id, or a dead process of this host. Nor need
        // any server once the owner's id is announced by a new process alone: the owner was restarted, and the
        // process that holds the claim is dead (on a loaded machine its lease lapsed seconds after the restart,
        // and the live scans stalled that long).
        const bool restart = resumable_.count(id) > 0;
        const bool stale_self = restart && view.data.owner_id == params_.server_id;
        const bool replaced = cluster_->replaced(view.data.owner_id, view.data.owner_incarnation);
        const bool known_dead = stale_self || replaced;
        const bool gone = !view.alive || known_dead || (restart && cluster_->diedOnThisHost(view.data.owner_id));
        if (!gone) {
            owner_gone_since_ns_.erase(id);
            owner_back_since_ns_.erase(id);
            continue;
        }
        const int64_t gone_since_ns = owner_gone_since_ns_.try_emplace(id, steadyNowNs()).first->second;
        if (!witnessed(id, gone_since_ns)) continue;
        if (stale_self && !view.data.standby_id.empty() && view.data.standby_id != params_.server_id &&
            cluster_->serverAlive(view.data.standby_id) && steadyNowNs() - gone_since_ns < lease_ns_) {
            // Restarted before the owner's lease lapsed: its live standby takes the scan over (it has a copy as
            // fresh as the one on disk, and its view of the cluster is not seconds old). Both at once claimed the
            // same epoch, and the one that lost the tie had started the scan for nothing. This copy is the
            // fallback, for a standby that does not take it within a lease.
            continue;
        }
        if (!known_dead && agentStillServed(id, view.data.epoch)) {
            // Witnessed, and yet the agent, heard from within the lease, still streams to that owner (or to a newer
            // one). The witnesses can be wrong for a moment: when a cut between the servers heals, the other
            // servers' announcements arrive before the owner's claim is rediscovered, and a takeover then took a
            // live scan from its owner. The agent tells at once when its owner stops serving. (Not when the owner is
            // known dead: its agent streams on to it until the claim lapses in its own eyes.)
            sayOnce("session " + id + ": owner '" + view.data.owner_id +
                    "' looks gone here, but its agent still streams to it: nothing is taken over");
            continue;
        }
        // An owner heard again after its claim lapsed here is alive: the scan waits up to a lease for its claim to
        // come back, a recording and a live scan alike (ownerHeardAgain says why).
        if (!known_dead && ownerHeardAgain(id, view.data.owner_id, gone_since_ns)) continue;
        std::optional<wire::ReplicaData> standby;
        if (view.data.standby_id == params_.server_id) standby = replicator_->standbyCopy(id);
        const auto disk = resumable_.find(id);
        const auto candidate = candidates_.find(id);
        // Live or a recording: the agent says so itself when it is in view; the copies only otherwise.
        const bool live = candidate != candidates_.end()
                              ? !candidate->second.camera.every_frame
                              : (standby && !standby->camera.every_frame) ||
                                    (disk != resumable_.end() && !disk->second.camera.every_frame);
        // The agent's own account counts as much as the claim's: it may have followed a newer owner than this
        // view shows, or dropped frames that an owner confirmed after the last claim this server saw.
        wire::SessionOwnerData last = view.data;
        if (candidate != candidates_.end()) {
            const wire::CameraInfoData& agent = candidate->second.camera;
            if (agent.followed_epoch > last.epoch) {
                const std::string why = "session " + id + ": its agent followed an owner at epoch " +
                                        std::to_string(agent.followed_epoch) + ", later than the last claim seen ('" +
                                        last.owner_id + "', epoch " + std::to_string(last.epoch) +
                                        "): this server's view is behind; it takes nothing over until it catches up";
                sayOnce(why);
                continue;
            }
            last.confirmed_seq = std::max(last.confirmed_seq, agent.dropped_before_seq);
        } else if (const auto left = gone_agents_dropped_before_.find(id); left != gone_agents_dropped_before_.end()) {
            // The agent left after dropping these frames (its owner had them confirmed, perhaps on its disk alone
            // behind a cut): a copy without them would be finished as a partial scan, and a second result beside
            // the owner's whole one when that owner finished it unseen.
            last.confirmed_seq = std::max(last.confirmed_seq, left->second);
        }
        const TakeoverChoice choice = chooseTakeover(last, standby ? &*standby : nullptr,
                                                     disk != resumable_.end() ? &disk->second : nullptr, live);
        if (choice.kind == TakeoverChoice::Kind::kFromFirstFrame) {
            // Nobody holds a replica (the owner died before its first one reached a standby or its disk), and the
            // agent still keeps every frame from the first: the scan starts over from there and loses nothing. A
            // live scan starts over from the frames that come now.
            takeOverFromFirstFrame(id, view);
            continue;
        }
        if (choice.kind == TakeoverChoice::Kind::kRefuse) {
            sayOnce(choice.why);
            continue;
        }
        if (choice.kind == TakeoverChoice::Kind::kWait) continue;  // a server that has its replica continues it
        std::optional<wire::ReplicaData> copy = *choice.copy;
        if (disk != resumable_.end()) resumable_.erase(disk);
        held_elsewhere_.erase(id);
        auto o = std::make_shared<OwnedSession>();
        // The takeover time runs from the old owner's last sign of life (an announcement or a replica); of the old
        // process, when a new one has its id.
        const int64_t heard = replaced ? cluster_->lastHeard(view.data.owner_id, view.data.owner_incarnation)
                                       : std::max(replicator_->lastHeardFrom(view.data.owner_id),
                                                  cluster_->lastHeard(view.data.owner_id));
        o->takeover_from_ns = heard > 0 ? heard : steadyNowNs();
        const uint32_t epoch = choice.epoch;
        std::fprintf(
            stderr,
            "facescan-server: session %s: owner '%s' is gone; taking over at frame %u (epoch %u, %.0f ms after "
            "its last sign of life, %.0f ms after its claim lapsed here)\n",
            id.c_str(), view.data.owner_id.c_str(), copy->next_seq, epoch,
            static_cast<double>(steadyNowNs() - o->takeover_from_ns) * 1e-6,
            static_cast<double>(steadyNowNs() - gone_since_ns) * 1e-6);
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
        auto view = owners.find(it->first);
        const auto elsewhere = held_elsewhere_.find(it->first);
        // A claim released (its server could not start the scan, or no frame came) holds nothing: this copy may be
        // what the scan continues from, above the released claim's epoch.
        const uint32_t released_epoch = view != owners.end() && view->second.data.state == wire::OwnerState::kReleased
                                            ? view->second.data.epoch
                                            : 0u;
        if (released_epoch > 0) view = owners.end();
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
            // The agent's account (the message's comment): the frames it dropped must all be in this copy.
            const auto agent = candidates_.find(it->first);
            const uint32_t followed = agent != candidates_.end() ? agent->second.camera.followed_epoch : 0u;
            const uint32_t dropped = agent != candidates_.end() ? agent->second.camera.dropped_before_seq : 0u;
            if (it->second.camera.every_frame && it->second.next_seq < dropped) {
                const std::string why = "session " + it->first + ": the replica in " + params_.data_dir.string() +
                                        " ends at frame " + std::to_string(it->second.next_seq) +
                                        " and the agent holds frames only from " + std::to_string(dropped) +
                                        " on: frames between exist on another server; not resuming from this copy";
                sayOnce(why);
                ++it;
                continue;
            }
            auto o = std::make_shared<OwnedSession>();
            o->takeover_from_ns = steadyNowNs();
            // Above every epoch this session had, including those of the servers that continued it meanwhile.
            const uint32_t epoch =
                std::max({it->second.epoch, elsewhere != held_elsewhere_.end() ? elsewhere->second : 0u, followed,
                          released_epoch}) +
                1;
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
        if (!view->second.alive && !view->second.disposed && holdsSession(view->second.data.state)) {
            ++it;  // its owner is gone: the takeover above decides (it may be waiting for its view to catch up)
            continue;
        }
        const wire::SessionOwnerData& claim = view->second.data;
        if (view->second.alive && holdsSession(claim.state) && claim.owner_id != params_.server_id) {
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
        if (resultSuperseded(view->second, it->second.epoch, it->second.next_seq)) {
            // Finished elsewhere with every frame this copy holds: the copy (and whatever an interrupted finish
            // wrote beside it here) is a second, partial scan of the person that nothing will ever read.
            removeCopy(params_.data_dir / it->first);
            std::fprintf(stderr,
                         "facescan-server: session %s is finished on server '%s' with every frame of the copy here: "
                         "the copy in %s is removed\n",
                         it->first.c_str(), claim.owner_id.c_str(), params_.data_dir.c_str());
        } else {
            std::fprintf(stderr, "facescan-server: session %s is %s on server '%s': the replica in %s stays as it is\n",
                         it->first.c_str(), wire::ownerStateName(claim.state), claim.owner_id.c_str(),
                         params_.data_dir.c_str());
        }
        held_elsewhere_.erase(it->first);
        it = resumable_.erase(it);
    }
}

void Server::removeCopy(const std::filesystem::path& dir) {
    // Only the files of the copy: a folder beside them holds another result (a server's own, written beside
    // another owner's files) and stays.
    retirer_->retire([dir] {
        std::error_code ec;
        std::vector<std::filesystem::path> files;
        for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
            if (entry.is_regular_file(ec)) files.push_back(entry.path());
        }
        for (const auto& f : files) std::filesystem::remove(f, ec);
        std::filesystem::remove(dir, ec);  // only when empty
    });
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
    // Agents heard from, not merely alive: Cyclone keeps a writer alive until the lease of its participant lapses,
    // which on a loaded machine came seconds after the peers' (every agent repeats its CameraInfo each second).
    bool agents = false;
    for (const auto& [id, c] : candidates_) agents = agents || (c.writer_alive && now - c.heard_ns < lease_ns_);
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

bool Server::witnessed(const std::string& session_id, int64_t owner_gone_since_ns) const {
    // A server cut off from the network sees every other server and every agent go. A takeover on that view would
    // win when the network heals (its epoch is higher) over the owner that went on scanning, and would ask the
    // agent for frames that it dropped once that owner had them confirmed: the scan would stall for good. So a
    // takeover needs a witness that the owner, not this server, is the one gone: most of the servers this one knows
    // heard from since the owner's claim lapsed (a server cut off never has that), or else the session's agent
    // still in view half a lease after the lapse. An agent's lease lapses later than a claim's (its participant goes
    // only once Cyclone has collected it, slower on a loaded machine); the wait is what a server cut off needs to
    // see it go, and what a cluster of two, where the survivor never has a majority, pays on every takeover.
    //
    // Heard, not merely alive: the peers' leases lapse one by one in the eyes of a server cut off, the owner's first
    // as often as not, and in the moment between the two the others still look alive. A takeover then split scans
    // in chaos runs, and worse, was made on the claim as it stood when the cut began: frames the owner had
    // confirmed since (the agent dropped them) were nowhere in the new owner's reach. An announcement that arrived
    // after the lapse proves that the network still carries that peer's messages; every server announces at least
    // four times a second, so this costs a takeover about that much.
    //
    // Losing every one of two or more other servers at once is, seen from inside, what a cut-off looks like (two
    // failures at the same moment are rare). The agent then goes from this server's view too, but Cyclone can
    // take seconds longer to notice it than the claim's lapse. So that case waits two leases for the agent to go;
    // a single lost peer (a cluster of two) keeps the short wait.
    const int known = 1 + cluster_->othersKnown();
    const int heard = 1 + cluster_->othersHeardSince(owner_gone_since_ns);
    if (2 * heard > known) return true;
    const bool lost_all = heard == 1 && known >= 3;
    const int64_t gone_for_ns = steadyNowNs() - owner_gone_since_ns;
    if (gone_for_ns < (lost_all ? 2 * lease_ns_ : lease_ns_ / 2)) return false;
    // Heard from since the lapse, not merely alive: an agent's writer stays alive in the view of a server cut off
    // until its participant's lease lapses there, which under load came after this wait, and a server cut off took
    // over a scan that its owner went on to finish (a split). Its CameraInfo, repeated every second, proves the path.
    if (!agentHeardSince(session_id, owner_gone_since_ns)) return false;
    // And the agent no longer sees an owner serve the scan: one that does is on the other side of a cut between the
    // servers, alive, and this server, cut from it, would take its scan away (chaos soaks: a server cut from the
    // other servers but not from the agents took their live scans over, and a recording lost the frames its owner
    // confirmed meanwhile).
    return candidates_.at(session_id).camera.serving_epoch == 0;
}

bool Server::ownerHeardAgain(const std::string& session_id, const std::string& owner_id, int64_t gone_since_ns) {
    // The owner announced itself after its claim lapsed here: it is alive (woken from a freeze, back from a cut, or
    // its DDS threads were starved), and its claim reads alive again once it writes it. A scan taken over now would
    // be taken from a live owner on the strength of the owner's own sign of life, so the takeover waits a lease for
    // the claim to come back. An owner heard for that long whose claim stays lapsed cannot write it: taken over as
    // before.
    // - A recording: in a 30-minute chaos soak a standby took two recordings over 1 ms after it heard their owner,
    //   woken from a 9 s freeze, and both servers finished them.
    // - A live scan whose agent is gone is being finished by its owner: a takeover replaced the owner's whole result
    //   with one from an older copy.
    // - A live scan whose agent streams: the new owner goes on from its copy, and the frames since that copy are
    //   gone for good (a live agent keeps none), all of them when the owner had no copy out yet. On a loaded CI
    //   machine two owners' claims lapsed at once while both still announced themselves, and their standby took
    //   three live scans over: one went on from a copy 76 frames old, one started over and ended with 3 frames.
    //   The wait stalls the scan by a lease at most: the agent streams to nobody while no claim is alive, whether
    //   the old owner's comes back or a new one is made.
    const int64_t now = steadyNowNs();
    if (cluster_->lastHeard(owner_id) <= gone_since_ns) {
        owner_back_since_ns_.erase(session_id);
        return false;
    }
    const int64_t back = owner_back_since_ns_.try_emplace(session_id, now).first->second;
    if (now - back >= lease_ns_) return false;
    sayOnce("session " + session_id + ": owner '" + owner_id +
            "' was heard again after its claim lapsed here: waiting up to a lease for its claim before taking over");
    return true;
}

bool Server::agentLives(const std::string& session_id) const {
    const auto agent = candidates_.find(session_id);
    return agent != candidates_.end() && agent->second.writer_alive;
}

bool Server::agentStillServed(const std::string& session_id, uint32_t epoch) const {
    const auto agent = candidates_.find(session_id);
    return agent != candidates_.end() && agent->second.writer_alive &&
           steadyNowNs() - agent->second.heard_ns < lease_ns_ && agent->second.camera.serving_epoch >= epoch;
}

bool Server::agentHeardSince(const std::string& session_id, int64_t since_ns) const {
    const auto agent = candidates_.find(session_id);
    return agent != candidates_.end() && agent->second.writer_alive && agent->second.heard_ns >= since_ns;
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
    std::fprintf(stderr, "facescan-server: session %s: owner '%s' is gone and left no replica; %s (epoch %u)\n",
                 session_id.c_str(), view.data.owner_id.c_str(),
                 c->second.camera.every_frame ? "its agent keeps every frame: starting over from the first"
                                              : "a live scan: starting over from the frames that come now",
                 epoch);
    if (const Status s = claimSession(session_id, epoch, o, view.data); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: cannot take over %s: %s\n", session_id.c_str(), s.toString().c_str());
    }
}

}  // namespace facescan::service
