// Finished sessions leave the server's memory (finished_sessions.hpp): the status thread retires each one once it
// is done with, and its commands are answered from its files in the data dir from then on.

#include <set>

#include "service/server.hpp"

namespace facescan::service {

void Server::retireFinished(std::map<std::string, bool>& final_sent) {
    const int64_t now = steadyNowNs();
    std::set<std::string> owned_ids;
    bool retired = false;
    std::vector<std::shared_ptr<OwnedSession>> all = ownedSessions();
    std::vector<std::shared_ptr<OwnedSession>> gone;
    for (const std::shared_ptr<OwnedSession>& o : all) {
        owned_ids.insert(o->id);
        // Done with: the intake no longer reads its frames and its claim says FINISHED (releaseStale), its files
        // are written (finalize does that before the session reports finished) and its final status went out.
        const auto sent = final_sent.find(o->id);
        if (o->phase != OwnedSession::Phase::kFinished || !o->session || sent == final_sent.end() || !sent->second) {
            continue;
        }
        Session& session = *o->session;
        // The final mesh as the last snapshot, unless the snapshot thread sent it already: the snapshot writer keeps
        // it (durable) for late subscribers while the session is listed.
        if (auto fin = session.takeFinalSnapshot()) publishSnapshot(o->id, *fin);
        FinishedSession f;
        f.stats = session.stats();
        f.dir = session.filesDir();
        if (auto mesh = session.mesh(); mesh.isOk()) {
            f.vertex_count = mesh->vertex_count;
            f.triangle_count = mesh->triangle_count;
        }
        f.claim = o->claim;
        f.retired_ns = now;
        {
            std::lock_guard lk(sessions_mutex_);
            const auto it = owned_.find(o->id);
            if (it == owned_.end() || it->second != o) continue;  // given up meanwhile (yield)
            finished_.add(std::move(f));
            owned_.erase(it);
        }
        owned_ids.erase(o->id);
        gone.push_back(o);
        retired = true;
    }
    std::erase_if(final_sent, [&](const auto& entry) { return !owned_ids.count(entry.first); });
    all.clear();
    for (FinishedSession& f : finished_.expire(now)) forgetFinished(f);
    // An erased scan (service/erasure.hpp) is not kept listed, whichever came first, its retirement or the erasure.
    for (const SessionStats& s : finished_.stats()) {
        if (!isErased(params_.data_dir, s.session_id)) continue;
        if (auto f = finished_.remove(s.session_id)) forgetFinished(*f);
    }
    if (!retired) return;
    // The retired sessions leave memory on the retiring thread, in the order of everything else given up there, and
    // never on a session's own worker (a Session's destructor joins its worker). The retirer trims the heap once
    // its queue is drained (retirer.cpp): without the trim the server's resident memory grew by tens of megabytes
    // a scan although the bytes in use stayed flat.
    retirer_->retire([gone = std::move(gone)]() mutable { gone.clear(); });
}

void Server::forgetFinished(FinishedSession& f) {
    unlist(f.stats.session_id);
    // Its claim's writer ends on the retiring thread, as every endpoint does: deleting a DDS entity can wait on
    // Cyclone's garbage collector (retirer.hpp), and the threads that forget records publish statuses (the status
    // thread) or make the cluster's decisions (the intake).
    if (f.claim) retirer_->retire([claim = std::move(f.claim)]() mutable { claim.reset(); });
}

bool Server::resultSuperseded(const OwnerView& view, uint32_t epoch, uint32_t next_seq) const {
    // The reader holds the strongest claim's record (EXCLUSIVE ownership: a later epoch, or the tie-break within
    // one), so another server's record at this epoch or later is the claim that the agent and the clients follow.
    // Its FINISHED record says how far its scan got (resume_seq); with fewer frames than this one had, these files
    // may hold the only whole scan, and they stay.
    const wire::SessionOwnerData& d = view.data;
    return d.owner_id != params_.server_id && d.state == wire::OwnerState::kFinished && d.epoch >= epoch &&
           d.resume_seq >= next_seq;
}

void Server::dropSupersededResults(const std::map<std::string, OwnerView>& owners) {
    // On the intake thread, every turn: the records are checked where they lie, not copied out first.
    std::vector<std::pair<std::string, wire::SessionOwnerData>> fuller;
    std::vector<FinishedSession> superseded = finished_.removeIf([&](const SessionStats& s) {
        const auto it = owners.find(s.session_id);
        if (it == owners.end()) return false;
        if (holdsFullerResult(it->second, s)) fuller.emplace_back(s.session_id, it->second.data);
        return resultSuperseded(it->second, s.epoch, s.next_seq);
    });
    for (FinishedSession& f : superseded) {
        const SessionStats& s = f.stats;
        const wire::SessionOwnerData& winner = owners.at(s.session_id).data;
        forgetFinished(f);
        removeResultFiles(s.session_id, f.dir,
                          "server '" + winner.owner_id + "' finished it too (epoch " + std::to_string(winner.epoch) +
                              ", " + std::to_string(winner.resume_seq) + " frames; this server's epoch " +
                              std::to_string(s.epoch) + ", " + std::to_string(s.next_seq) + " frames)");
        // The claim (FINISHED, this epoch) goes with the record without disposing: the winner's stays.
    }
    for (const auto& [session_id, winner] : fuller) claimFullerResult(session_id, winner);
    // Results of sessions given up (yield): written before the yield, or by a finish that was under way then.
    constexpr int64_t kWatchGivenUpNs = 600'000'000'000;  // a winner that has not finished by then is not waited for
    for (auto it = given_up_results_.begin(); it != given_up_results_.end();) {
        const auto view = owners.find(it->first);
        if (steadyNowNs() - it->second.since_ns > kWatchGivenUpNs) {
            it = given_up_results_.erase(it);
            continue;
        }
        if (view == owners.end() || !resultSuperseded(view->second, it->second.epoch, it->second.next_seq)) {
            ++it;
            continue;
        }
        const auto dir = findFinishedSessionDir(params_.data_dir, it->first, params_.server_id);
        if (!dir) {
            ++it;  // a finish may still be writing it
            continue;
        }
        const wire::SessionOwnerData& winner = view->second.data;
        removeResultFiles(it->first, *dir,
                          "server '" + winner.owner_id + "' finished it too (epoch " + std::to_string(winner.epoch) +
                              ", " + std::to_string(winner.resume_seq) + " frames; this server gave it up at epoch " +
                              std::to_string(it->second.epoch) + " with " + std::to_string(it->second.next_seq) +
                              " frames)");
        it = given_up_results_.erase(it);
    }
}

bool Server::holdsFullerResult(const OwnerView& view, const SessionStats& mine) const {
    // Another server finished the scan at a later epoch with fewer frames than this one did whole: it took the scan
    // over from a copy while this server, cut off from it, went on receiving every frame, and the agent left before
    // it could resend the rest. Its claim is the strongest, so clients follow its partial result, and it never sees
    // this server's FINISHED claim (EXCLUSIVE ownership hides the weaker one) to give way.
    const wire::SessionOwnerData& d = view.data;
    return d.owner_id != params_.server_id && d.state == wire::OwnerState::kFinished && d.epoch > mine.epoch &&
           d.resume_seq < mine.next_seq && mine.frames_dropped == 0;
}

void Server::claimFullerResult(const std::string& session_id, const wire::SessionOwnerData& winner) {
    const std::optional<FinishedSession> record = finished_.find(session_id);
    if (!record || record->dir.empty() || !std::filesystem::exists(record->dir / "summary.json")) return;
    // Claimed again, above the other server's epoch: that server sees a FINISHED claim with every frame it had and
    // removes its partial result (resultSuperseded), and clients follow this one.
    wire::SessionOwnerData data;
    data.session_id = session_id;
    data.owner_id = params_.server_id;
    data.epoch = winner.epoch + 1;
    data.state = wire::OwnerState::kFinished;
    data.resume_seq = data.confirmed_seq = record->stats.next_seq;
    data.failovers = winner.failovers;
    auto claim = cluster_->claim(data);
    if (!claim.isOk()) {
        std::fprintf(stderr, "facescan-server: session %s: cannot claim its fuller result again: %s\n",
                     session_id.c_str(), claim.status().toString().c_str());
        return;
    }
    if (!finished_.replaceClaim(session_id, std::move(*claim), data.epoch)) return;
    std::fprintf(stderr,
                 "facescan-server: session %s: server '%s' finished it too at epoch %u with %u frames, fewer than the "
                 "%u this server finished it with (%s): claiming it again at epoch %u, so that the whole result is "
                 "the one kept\n",
                 session_id.c_str(), winner.owner_id.c_str(), winner.epoch, winner.resume_seq, record->stats.next_seq,
                 record->dir.c_str(), data.epoch);
}

bool Server::holdsFullerSession(const OwnedSession& o, const OwnerView& view) const {
    // Two claims at one epoch: the ownership strength breaks the tie (the epoch, then a hash of server and session),
    // not what each holds. A server whose view missed this one's claim (cut off from it when the scan was placed,
    // or its view of the claims lagging after a cut) placed the scan too, from the first frame; when the cut heals,
    // its claim may win the tie although this server has meanwhile confirmed frames that the agent then dropped.
    // Yielding would lose them for good: the winner starts before them, and nobody can send them any more (a
    // recording in the chaos soak lost 71 frames so).
    const wire::SessionOwnerData& d = view.data;
    if (d.owner_id == params_.server_id || d.epoch != o.epoch || d.state == wire::OwnerState::kFinished ||
        d.state == wire::OwnerState::kReleased) {
        return false;
    }
    if (o.phase != OwnedSession::Phase::kActive || !o.session || o.session->finished() || !o.claim) return false;
    const uint32_t confirmed_here = o.claim->record().confirmed_seq;
    // After a pause this server's own view is what is in doubt: it yields as before.
    return confirmed_here > std::max(d.confirmed_seq, d.resume_seq) && viewFresh() && ownSessionsFree();
}

void Server::claimFullerSession(OwnedSession& o, const wire::SessionOwnerData& winner) {
    const uint32_t epoch = o.epoch + 1;
    const uint32_t confirmed_here = o.claim->record().confirmed_seq;
    const uint32_t resume_seq = o.session->nextSeq();
    auto old = cluster_->raise(*o.claim, epoch, resume_seq);
    if (!old.isOk()) {
        sayOnce("session " + o.id + ": cannot raise its claim above server '" + winner.owner_id +
                "' (which holds fewer of its frames): " + old.status().toString());
        return;
    }
    o.epoch = epoch;
    o.session->setOwnership(params_.server_id, epoch);
    retirer_->retire(
        [writer = std::make_shared<wire::Writer<facescan_wire_SessionOwner>>(std::move(*old)), this]() mutable {
            retirer_->note("deleting a claim's writer of an earlier epoch");
            writer.reset();
        });
    std::fprintf(
        stderr,
        "facescan-server: session %s: server '%s' claimed it too at epoch %u, with frames confirmed up to %u "
        "only; this server confirmed them up to %u, and its agent may have dropped those: claiming it again at "
        "epoch %u and going on from frame %u (the other server gives it up)\n",
        o.id.c_str(), winner.owner_id.c_str(), winner.epoch, std::max(winner.confirmed_seq, winner.resume_seq),
        confirmed_here, epoch, resume_seq);
}

void Server::removeResultFiles(const std::string& session_id, const std::filesystem::path& dir,
                               const std::string& why) {
    if (dir.empty()) return;
    retirer_->retire([dir] {
        std::error_code ec;
        std::filesystem::remove_all(dir, ec);
    });
    std::fprintf(stderr,
                 "facescan-server: session %s: %s; it had finished here meanwhile: the files written for it in %s are "
                 "removed (one result a scan: the new owner's, which its agent and clients follow)\n",
                 session_id.c_str(), why.c_str(), dir.c_str());
}

void Server::unlist(const std::string& session_id) {
    // Its last status and mesh from this server leave the writers' histories: late subscribers no longer get them,
    // and `facescan sessions` no longer shows this server's last word on it (after a yield, a stale one: the new
    // owner's statuses say where the scan is).
    wire::ScanStatusData key;
    key.session_id = session_id;
    (void)status_writer_->unregister(wire::toMessage(key));
    facescan_wire_MeshSnapshot snap{};
    snap.session_id = wire::stringView(session_id);
    (void)snapshot_writer_->unregister(snap);
}

bool Server::answersFromFiles(const std::string& session_id) const {
    return finished_.find(session_id) || findFinishedSessionDir(params_.data_dir, session_id, params_.server_id);
}

bool Server::answerFromFiles(const Command& c) {
    const std::optional<FinishedSession> record = finished_.find(c.session_id);
    std::filesystem::path dir;
    if (record) {
        dir = record->dir;
    } else if (auto found = findFinishedSessionDir(params_.data_dir, c.session_id, params_.server_id)) {
        dir = *found;
    } else {
        return false;
    }
    const std::string& id = c.session_id;
    const auto kind = static_cast<facescan_wire_CommandKind>(c.kind);
    if (kind == facescan_wire_CMD_RESET) {
        reply(c, invalidArgument("session '" + id + "' is finished: nothing to reset"));
        return true;
    }
    if (kind == facescan_wire_CMD_GET_STATUS) {
        reply(c, Status::ok());
        return true;
    }
    if (dir.empty()) {
        reply(c, unavailable("session '" + id + "' finished without its files: " + record->stats.detail));
        return true;
    }
    switch (kind) {
        case facescan_wire_CMD_FINISH: {
            MeshResult counts;
            if (record) {
                counts.vertex_count = record->vertex_count;
                counts.triangle_count = record->triangle_count;
            } else if (auto m = readFinishedMesh(dir); m.isOk()) {
                counts.vertex_count = m->vertex_count;
                counts.triangle_count = m->triangle_count;
            }
            reply(c, Status::ok(), &counts);
            break;
        }
        case facescan_wire_CMD_GET_MESH: {
            if (c.want_texture && answerTextured(c, dir)) break;
            auto m = readFinishedMesh(dir);
            if (!m.isOk()) {
                reply(c, m.status());
            } else {
                reply(c, Status::ok(), &*m, m->draco.get());
            }
            break;
        }
        case facescan_wire_CMD_GET_TRAJECTORY:
        case facescan_wire_CMD_GET_PREVIEW: {
            const bool trajectory = kind == facescan_wire_CMD_GET_TRAJECTORY;
            auto bytes = readFinishedFile(dir, trajectory ? "trajectory.txt" : "preview.png");
            if (!bytes.isOk()) {
                reply(c, trajectory ? bytes.status()
                                    : notFound("session '" + id + "' finished without a preview (" +
                                               bytes.status().message() + ")"));
            } else {
                reply(c, Status::ok(), nullptr, &*bytes);
            }
            break;
        }
        default: reply(c, Status::ok()); break;
    }
    return true;
}

bool Server::answerTextured(const Command& c, const std::filesystem::path& dir) {
    if (dir.empty()) return false;  // still scanning, or finished without its files
    auto textured = readFinishedTexture(dir);
    if (!textured.isOk()) {
        // A damaged textured.drc is the server's problem, not the client's: it still gets the vertex-coloured model.
        if (textured.status().code() != StatusCode::kNotFound) {
            std::fprintf(stderr, "facescan-server: session %s: the texture is not sent: %s\n", c.session_id.c_str(),
                         textured.status().toString().c_str());
        }
        return false;
    }
    reply(c, Status::ok(), &textured->mesh, textured->mesh.draco.get(), &textured->png);
    return true;
}

}  // namespace facescan::service
