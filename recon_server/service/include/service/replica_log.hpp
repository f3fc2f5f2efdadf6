// The owner's replica of a session on disk (restart recovery): DIR/replica.log holds a full replica
// followed by the deltas of the rounds after it, each record framed as [u32 magic "FSRL"][u32 bytes][bytes of
// wire::encodeReplica]. A round is appended and synced before the agent is told it may drop the frames it
// covers; a full round replaces the file (temporary file, sync, rename). After a crash the last record may be
// torn: loading stops at the first record that does not decode and continues from the ones before it.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "recon/status.hpp"
#include "wire/replica_codec.hpp"

namespace facescan::service {

class ReplicaLog {
 public:
    explicit ReplicaLog(std::filesystem::path dir) : dir_(std::move(dir)) {}
    ~ReplicaLog();
    ReplicaLog(const ReplicaLog&) = delete;
    ReplicaLog& operator=(const ReplicaLog&) = delete;

    // Appends one encoded round (a full one starts the file over). Synced to disk when it returns ok.
    Status append(const std::vector<uint8_t>& encoded, bool full);
    uint64_t bytes() const { return bytes_; }           // size of the file now
    uint64_t fullBytes() const { return full_bytes_; }  // size of its full record
    const std::filesystem::path& dir() const { return dir_; }

 private:
    std::filesystem::path dir_;
    int fd_ = -1;
    uint64_t bytes_ = 0;
    uint64_t full_bytes_ = 0;
    std::vector<uint8_t> record_;  // the framed round; keeps its capacity (no fresh pages every round)
};

// DIR/replica.log as one full replica (its deltas merged). NotFound when there is none; a torn or corrupt tail is
// skipped and described in `warning`.
StatusOr<wire::ReplicaData> loadReplicaLog(const std::filesystem::path& dir, std::string* warning);

}  // namespace facescan::service
