#include "service/replica_log.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>

#include "service/session_store.hpp"

namespace facescan::service {
namespace {

constexpr uint32_t kRecordMagic = 0x4c525346;  // "FSRL"
constexpr size_t kRecordHeader = 8;

void frame(const std::vector<uint8_t>& encoded, std::vector<uint8_t>& out) {
    out.resize(kRecordHeader + encoded.size());
    const uint32_t size = static_cast<uint32_t>(encoded.size());
    std::memcpy(out.data(), &kRecordMagic, 4);
    std::memcpy(out.data() + 4, &size, 4);
    std::memcpy(out.data() + kRecordHeader, encoded.data(), encoded.size());
}

Status writeAll(int fd, const uint8_t* p, size_t n, const std::string& what) {
    while (n > 0) {
        const ssize_t w = ::write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return internalError("cannot write " + what + ": " + std::strerror(errno));
        p += w;
        n -= static_cast<size_t>(w);
    }
    return Status::ok();
}

}  // namespace

ReplicaLog::~ReplicaLog() {
    if (fd_ >= 0) ::close(fd_);
}

Status ReplicaLog::append(const std::vector<uint8_t>& encoded, bool full) {
    const std::filesystem::path path = dir_ / "replica.log";
    frame(encoded, record_);
    const std::vector<uint8_t>& record = record_;
    if (full || fd_ < 0) {
        if (!full) return internalError(path.string() + ": a delta cannot start a replica log");
        if (fd_ >= 0) ::close(fd_);
        fd_ = -1;
        RETURN_IF_ERROR(writeFileAtomic(path, record.data(), record.size()));
        fd_ = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
        if (fd_ < 0) return internalError("cannot open " + path.string() + ": " + std::strerror(errno));
        bytes_ = full_bytes_ = record.size();
        return Status::ok();
    }
    RETURN_IF_ERROR(writeAll(fd_, record.data(), record.size(), path.string()));
    // The agent drops the frames this round covers once it is confirmed: it must be on the disk by then.
    if (::fdatasync(fd_) != 0) return internalError("cannot sync " + path.string() + ": " + std::strerror(errno));
    bytes_ += record.size();
    return Status::ok();
}

StatusOr<wire::ReplicaData> loadReplicaLog(const std::filesystem::path& dir, std::string* warning) {
    const std::filesystem::path path = dir / "replica.log";
    std::ifstream in(path, std::ios::binary);
    if (!in) return notFound("no replica in " + dir.string());
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    wire::ReplicaData state;
    size_t at = 0;
    int records = 0;
    std::string problem;
    while (at < bytes.size()) {
        uint32_t magic = 0, size = 0;
        if (bytes.size() - at < kRecordHeader) {
            problem = "a torn record header at byte " + std::to_string(at);
            break;
        }
        std::memcpy(&magic, bytes.data() + at, 4);
        std::memcpy(&size, bytes.data() + at + 4, 4);
        if (magic != kRecordMagic || size > bytes.size() - at - kRecordHeader) {
            problem = "a torn or corrupt record at byte " + std::to_string(at);
            break;
        }
        wire::ReplicaData round;
        Status s = wire::decodeReplica(bytes.data() + at + kRecordHeader, size, round);
        if (s.isOk()) s = records == 0 && !round.full() ? dataLoss("the first record is not a full state") : s;
        if (s.isOk()) s = wire::mergeReplica(state, round);
        if (!s.isOk()) {
            problem = "record " + std::to_string(records + 1) + ": " + s.message();
            break;
        }
        ++records;
        at += kRecordHeader + size;
    }
    if (records == 0)
        return dataLoss(path.string() + " holds no usable replica" + (problem.empty() ? "" : ": " + problem));
    if (!problem.empty() && warning) {
        *warning = path.string() + ": resuming from round " + std::to_string(state.round) + ", skipped " + problem;
    }
    return state;
}

}  // namespace facescan::service
