#include "service/erasure_service.hpp"

#include <chrono>
#include <cstdio>

#include "recon/parallel.hpp"
#include "wire/messages.hpp"

namespace facescan::service {
namespace {
using namespace std::chrono_literals;
}  // namespace

StatusOr<std::unique_ptr<ErasureService>> ErasureService::start(const wire::Participant& participant,
                                                                std::filesystem::path data_dir, std::string server_id,
                                                                Hooks hooks, double settle_s) {
    using wire::boxed;
    std::unique_ptr<ErasureService> s(new ErasureService());
    s->data_dir_ = std::move(data_dir);
    s->server_id_ = std::move(server_id);
    s->hooks_ = std::move(hooks);
    ASSIGN_OR_RETURN(s->request_topic_, boxed(wire::Topic<facescan_wire_EraseRequest>::create(participant)));
    ASSIGN_OR_RETURN(s->report_topic_, boxed(wire::Topic<facescan_wire_EraseReport>::create(participant)));
    ASSIGN_OR_RETURN(s->requests_, boxed(wire::Reader<facescan_wire_EraseRequest>::create(*s->request_topic_)));
    ASSIGN_OR_RETURN(s->forward_, boxed(wire::Writer<facescan_wire_EraseRequest>::create(*s->request_topic_)));
    ASSIGN_OR_RETURN(s->reports_, boxed(wire::Writer<facescan_wire_EraseReport>::create(*s->report_topic_)));
    // The tombstones of this data dir go on the domain: a server that never heard of an erasure learns it here.
    for (const std::string& session : erasedSessions(s->data_dir_))
        s->republish(session, "tombstone", "server " + s->server_id_);
    // Requests already on the domain (from live servers' writers) before the server resumes anything.
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(settle_s);
    s->takeRequests();
    while (std::chrono::steady_clock::now() < until) {
        std::this_thread::sleep_for(50ms);
        s->takeRequests();
    }
    ErasureService* raw = s.get();
    s->thread_ = std::thread([raw] {
        recon::nameThisThread("fs-erasure");
        while (!raw->stopping_) {
            raw->takeRequests();
            std::this_thread::sleep_for(100ms);
        }
    });
    return s;
}

ErasureService::~ErasureService() {
    stopping_ = true;
    if (thread_.joinable()) thread_.join();
}

void ErasureService::takeRequests() {
    struct Request {
        std::string session, request_id, client_id, identity;
    };
    std::vector<Request> got;
    auto n = requests_->take([&](const facescan_wire_EraseRequest& m, const dds_sample_info_t& info) {
        if (!info.valid_data) return;
        std::string client = wire::fromDds(m.client_id);
        // Identified now, while its writer is matched.
        std::string identity =
            hooks_.identify ? hooks_.identify(requests_->handle(), info.publication_handle, client) : client;
        got.push_back(
            {wire::fromDds(m.session_id), wire::fromDds(m.request_id), std::move(client), std::move(identity)});
    });
    if (!n.isOk()) std::fprintf(stderr, "facescan-server: %s\n", n.status().toString().c_str());
    for (const Request& r : got) handle(r.session, r.request_id, r.client_id, r.identity);
}

void ErasureService::handle(const std::string& session, const std::string& request_id, const std::string& client_id,
                            const std::string& identity) {
    if (Status s = wire::validateSessionId(session); !s.isOk()) return report(session, request_id, s, {});
    // Each request once: the copies other servers pass on carry the same request id.
    if (!handled_.insert(session + "\n" + request_id).second) return;
    const bool known = isErased(data_dir_, session);
    std::error_code ec;
    // A tombstone passed on, and nothing of the scan left here: nothing to do, and nothing to say.
    if (known && request_id == "tombstone" && !std::filesystem::exists(data_dir_ / session, ec)) return;
    if (hooks_.scanning_here && hooks_.scanning_here(session)) {
        const Status refused =
            Status(StatusCode::kUnavailable, "session " + session + " is still being scanned on server " + server_id_ +
                                                 ": finish it first (facescan finish " + session + "), then delete it");
        if (hooks_.erased) hooks_.erased(identity, refused, ErasureReport{session, {}, false});
        report(session, request_id, refused, {});
        return;
    }
    auto erased = eraseSession(data_dir_, session, "asked by " + identity + " (request " + request_id + ")");
    const Status status = erased.status();
    const ErasureReport result = erased.isOk() ? *erased : ErasureReport{session, {}, false};
    if (hooks_.erased) hooks_.erased(identity, status, result);  // on record before the client hears of it
    report(session, request_id, status, result.removed);
    if (status.isOk() && !known) republish(session, request_id, client_id);
}

void ErasureService::report(const std::string& session, const std::string& request_id, const Status& status,
                            const std::vector<std::string>& removed) {
    std::vector<char*> items;
    for (const std::string& r : removed) items.push_back(const_cast<char*>(r.c_str()));
    const std::string error = status.isOk() ? std::string() : status.message();
    facescan_wire_EraseReport m{};
    m.session_id = wire::stringView(session);
    m.server_id = wire::stringView(server_id_);
    m.request_id = wire::stringView(request_id);
    m.ok = status.isOk();
    m.error = wire::stringView(error);
    m.removed._length = m.removed._maximum = static_cast<uint32_t>(items.size());
    m.removed._buffer = items.empty() ? nullptr : items.data();
    m.removed._release = false;
    if (const Status s = reports_->write(m); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: erasure report for %s: %s\n", session.c_str(), s.toString().c_str());
    }
}

void ErasureService::republish(const std::string& session, const std::string& request_id,
                               const std::string& client_id) {
    facescan_wire_EraseRequest m{};
    m.session_id = wire::stringView(session);
    m.request_id = wire::stringView(request_id);
    m.client_id = wire::stringView(client_id);
    if (const Status s = forward_->write(m); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: passing on the erasure of %s: %s\n", session.c_str(),
                     s.toString().c_str());
    }
}

}  // namespace facescan::service
