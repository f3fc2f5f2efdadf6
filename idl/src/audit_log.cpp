#include "wire/audit_log.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <fstream>

namespace facescan::wire {
namespace {

constexpr int kFields = 6;

std::string escape(const std::string& s) {
    std::string out;
    for (const char c : s) {
        switch (c) {
            case '\t': out += "\\t"; break;
            case '\n': out += "\\n"; break;
            case '\r': out += "\\r"; break;
            case '\\': out += "\\\\"; break;
            default: out += c;
        }
    }
    return out;
}

bool unescapeFields(const std::string& line, std::vector<std::string>& fields) {
    fields.assign(1, std::string());
    for (size_t i = 0; i < line.size(); ++i) {
        const char c = line[i];
        if (c == '\t') {
            fields.emplace_back();
        } else if (c == '\\') {
            if (++i == line.size()) return false;
            const char e = line[i];
            fields.back() += e == 't' ? '\t' : e == 'n' ? '\n' : e == 'r' ? '\r' : e == '\\' ? '\\' : '\0';
            if (fields.back().back() == '\0') return false;
        } else {
            fields.back() += c;
        }
    }
    return true;
}

int64_t nowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

}  // namespace

std::string auditTimeText(int64_t time_ns) {
    const time_t s = static_cast<time_t>(time_ns / 1'000'000'000);
    std::tm tm{};
    ::gmtime_r(&s, &tm);
    char text[96];
    std::snprintf(text, sizeof text, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1,
                  tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, static_cast<int>((time_ns / 1'000'000) % 1000));
    return text;
}

std::string formatAuditRecord(const AuditRecord& r) {
    return auditTimeText(r.time_ns) + "\t" + escape(r.action) + "\t" + escape(r.session) + "\t" + escape(r.identity) +
           "\t" + escape(r.outcome) + "\t" + escape(r.recorder);
}

StatusOr<AuditRecord> parseAuditRecord(const std::string& line) {
    std::vector<std::string> f;
    if (!unescapeFields(line, f) || f.size() != kFields) {
        return invalidArgument("not an audit record (TIME ACTION SESSION IDENTITY OUTCOME RECORDER, tab-separated)");
    }
    std::tm tm{};
    int ms = 0;
    if (std::sscanf(f[0].c_str(), "%4d-%2d-%2dT%2d:%2d:%2d.%3dZ", &tm.tm_year, &tm.tm_mon, &tm.tm_mday, &tm.tm_hour,
                    &tm.tm_min, &tm.tm_sec, &ms) != 7) {
        return invalidArgument("the time '" + f[0] + "' is not YYYY-MM-DDTHH:MM:SS.mmmZ");
    }
    tm.tm_year -= 1900;
    tm.tm_mon -= 1;
    AuditRecord r;
    r.time_ns = static_cast<int64_t>(::timegm(&tm)) * 1'000'000'000 + int64_t(ms) * 1'000'000;
    r.action = f[1];
    r.session = f[2];
    r.identity = f[3];
    r.outcome = f[4];
    r.recorder = f[5];
    return r;
}

StatusOr<std::unique_ptr<AuditLog>> AuditLog::open(const std::filesystem::path& path) {
    std::unique_ptr<AuditLog> log(new AuditLog());
    log->path_ = path;
    log->fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0600);
    if (log->fd_ < 0) {
        return unavailable("cannot open the audit trail " + path.string() + ": " + std::strerror(errno));
    }
    if (::fchmod(log->fd_, 0600) != 0) {
        return unavailable("cannot make the audit trail " + path.string() + " private: " + std::strerror(errno));
    }
    return log;
}

AuditLog::~AuditLog() {
    if (fd_ >= 0) ::close(fd_);
}

Status AuditLog::append(AuditRecord record) {
    if (record.time_ns == 0) record.time_ns = nowNs();
    const std::string line = formatAuditRecord(record) + "\n";
    std::lock_guard lock(mutex_);
    // One write: with O_APPEND, records of several writers never interleave.
    const ssize_t n = ::write(fd_, line.data(), line.size());
    if (n != static_cast<ssize_t>(line.size())) {
        return unavailable("cannot append to the audit trail " + path_.string() + ": " +
                           (n < 0 ? std::strerror(errno) : "short write"));
    }
    if (::fdatasync(fd_) != 0) return unavailable("cannot sync the audit trail " + path_.string());
    return Status::ok();
}

StatusOr<std::vector<AuditRecord>> readAuditLog(const std::filesystem::path& path) {
    std::ifstream in(path);
    if (!in) return notFound("no audit trail at " + path.string());
    std::vector<AuditRecord> records;
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        ++number;
        if (line.empty() || line[0] == '#') continue;
        auto r = parseAuditRecord(line);
        if (!r.isOk())
            return invalidArgument(path.string() + " line " + std::to_string(number) + ": " + r.status().message());
        records.push_back(std::move(*r));
    }
    return records;
}

}  // namespace facescan::wire
