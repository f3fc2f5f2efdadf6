// Finished sessions once their Session is gone. A finished scan leaves the server's memory as soon as its files are
// written and its final status and mesh are published (Server::retireFinished): its volume, engine, frame buffers
// and snapshot state go with the Session, and what stays is a record of a few hundred bytes. The record keeps the
// session listed (its durable ScanStatus, `facescan sessions`, Server::sessions()) while it is among the newest
// --keep-finished and younger than --keep-finished-s; its commands are answered from its files in the data dir,
// listed or not, so the server's memory does not grow with the scans it has done.
#pragma once

#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "service/cluster.hpp"
#include "service/session.hpp"

namespace facescan::service {

struct FinishedSession {
    SessionStats stats;         // the final status
    std::filesystem::path dir;  // its files in the data dir (empty: they could not be written)
    uint32_t vertex_count = 0;  // of the final mesh, for FINISH replies
    uint32_t triangle_count = 0;
    // Its claim, in state FINISHED, while it is listed: the claim's DDS writer goes with the record. Readers then
    // see the FINISHED record without a writer, which nobody takes over (only claims that hold a session are).
    std::shared_ptr<Claim> claim;
    int64_t retired_ns = 0;  // steady clock
};

class FinishedSessions {
 public:
    FinishedSessions(int keep, double keep_s);

    void add(FinishedSession session);
    // A copy without the claim (nullopt: not listed).
    std::optional<FinishedSession> find(const std::string& session_id) const;
    std::vector<SessionStats> stats() const;
    size_t size() const;
    // Removes and returns the records beyond the newest `keep` and those older than keep_s at now_ns.
    std::vector<FinishedSession> expire(int64_t now_ns);
    // Removes and returns the record of `session_id` (an erased scan), with its claim; nullopt when none.
    std::optional<FinishedSession> remove(const std::string& session_id);
    // Removes and returns the records `drop` picks (it sees each final status, under the lock, without a copy).
    std::vector<FinishedSession> removeIf(const std::function<bool(const SessionStats&)>& drop);
    // The record's claim is now `claim`, at `epoch` (a claim made again at a later epoch); false when not listed.
    bool replaceClaim(const std::string& session_id, std::shared_ptr<Claim> claim, uint32_t epoch);

 private:
    const size_t keep_;
    const int64_t keep_ns_;
    mutable std::mutex mutex_;
    std::deque<FinishedSession> list_;  // oldest first
};

// The folder of a finished session that this server wrote into data_dir: data_dir/SESSION when its owner.json
// names server_id, else the newest data_dir/SESSION/SERVER.eEPOCH (written beside another owner's files, see
// claimSessionDir). Nullopt when there is none with a summary.json (written last: the session is complete), or
// when session_id is not a valid id (it becomes a path).
std::optional<std::filesystem::path> findFinishedSessionDir(const std::filesystem::path& data_dir,
                                                            const std::string& session_id,
                                                            const std::string& server_id);

// A finished session's results, read from its folder (session_store.hpp names the files).
StatusOr<MeshResult> readFinishedMesh(const std::filesystem::path& dir);  // mesh.drc, counts from decoding it
StatusOr<std::vector<uint8_t>> readFinishedFile(const std::filesystem::path& dir, const std::string& name);
// The textured model of a finished session: textured.drc (Draco with texture coordinates; the counts from decoding
// it, which also checks it) and its atlas textured.png. NotFound when the session has no texture (no colour, or
// finished by a version that did not write textured.drc); DataLoss when textured.drc cannot be decoded.
struct TexturedResult {
    MeshResult mesh;
    std::vector<uint8_t> png;
};
StatusOr<TexturedResult> readFinishedTexture(const std::filesystem::path& dir);

}  // namespace facescan::service
