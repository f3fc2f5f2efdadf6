// Erasing a scan from a server's data dir, and keeping scans only as long as the site's policy says
// (--retain-days). A face used to identify someone is special-category data (GDPR Art. 9) and its subject may ask
// for erasure (Art. 17): erasing removes the session's whole folder (the owner's results, a replica log, and the
// files of any other owner written beside them, SERVER.eEPOCH) and leaves a tombstone, DATA_DIR/@erased/SESSION,
// so that nothing this server receives later (a late replica, a finish, a restart's resume) writes the scan again.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "recon/status.hpp"

namespace facescan::service {

struct ErasureReport {
    std::string session_id;
    std::vector<std::string> removed;  // what went, relative to the data dir ("SESSION/mesh.ply", ...)
    bool had_files = false;            // false: nothing of it was here (the tombstone is still written)
};

// Removes DATA_DIR/SESSION entirely and writes the tombstone (0600, the time and `reason`). InvalidArgument for a
// session id that is not one (it becomes a path); the first error otherwise, with what was removed before it.
StatusOr<ErasureReport> eraseSession(const std::filesystem::path& data_dir, const std::string& session_id,
                                     const std::string& reason);
// Whether SESSION was erased here (its tombstone exists).
bool isErased(const std::filesystem::path& data_dir, const std::string& session_id);
// Every session erased here (the tombstones), sorted.
std::vector<std::string> erasedSessions(const std::filesystem::path& data_dir);

// The sessions in data_dir whose newest file is older than max_age (by modification time): finished scans and
// replicas left behind alike. A session still being scanned writes its replica every second and is never old.
std::vector<std::string> sessionsOlderThan(const std::filesystem::path& data_dir, std::chrono::seconds max_age,
                                           std::filesystem::file_time_type now);

// Erases the sessions older than `retain` (sessionsOlderThan) once in the constructor, then every `period` on a
// thread of its own, calling `erased` for each with its report (the server logs it and records it in its audit
// trail). Stops with the object.
class RetentionSweeper {
 public:
    using Erased = std::function<void(const ErasureReport&, const Status&)>;
    RetentionSweeper(std::filesystem::path data_dir, std::chrono::seconds retain, std::chrono::seconds period,
                     Erased erased);
    ~RetentionSweeper();
    RetentionSweeper(const RetentionSweeper&) = delete;
    RetentionSweeper& operator=(const RetentionSweeper&) = delete;

    // One sweep now (the thread runs these); returns how many sessions were erased.
    int sweep();

 private:
    const std::filesystem::path data_dir_;
    const std::chrono::seconds retain_, period_;
    const Erased erased_;
    std::mutex mutex_;
    std::condition_variable wake_;
    bool stopping_ = false;
    std::thread thread_;
};

}  // namespace facescan::service
