#include "service/erasure.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "recon/parallel.hpp"
#include "service/session_store.hpp"
#include "wire/messages.hpp"
#include "wire/private_files.hpp"

namespace facescan::service {
namespace {
namespace fs = std::filesystem;

// Not a valid session id ([A-Za-z0-9._-]), so no session folder can take its name.
constexpr const char* kTombstones = "@erased";

std::string utcNow() {
    const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    std::tm tm{};
    ::gmtime_r(&now, &tm);
    char text[32];
    std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return text;
}

}  // namespace

StatusOr<ErasureReport> eraseSession(const fs::path& data_dir, const std::string& session_id,
                                     const std::string& reason) {
    if (Status s = wire::validateSessionId(session_id); !s.isOk()) {
        return invalidArgument("cannot erase '" + session_id + "': " + s.message());
    }
    ErasureReport report;
    report.session_id = session_id;
    // The tombstone first: whatever arrives while the files go must not write them again.
    std::error_code ec;
    RETURN_IF_ERROR(wire::createPrivateDir(data_dir / kTombstones));
    RETURN_IF_ERROR(writeFileAtomic(data_dir / kTombstones / session_id, "erased " + utcNow() + ": " + reason + "\n"));
    const fs::path dir = data_dir / session_id;
    if (!fs::exists(fs::symlink_status(dir, ec))) return report;
    report.had_files = true;
    std::vector<fs::path> files;
    for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        if (!it->is_directory(ec)) files.push_back(it->path());
    }
    std::sort(files.begin(), files.end());
    for (const fs::path& f : files) {
        if (fs::remove(f, ec)) report.removed.push_back(fs::relative(f, data_dir, ec).string());
        if (ec) return internalError("cannot remove " + f.string() + ": " + ec.message());
    }
    fs::remove_all(dir, ec);
    if (ec) return internalError("cannot remove " + dir.string() + ": " + ec.message());
    return report;
}

bool isErased(const fs::path& data_dir, const std::string& session_id) {
    std::error_code ec;
    return wire::validateSessionId(session_id).isOk() && fs::exists(data_dir / kTombstones / session_id, ec);
}

std::vector<std::string> erasedSessions(const fs::path& data_dir) {
    std::vector<std::string> out;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(data_dir / kTombstones, ec)) {
        const std::string name = e.path().filename().string();
        if (wire::validateSessionId(name).isOk() && !name.ends_with(".tmp")) out.push_back(name);
    }
    std::sort(out.begin(), out.end());
    return out;
}

std::vector<std::string> sessionsOlderThan(const fs::path& data_dir, std::chrono::seconds max_age,
                                           fs::file_time_type now) {
    std::vector<std::string> old;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(data_dir, ec)) {
        const std::string name = entry.path().filename().string();
        if (!entry.is_directory(ec) || entry.is_symlink(ec) || !wire::validateSessionId(name).isOk()) continue;
        fs::file_time_type newest = fs::last_write_time(entry.path(), ec);
        bool any = false;
        for (fs::recursive_directory_iterator it(entry.path(), ec), end; !ec && it != end; it.increment(ec)) {
            if (!it->is_regular_file(ec)) continue;
            newest = any ? std::max(newest, it->last_write_time(ec)) : it->last_write_time(ec);
            any = true;
        }
        if (any && now - newest > max_age) old.push_back(name);
    }
    std::sort(old.begin(), old.end());
    return old;
}

RetentionSweeper::RetentionSweeper(fs::path data_dir, std::chrono::seconds retain, std::chrono::seconds period,
                                   Erased erased)
    : data_dir_(std::move(data_dir)), retain_(retain), period_(period), erased_(std::move(erased)) {
    sweep();  // the first one before the constructor returns: the server resumes nothing it erases
    thread_ = std::thread([this] {
        recon::nameThisThread("fs-retention");
        std::unique_lock lock(mutex_);
        while (!wake_.wait_for(lock, period_, [this] { return stopping_; })) {
            lock.unlock();
            sweep();
            lock.lock();
        }
    });
}

RetentionSweeper::~RetentionSweeper() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
}

int RetentionSweeper::sweep() {
    int n = 0;
    const long days = static_cast<long>(retain_.count() / 86400);
    for (const std::string& session : sessionsOlderThan(data_dir_, retain_, fs::file_time_type::clock::now())) {
        auto report = eraseSession(data_dir_, session, "retention: older than " + std::to_string(days) + " day(s)");
        erased_(report.isOk() ? *report : ErasureReport{session, {}, true}, report.status());
        n += report.isOk() ? 1 : 0;
    }
    return n;
}

}  // namespace facescan::service
