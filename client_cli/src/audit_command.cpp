// `facescan audit`: prints the audit trails that servers (DATA_DIR/audit.log) and viewers (view --audit) append
// to (wire/audit_log.hpp), oldest first across every file given, optionally one session's only. Reads only.
#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "client/status_json.hpp"
#include "command_util.hpp"
#include "wire/audit_log.hpp"

namespace facescan::client::detail {

int runAudit(const CliOptions& options) {
    std::vector<wire::AuditRecord> records;
    for (const std::string& given : options.audit_files) {
        std::filesystem::path file = given;
        std::error_code ec;
        if (std::filesystem::is_directory(file, ec)) file /= "audit.log";  // a server's data dir
        auto read = wire::readAuditLog(file);
        if (!read.isOk()) {
            return fail(kExitUsage, read.status().message() +
                                        (read.status().code() == StatusCode::kNotFound
                                             ? " (give a server's data dir or audit.log, or the viewer's --audit file)"
                                             : ""));
        }
        for (wire::AuditRecord& r : *read) {
            if (options.session.empty() || r.session == options.session) records.push_back(std::move(r));
        }
    }
    std::stable_sort(records.begin(), records.end(),
                     [](const wire::AuditRecord& a, const wire::AuditRecord& b) { return a.time_ns < b.time_ns; });
    if (options.json) {
        for (const wire::AuditRecord& r : records) {
            std::printf("{\"time\":%s,\"action\":%s,\"session\":%s,\"identity\":%s,\"outcome\":%s,\"recorder\":%s}\n",
                        jsonString(wire::auditTimeText(r.time_ns)).c_str(), jsonString(r.action).c_str(),
                        jsonString(r.session).c_str(), jsonString(r.identity).c_str(), jsonString(r.outcome).c_str(),
                        jsonString(r.recorder).c_str());
        }
        return kExitOk;
    }
    std::printf("%-24s %-16s %-20s %-36s %-20s %s\n", "TIME (UTC)", "ACTION", "SESSION", "IDENTITY", "RECORDER",
                "OUTCOME");
    for (const wire::AuditRecord& r : records) {
        std::printf("%-24s %-16s %-20s %-36s %-20s %s\n", wire::auditTimeText(r.time_ns).c_str(), r.action.c_str(),
                    r.session.empty() ? "-" : r.session.c_str(), r.identity.c_str(), r.recorder.c_str(),
                    r.outcome.c_str());
    }
    if (records.empty()) std::printf("(no records%s)\n", options.session.empty() ? "" : " for this session");
    return kExitOk;
}

}  // namespace facescan::client::detail
