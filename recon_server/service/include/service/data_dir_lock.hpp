// One server per data dir. Two servers writing one folder would overwrite each other's scans and replicas, and a
// server restarted on a data dir would resume sessions that another live server still owns. The lock is flock(2) on
// DIR/server.lock: the kernel drops it when its process dies, so a server killed with SIGKILL leaves no stale lock
// for its restart, and the file names the holder for the message that refuses a second server.
#pragma once

#include <filesystem>
#include <string>

#include "recon/status.hpp"

namespace facescan::service {

class DataDirLock {
 public:
    // Takes the lock for `server_id`, or says which server holds it and what to do.
    static StatusOr<DataDirLock> acquire(const std::filesystem::path& dir, const std::string& server_id);
    DataDirLock() = default;
    ~DataDirLock();
    DataDirLock(DataDirLock&& other) noexcept;
    DataDirLock& operator=(DataDirLock&& other) noexcept;
    DataDirLock(const DataDirLock&) = delete;
    DataDirLock& operator=(const DataDirLock&) = delete;

 private:
    int fd_ = -1;
};

}  // namespace facescan::service
