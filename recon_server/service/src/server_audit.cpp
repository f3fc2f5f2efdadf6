// The server's audit trail (wire/audit_log.hpp): every command it answers about a scan's data or model, with the
// client that sent it, the session and the outcome, in DATA_DIR/audit.log; and its retention (service/erasure.hpp),
// whose erasures are recorded there too.
#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "service/server.hpp"

namespace facescan::service {
namespace {

const char* actionName(uint32_t kind) {
    switch (static_cast<facescan_wire_CommandKind>(kind)) {
        case facescan_wire_CMD_RESET: return "reset";
        case facescan_wire_CMD_FINISH: return "finish";
        case facescan_wire_CMD_GET_MESH: return "get_mesh";
        case facescan_wire_CMD_GET_TRAJECTORY: return "get_trajectory";
        case facescan_wire_CMD_GET_PREVIEW: return "get_preview";
        case facescan_wire_CMD_GET_STATUS: return "get_status";
    }
    return "unknown_command";
}

}  // namespace

void Server::audit(const Command& c, const Status& status) {
    if (!audit_ || c.kind == static_cast<uint32_t>(facescan_wire_CMD_GET_STATUS)) return;
    wire::AuditRecord r;
    r.action = actionName(c.kind);
    r.session = c.session_id;
    r.identity = c.identity;
    r.outcome = status.isOk() ? "ok" : "error: " + status.message();
    r.recorder = "server " + params_.server_id;
    if (const Status s = audit_->append(std::move(r)); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: %s\n", s.message().c_str());
    }
}

std::string Server::identify(dds_entity_t reader, dds_instance_handle_t writer, const std::string& claimed_client) {
    const std::string claimed = claimed_client.empty() ? std::string("(no client id)") : claimed_client;
    // Without DDS Security nobody is authenticated: the client id is all there is, and anyone may send any.
    if (!peers_) return "client " + claimed;
    auto subject = peers_->subjectOf(reader, writer);
    if (!subject.isOk()) return "client " + claimed + " (identity not verified: " + subject.status().message() + ")";
    return "dds " + *subject + " (client id " + claimed + ")";
}

void Server::startRetention() {
    if (params_.retain_days <= 0) return;
    const int days = params_.retain_days;
    std::fprintf(stderr, "facescan-server: retention: sessions whose newest file is older than %d day(s) are erased\n",
                 days);
    retention_ = std::make_unique<RetentionSweeper>(
        params_.data_dir, std::chrono::seconds(int64_t(days) * 86400), std::chrono::hours(1),
        [this, days](const ErasureReport& report, const Status& status) {
            std::string what = std::to_string(report.removed.size()) + " file(s)";
            if (!report.removed.empty())
                what += " (" + report.removed.front() + (report.removed.size() > 1 ? ", ..." : "") + ")";
            if (status.isOk()) {
                std::fprintf(stderr, "facescan-server: retention (%d days): erased session %s from %s: removed %s\n",
                             days, report.session_id.c_str(), params_.data_dir.c_str(), what.c_str());
            } else {
                std::fprintf(stderr, "facescan-server: retention (%d days): cannot erase session %s: %s\n", days,
                             report.session_id.c_str(), status.message().c_str());
            }
            if (!audit_) return;
            wire::AuditRecord r;
            r.action = "delete";
            r.session = report.session_id;
            r.identity = "retention " + std::to_string(days) + " days";
            r.outcome = status.isOk() ? "ok: removed " + what : "error: " + status.message();
            r.recorder = "server " + params_.server_id;
            if (const Status s = audit_->append(std::move(r)); !s.isOk()) {
                std::fprintf(stderr, "facescan-server: %s\n", s.message().c_str());
            }
        });
}

Status Server::startErasure() {
    ErasureService::Hooks hooks;
    hooks.scanning_here = [this](const std::string& session) {
        std::lock_guard lk(sessions_mutex_);
        const auto it = owned_.find(session);
        return it != owned_.end() && it->second->session && it->second->session->open();
    };
    hooks.identify = [this](dds_entity_t reader, dds_instance_handle_t writer, const std::string& client) {
        // A tombstone a server passes on names that server, not a client.
        if (!peers_ && client.starts_with("server ")) return client;
        return identify(reader, writer, client);
    };
    hooks.erased = [this](const std::string& client, const Status& status, const ErasureReport& report) {
        // Its record in memory goes too: unlisted at once, its last status and snapshot out of the writers.
        if (status.isOk()) {
            if (auto record = finished_.remove(report.session_id)) forgetFinished(*record);
        }
        if (status.isOk() && snapshot_writer_) {
            // The last snapshot of the scan is still in this server's durable writer, for readers that join later:
            // let the instance go, so no viewer starting now gets its geometry.
            facescan_wire_MeshSnapshot key{};
            key.session_id = wire::stringView(report.session_id);
            // Unregistering drops the instance from the writer's durable history (and disposes of it for readers).
            if (const Status u = snapshot_writer_->unregister(key); !u.isOk() && u.code() != StatusCode::kNotFound) {
                std::fprintf(stderr, "facescan-server: erasing %s: the last snapshot: %s\n", report.session_id.c_str(),
                             u.toString().c_str());
            }
        }
        if (status.isOk()) {
            std::fprintf(stderr, "facescan-server: erased session %s (asked by %s): removed %zu file(s)\n",
                         report.session_id.c_str(), client.c_str(), report.removed.size());
        } else {
            std::fprintf(stderr, "facescan-server: not erasing session %s (asked by %s): %s\n",
                         report.session_id.c_str(), client.c_str(), status.message().c_str());
        }
        if (!audit_) return;
        wire::AuditRecord r;
        r.action = "delete";
        r.session = report.session_id;
        r.identity = client;
        r.outcome = status.isOk() ? "ok: removed " + std::to_string(report.removed.size()) + " file(s)"
                                  : "error: " + status.message();
        r.recorder = "server " + params_.server_id;
        if (const Status s = audit_->append(std::move(r)); !s.isOk()) {
            std::fprintf(stderr, "facescan-server: %s\n", s.message().c_str());
        }
    };
    // Requests already on the domain are waited for only when there is a replica to resume (the resume must not
    // bring back an erased scan); finished files are erased as the requests arrive, start-up does not wait.
    bool resumable = false;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(params_.data_dir, ec)) {
        resumable = resumable || std::filesystem::exists(entry.path() / "replica.log", ec);
    }
    auto started = ErasureService::start(*participant_, params_.data_dir, params_.server_id, std::move(hooks),
                                         resumable ? std::min(1.0, double(params_.join_settle_s)) : 0.0);
    if (!started.isOk()) {
        // An identity enrolled before erasure existed may not use its topics: the server still scans.
        std::fprintf(stderr,
                     "facescan-server: WARNING: facescan delete cannot reach this server (%s); with DDS Security, "
                     "enrol its identity again (site.sh add) so that its permissions name the erasure topics\n",
                     started.status().message().c_str());
        return Status::ok();
    }
    erasure_ = std::move(started).value();
    return Status::ok();
}

}  // namespace facescan::service
