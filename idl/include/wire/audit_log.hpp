// The audit trail: who fetched, downloaded, reset, finished or deleted which scan, when, and with what outcome.
// Written by the server (its commands, in DATA_DIR/audit.log) and the web viewer (its downloads, by viewer
// login), read by `facescan audit`. Append-only: the file is opened O_APPEND (each record one write, synced) and
// 0600, and nothing in facescan rewrites or truncates it.
//
// One record per line, tab-separated, a tab, newline or backslash inside a field written as \t, \n, \\:
//   TIME (UTC, 2026-11-26T07:03:00.123Z)  ACTION  SESSION  IDENTITY  OUTCOME ("ok" or "error: ...")  RECORDER
// IDENTITY says what kind it is: "dds SUBJECT (client id ID)" (with DDS Security: the certificate subject the
// sender's participant authenticated with, wire/peer_identity.hpp, and beside it the client id it claims),
// "client NAME@HOST:PID:N" (without DDS Security: only the client id the client sends, which nothing checks;
// "(identity not verified: WHY)" follows it when a secured server could not establish the sender),
// "login USER" (a viewer login over TLS), "http ADDRESS" (a viewer without a login). RECORDER is the program
// that wrote the record ("server ID", "viewer HOST").
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "recon/status.hpp"

namespace facescan::wire {

struct AuditRecord {
    int64_t time_ns = 0;  // since the Unix epoch (UTC)
    std::string action;   // get_mesh, get_trajectory, get_preview, reset, finish, delete, download, snapshot, ...
    std::string session;
    std::string identity;
    std::string outcome;  // "ok" or "error: WHY"
    std::string recorder;
};

std::string formatAuditRecord(const AuditRecord& record);  // one line, without the newline
StatusOr<AuditRecord> parseAuditRecord(const std::string& line);
std::string auditTimeText(int64_t time_ns);  // 2026-11-26T07:03:00.123Z

class AuditLog {
 public:
    // Opens (creates) `path` for appending, 0600; its folder must exist.
    static StatusOr<std::unique_ptr<AuditLog>> open(const std::filesystem::path& path);
    ~AuditLog();
    AuditLog(const AuditLog&) = delete;
    AuditLog& operator=(const AuditLog&) = delete;

    // Appends one record (time_ns 0: now) in one write and syncs it. Thread-safe.
    Status append(AuditRecord record);
    const std::filesystem::path& path() const { return path_; }

 private:
    AuditLog() = default;
    std::filesystem::path path_;
    int fd_ = -1;
    std::mutex mutex_;
};

// Every record of an audit file, in order; InvalidArgument naming the line for one that is not a record.
StatusOr<std::vector<AuditRecord>> readAuditLog(const std::filesystem::path& path);

}  // namespace facescan::wire
