#include "service/data_dir_lock.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

namespace facescan::service {
namespace {

std::string hostName() {
    char host[256] = {};
    return ::gethostname(host, sizeof host - 1) == 0 ? std::string(host) : std::string("?");
}

}  // namespace

StatusOr<DataDirLock> DataDirLock::acquire(const std::filesystem::path& dir, const std::string& server_id) {
    const std::filesystem::path path = dir / "server.lock";
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0)
        return unavailable("data dir " + dir.string() + ": cannot open " + path.string() + ": " + std::strerror(errno));
    DataDirLock lock;
    lock.fd_ = fd;
    // It names the server's host and pid: owner-only like every file in the data dir, even one an older version made.
    if (::fchmod(fd, 0600) != 0) {
        return unavailable("data dir " + dir.string() + ": cannot make " + path.string() +
                           " private: " + std::strerror(errno));
    }
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
        const int err = errno;
        char holder[512] = {};
        const ssize_t n = ::pread(fd, holder, sizeof holder - 1, 0);
        std::string who = n > 0 ? std::string(holder, static_cast<size_t>(n)) : std::string("another process");
        while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
        if (err != EWOULDBLOCK) {
            return unavailable("data dir " + dir.string() + ": cannot lock " + path.string() + ": " +
                               std::strerror(err));
        }
        return invalidArgument("data dir " + dir.string() + " is in use by " + who +
                               ": each server needs a --data-dir of its own (two would overwrite each other's "
                               "scans and replicas); server '" +
                               server_id + "' does not start");
    }
    const std::string me =
        "facescan-server '" + server_id + "' (pid " + std::to_string(::getpid()) + " on " + hostName() + ")\n";
    if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, me.data(), me.size(), 0) != static_cast<ssize_t>(me.size())) {
        return unavailable("data dir " + dir.string() + ": cannot write " + path.string() + ": " +
                           std::strerror(errno));
    }
    return lock;
}

DataDirLock::~DataDirLock() {
    if (fd_ >= 0) ::close(fd_);  // closing drops the lock
}

DataDirLock::DataDirLock(DataDirLock&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}

DataDirLock& DataDirLock::operator=(DataDirLock&& other) noexcept {
    if (this != &other) {
        if (fd_ >= 0) ::close(fd_);
        fd_ = std::exchange(other.fd_, -1);
    }
    return *this;
}

}  // namespace facescan::service
