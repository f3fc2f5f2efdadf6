// Writing a finished session to the data dir (--data-dir/SESSION/): mesh.ply (binary, normals and colours),
// mesh.drc (Draco), the textured model when there is one (textured.obj/.mtl/.png, textured.ply, textured.drc),
// trajectory.txt (TUM), preview.png (the last shaded view), summary.json, frames.tsv (each processed
// frame's timings). Once a finished session has left the server's memory, these files answer its commands
// (finished_sessions.hpp). Every file goes to NAME.tmp first, is fsync'ed and then renamed over NAME, so a crash
// leaves either the old file or the whole new one, never a half file.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "recon/indexed_mesh.hpp"
#include "recon/status.hpp"
#include "recon/texture_atlas.hpp"

namespace facescan::service {

// Writes `bytes` to `path` atomically (path.tmp, fsync, rename, fsync of the directory).
Status writeFileAtomic(const std::filesystem::path& path, const void* bytes, size_t size);
inline Status writeFileAtomic(const std::filesystem::path& path, const std::string& text) {
    return writeFileAtomic(path, text.data(), text.size());
}

// Binary PLY with vertex normals (from the triangles) and colours (recon/mesh_writer.hpp, to memory).
StatusOr<std::string> meshToPly(const recon::IndexedMesh& mesh);

struct SessionFiles {
    const recon::IndexedMesh* mesh = nullptr;           // the final full-resolution mesh (may be empty: no faces)
    const std::vector<uint8_t>* draco = nullptr;        // Draco bytes of mesh (empty when the mesh is empty)
    std::string trajectory_tum;                         // TUM lines
    std::string frames_tsv;                             // Session::frameTimingsTsv; not written when empty
    const std::vector<uint8_t>* preview_png = nullptr;  // not written when empty (no model)
    // The textured model (recon/texture_atlas.hpp), when one was baked: textured.obj + textured.mtl + textured.png
    // and textured.ply (u, v per vertex, naming textured.png); null or invalid: not written.
    const recon::TexturedMesh* textured = nullptr;
    // The textured model as Draco with texture coordinates (wire::encodeTexturedMeshDraco): textured.drc, what a
    // client that asks for the texture gets with textured.png (finished_sessions.hpp); written with the textured
    // files when not empty.
    const std::vector<uint8_t>* textured_draco = nullptr;
    std::string summary_json;  // written last: its presence means the session is complete
};

// Creates dir and writes the files that have content (mesh.ply and mesh.drc only for a non-empty mesh).
Status writeSessionFiles(const std::filesystem::path& dir, const SessionFiles& files);

// The session's folder in the data dir for `server_id` at ownership `epoch`, recorded in DIR/owner.json. The main
// folder (data_dir/SESSION) when it is free, already this server's, or recorded for an earlier epoch (a takeover:
// owner.json is rewritten, naming the previous owner). When another server holds it at the same or a later epoch
// (two servers that could not see each other both owned the session), a sub-folder "SERVER.eEPOCH" instead, and
// `note` says so: nobody's results are overwritten.
StatusOr<std::filesystem::path> claimSessionDir(const std::filesystem::path& data_dir, const std::string& session_id,
                                                const std::string& server_id, uint32_t epoch, std::string* note);
// The owner recorded in DIR/owner.json: (server id, epoch), or nullopt when none is readable.
std::optional<std::pair<std::string, uint32_t>> readSessionOwner(const std::filesystem::path& dir);
// A finished session needs no replica: removes DIR/replica.log (and its temporary file).
void removeReplicaLog(const std::filesystem::path& dir);

// A finish writes its files one by one, summary.json last, and removes the replica log once they are all there.
// A folder of `server_id`'s (its owner.json names it) with files but neither summary.json nor replica.log is a
// finish that a kill or a crash cut off: an incomplete result, which nothing can continue (no replica) and which
// would stand beside the result that the next owner writes from its copy and the frames its agent keeps. Removes
// such a folder's files (the main folder and this server's SERVER.eEPOCH folders beside another's; every other
// folder is left as it is), and the folder when nothing else is left in it. Called when the server starts, before
// it resumes anything: the folders it cleaned.
struct InterruptedFinish {
    std::filesystem::path dir;
    std::vector<std::string> removed;  // file names
};
std::vector<InterruptedFinish> removeInterruptedFinishes(const std::filesystem::path& data_dir,
                                                         const std::string& server_id);
// Creates dir when missing and proves that a file can be written there (a probe written atomically, then
// removed): checked when the server starts, so that a data dir the server cannot write is refused at once with
// the reason, not discovered when the first finished scan cannot be saved.
Status checkDataDir(const std::filesystem::path& dir);

// Minimal JSON string escaping for summaries (quotes, backslash, control characters).
std::string jsonEscape(const std::string& s);

}  // namespace facescan::service
