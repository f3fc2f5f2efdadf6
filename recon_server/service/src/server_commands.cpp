// The server's commands (facescan CLI and viewer requests): taken on the intake thread, where the view of the cluster
// says which server answers each (only the owner answers for a session it holds; a retired one answers from its
// files; the cluster's responder answers for sessions nobody owns), then run one at a time on the command thread,
// so that a slow answer (a finish, a mesh) never holds the intake.
#include <cstdio>
#include <deque>
#include <string>
#include <vector>

#include "recon/parallel.hpp"
#include "service/server.hpp"

namespace facescan::service {

void Server::takeCommands() {
    std::vector<Command> got;
    auto n = command_reader_->take([&](const facescan_wire_ScanCommand& msg, const dds_sample_info_t& info) {
        if (!info.valid_data) return;
        const std::string client = wire::fromDds(msg.client_id);
        // Identified now, while its writer is matched (the client may be gone when a deferred command runs).
        std::string identity = static_cast<facescan_wire_CommandKind>(msg.kind) == facescan_wire_CMD_GET_STATUS
                                   ? std::string()
                                   : identify(command_reader_->handle(), info.publication_handle, client);
        got.push_back({wire::fromDds(msg.session_id), wire::fromDds(msg.request_id), static_cast<uint32_t>(msg.kind),
                       steadyNowNs(), client, std::move(identity), msg.want_texture});
    });
    if (!n.isOk()) std::fprintf(stderr, "facescan-server: %s\n", n.status().toString().c_str());
    if (!ownSessionsFree()) {
        // Answered once this server knows which of its sessions are still its own.
        for (Command& c : got) deferred_.push_back(std::move(c));
        return;
    }
    // Deferred ones first (they came earlier), then the new ones.
    std::deque<Command> todo;
    todo.swap(deferred_);
    for (Command& c : got) todo.push_back(std::move(c));
    constexpr int64_t kDeferNs = 3'000'000'000;  // a claim settles well within this
    const std::string responder = cluster_->responder();
    std::vector<Command> run;
    for (Command& c : todo) {
        const std::shared_ptr<OwnedSession> o = owned(c.session_id);
        if (o && o->session) {
            run.push_back(std::move(c));  // ours: only the owner answers
        } else if (o && steadyNowNs() - c.received_ns < kDeferNs) {
            deferred_.push_back(std::move(c));  // being claimed here: answer once it settled
        } else if (answersFromFiles(c.session_id)) {
            run.push_back(std::move(c));  // finished here and retired: its files answer
        } else if (responder == params_.server_id) {
            const auto view = cluster_->owner(c.session_id);
            // A session finished on another live server: that one answers from its files.
            const bool finished_elsewhere = view && view->data.state == wire::OwnerState::kFinished &&
                                            view->data.owner_id != params_.server_id &&
                                            cluster_->serverAlive(view->data.owner_id);
            if ((!view || !view->alive) && !finished_elsewhere) run.push_back(std::move(c));  // nobody owns it
        }
    }
    if (run.empty()) return;
    {
        std::lock_guard lk(command_mutex_);
        for (Command& c : run) commands_.push_back(std::move(c));
    }
    command_cv_.notify_one();
}

void Server::commandLoop() {
    recon::nameThisThread("fs-command");
    for (;;) {
        Command c;
        {
            std::unique_lock lk(command_mutex_);
            command_cv_.wait(lk, [&] { return stopping_ || !commands_.empty(); });
            if (commands_.empty()) return;
            c = std::move(commands_.front());
            commands_.pop_front();
        }
        runCommand(c);
    }
}

void Server::runCommand(const Command& c) {
    if (c.request_id.empty()) return reply(c, invalidArgument("bad request: empty request_id"));
    if (c.kind > static_cast<uint32_t>(facescan_wire_CMD_GET_STATUS)) {
        return reply(c, invalidArgument("bad request: unknown command kind " + std::to_string(c.kind)));
    }
    std::shared_ptr<Session> session;
    {
        std::lock_guard lk(sessions_mutex_);
        if (auto it = owned_.find(c.session_id); it != owned_.end()) session = it->second->session;
        if (!session) {
            if (auto r = refused_.find(c.session_id); r != refused_.end()) {
                return reply(c, resourceExhausted("session '" + c.session_id + "' was " + r->second.detail));
            }
        }
    }
    if (!session && answerFromFiles(c)) return;
    if (!session) {
        // Only the responder gets here for sessions it does not own: say why nobody answers for it.
        const auto view = cluster_->owner(c.session_id);
        if (view && !view->alive && !view->disposed && view->data.state != wire::OwnerState::kFinished) {
            return reply(c, unavailable("session '" + c.session_id + "' has no live owner: server '" +
                                        view->data.owner_id + "' is gone and no standby has taken it over yet"));
        }
        return reply(c, notFound("unknown session '" + c.session_id + "'"));
    }
    switch (static_cast<facescan_wire_CommandKind>(c.kind)) {
        case facescan_wire_CMD_RESET: session->requestReset([this, c](const Status& s) { reply(c, s); }); return;
        case facescan_wire_CMD_FINISH:
            session->requestFinish("finish command",
                                   [this, c](const Status& s, const MeshResult& m) { reply(c, s, &m); });
            return;
        case facescan_wire_CMD_GET_MESH: {
            // A live session has no texture yet: its mesh keeps the vertex colours.
            if (c.want_texture && answerTextured(c, session->filesDir())) return;
            auto m = session->mesh();
            if (!m.isOk()) return reply(c, m.status());
            return reply(c, Status::ok(), &*m, m->draco.get());
        }
        case facescan_wire_CMD_GET_TRAJECTORY: {
            const std::string tum = session->trajectoryTum();
            const std::vector<uint8_t> bytes(tum.begin(), tum.end());
            return reply(c, Status::ok(), nullptr, &bytes);
        }
        case facescan_wire_CMD_GET_PREVIEW: {
            auto png = session->previewPng();
            if (!png.isOk()) return reply(c, png.status());
            return reply(c, Status::ok(), nullptr, &*png);
        }
        case facescan_wire_CMD_GET_STATUS: return reply(c, Status::ok());
    }
}

void Server::reply(const Command& c, const Status& status, const MeshResult* mesh, const std::vector<uint8_t>* payload,
                   const std::vector<uint8_t>* texture) {
    facescan_wire_ScanReply r{};
    r.session_id = wire::stringView(c.session_id);
    r.request_id = wire::stringView(c.request_id);
    r.server_id = wire::stringView(params_.server_id);
    r.kind = static_cast<facescan_wire_CommandKind>(c.kind);
    r.ok = status.isOk();
    const std::string error = status.isOk() ? std::string() : status.message();
    r.error = wire::stringView(error);
    if (mesh) {
        r.vertex_count = mesh->vertex_count;
        r.triangle_count = mesh->triangle_count;
    }
    if (payload) r.payload = wire::octetView(payload->data(), payload->size());
    if (texture) r.texture = wire::octetView(texture->data(), texture->size());
    audit(c, status);  // on record before the answer (and any scan data in it) leaves
    if (const Status s = reply_writer_->write(r); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: reply to %s: %s\n", c.request_id.c_str(), s.toString().c_str());
    }
}

}  // namespace facescan::service
