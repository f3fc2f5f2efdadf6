// The server's audit trail (wire/audit_log.hpp): every command it answers about a scan's data or model, with the
// client that sent it, the session and the outcome, in DATA_DIR/audit.log.
#include <cstdio>

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
    r.identity = "client " + (c.client_id.empty() ? std::string("(no client id)") : c.client_id);
    r.outcome = status.isOk() ? "ok" : "error: " + status.message();
    r.recorder = "server " + params_.server_id;
    if (const Status s = audit_->append(std::move(r)); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: %s\n", s.message().c_str());
    }
}

}  // namespace facescan::service
