// The server's side of `facescan delete`: it reads EraseRequest (idl/facescan.idl), erases the scan from its data
// dir (service/erasure.hpp: files, replicas, the tombstone), reports what it removed on EraseReport, and publishes
// the request again on its own transient-local writer, so a server that was down when the client asked gets the
// request from any live server when it comes back. At start it also publishes the tombstones of its data dir.
// A scan still being scanned here is not erased: the report says to finish it first.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <thread>

#include "service/erasure.hpp"
#include "wire/topics.hpp"

namespace facescan::service {

class ErasureService {
 public:
    struct Hooks {
        std::function<bool(const std::string& session)> scanning_here;  // an open session this server owns
        // Who sent a request, for the record: the request's reader, its writer (publication handle) and the
        // client id the request claims. Unset: the claimed client id.
        std::function<std::string(dds_entity_t reader, dds_instance_handle_t writer, const std::string& client)>
            identify;
        // After each request handled: who asked (identify), the outcome and the report (log, audit trail).
        std::function<void(const std::string& identity, const Status&, const ErasureReport&)> erased;
    };
    // Creates the endpoints, takes the requests already on the domain for `settle_s` (0: only what has arrived;
    // more when the server has replicas to resume), then keeps taking them on a thread of its own.
    static StatusOr<std::unique_ptr<ErasureService>> start(const wire::Participant& participant,
                                                           std::filesystem::path data_dir, std::string server_id,
                                                           Hooks hooks, double settle_s);
    ~ErasureService();
    ErasureService(const ErasureService&) = delete;
    ErasureService& operator=(const ErasureService&) = delete;

 private:
    ErasureService() = default;
    void takeRequests();
    void handle(const std::string& session, const std::string& request_id, const std::string& client_id,
                const std::string& identity);
    void report(const std::string& session, const std::string& request_id, const Status& status,
                const std::vector<std::string>& removed);
    void republish(const std::string& session, const std::string& request_id, const std::string& client_id);

    std::filesystem::path data_dir_;
    std::string server_id_;
    Hooks hooks_;
    std::unique_ptr<wire::Topic<facescan_wire_EraseRequest>> request_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_EraseReport>> report_topic_;
    std::unique_ptr<wire::Reader<facescan_wire_EraseRequest>> requests_;
    std::unique_ptr<wire::Writer<facescan_wire_EraseRequest>> forward_;
    std::unique_ptr<wire::Writer<facescan_wire_EraseReport>> reports_;
    std::set<std::string> handled_;  // "SESSION\nREQUEST": requests handled (only the taking thread touches it)
    std::atomic<bool> stopping_{false};
    std::thread thread_;
};

}  // namespace facescan::service
