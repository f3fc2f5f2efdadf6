#include "service/session_store.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>

#include "recon/mesh_writer.hpp"
#include "service/erasure.hpp"
#include "wire/private_files.hpp"

namespace facescan::service {
namespace {

Status errnoStatus(const std::string& what) { return internalError(what + ": " + std::strerror(errno)); }

}  // namespace

Status writeFileAtomic(const std::filesystem::path& path, const void* bytes, size_t size) {
    const std::filesystem::path tmp = path.string() + ".tmp";
    // Owner-only (wire/private_files.hpp); fchmod as well, for a NAME.tmp that an older version left readable.
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) return errnoStatus("cannot create " + tmp.string());
    if (::fchmod(fd, 0600) != 0) {
        const Status s = errnoStatus("cannot make " + tmp.string() + " private");
        ::close(fd);
        return s;
    }
    const auto* p = static_cast<const char*>(bytes);
    size_t left = size;
    while (left > 0) {
        const ssize_t n = ::write(fd, p, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const Status s = errnoStatus("cannot write " + tmp.string());
            ::close(fd);
            ::unlink(tmp.c_str());
            return s;
        }
        p += n;
        left -= static_cast<size_t>(n);
    }
    // The data must be on disk before the rename makes it visible under the final name.
    if (::fsync(fd) != 0) {
        const Status s = errnoStatus("cannot sync " + tmp.string());
        ::close(fd);
        ::unlink(tmp.c_str());
        return s;
    }
    ::close(fd);
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
        const Status s = errnoStatus("cannot rename " + tmp.string() + " to " + path.string());
        ::unlink(tmp.c_str());
        return s;
    }
    // And the rename itself must survive a crash: sync the directory entry.
    const std::filesystem::path dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0) {
        (void)::fsync(dfd);
        ::close(dfd);
    }
    return Status::ok();
}

StatusOr<std::string> meshToPly(const recon::IndexedMesh& mesh) {
    return recon::meshFileBytes(mesh, recon::MeshFileFormat::kPly);
}

Status writeSessionFiles(const std::filesystem::path& dir, const SessionFiles& files) {
    RETURN_IF_ERROR(wire::createPrivateDir(dir));
    if (files.mesh && !files.mesh->triangles.empty()) {
        ASSIGN_OR_RETURN(const std::string ply, meshToPly(*files.mesh));
        RETURN_IF_ERROR(writeFileAtomic(dir / "mesh.ply", ply));
        if (files.draco && !files.draco->empty()) {
            RETURN_IF_ERROR(writeFileAtomic(dir / "mesh.drc", files.draco->data(), files.draco->size()));
        }
    }
    if (files.textured && files.textured->valid()) {
        ASSIGN_OR_RETURN(const recon::TexturedObjFiles obj, recon::texturedObjFiles(*files.textured, "textured"));
        ASSIGN_OR_RETURN(const std::string ply, recon::texturedPlyBytes(*files.textured, "textured.png"));
        RETURN_IF_ERROR(writeFileAtomic(dir / "textured.png", obj.png));
        RETURN_IF_ERROR(writeFileAtomic(dir / "textured.mtl", obj.mtl));
        RETURN_IF_ERROR(writeFileAtomic(dir / "textured.obj", obj.obj));
        RETURN_IF_ERROR(writeFileAtomic(dir / "textured.ply", ply));
        if (files.textured_draco && !files.textured_draco->empty()) {
            RETURN_IF_ERROR(
                writeFileAtomic(dir / "textured.drc", files.textured_draco->data(), files.textured_draco->size()));
        }
    }
    RETURN_IF_ERROR(writeFileAtomic(dir / "trajectory.txt", files.trajectory_tum));
    if (!files.frames_tsv.empty()) RETURN_IF_ERROR(writeFileAtomic(dir / "frames.tsv", files.frames_tsv));
    if (files.preview_png && !files.preview_png->empty()) {
        RETURN_IF_ERROR(writeFileAtomic(dir / "preview.png", files.preview_png->data(), files.preview_png->size()));
    }
    return writeFileAtomic(dir / "summary.json", files.summary_json);
}

Status checkDataDir(const std::filesystem::path& dir) {
    std::error_code ec;
    if (Status s = wire::createPrivateDir(dir); !s.isOk()) {
        return Status(s.code() == StatusCode::kInvalidArgument ? s.code() : StatusCode::kUnavailable,
                      "data dir " + dir.string() + ": " + s.message());
    }
    const std::filesystem::path probe = dir / (".write-test-" + std::to_string(::getpid()));
    const Status s = writeFileAtomic(probe, std::string("facescan"));
    std::filesystem::remove(probe, ec);
    if (!s.isOk()) return unavailable("data dir " + dir.string() + " is not writable: " + s.message());
    return Status::ok();
}

std::string jsonEscape(const std::string& s) {
    std::string out;
    out.reserve(s.size() + 2);
    for (const char c : s) {
        switch (c) {
            case '"': out += "\\\""; break;
            case '\\': out += "\\\\"; break;
            case '\n': out += "\\n"; break;
            case '\t': out += "\\t"; break;
            default:
                if (static_cast<unsigned char>(c) < 0x20) {
                    char buf[8];
                    std::snprintf(buf, sizeof(buf), "\\u%04x", static_cast<unsigned>(static_cast<unsigned char>(c)));
                    out += buf;
                } else {
                    out += c;
                }
        }
    }
    return out;
}

std::optional<std::pair<std::string, uint32_t>> readSessionOwner(const std::filesystem::path& dir) {
    std::ifstream in(dir / "owner.json");
    if (!in) return std::nullopt;
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    static const std::regex kOwner(R"re("server_id"\s*:\s*"([A-Za-z0-9._-]+)"[\s\S]*?"epoch"\s*:\s*([0-9]{1,9}))re");
    std::smatch m;
    if (!std::regex_search(text, m, kOwner)) return std::nullopt;
    return std::make_pair(m[1].str(), static_cast<uint32_t>(std::stoul(m[2].str())));
}

StatusOr<std::filesystem::path> claimSessionDir(const std::filesystem::path& data_dir, const std::string& session_id,
                                                const std::string& server_id, uint32_t epoch, std::string* note) {
    // An erased scan is never written again: not by a late replica, a finish or a resume.
    if (isErased(data_dir, session_id)) {
        return permissionDenied("session " + session_id + " was erased from " + data_dir.string() +
                                " (its tombstone is in @erased/): nothing of it is written again");
    }
    std::filesystem::path dir = data_dir / session_id;
    RETURN_IF_ERROR(wire::createPrivateDir(dir));
    const auto current = readSessionOwner(dir);
    std::string previous;
    if (current && current->first != server_id) {
        if (current->second >= epoch) {
            // Another server owns this folder at our epoch or later: write beside it, never over it.
            dir /= server_id + ".e" + std::to_string(epoch);
            RETURN_IF_ERROR(wire::createPrivateDir(dir));
            if (note) {
                *note = "session " + session_id + ": " + (data_dir / session_id).string() + " belongs to server '" +
                        current->first + "' (epoch " + std::to_string(current->second) +
                        "); this server's files (epoch " + std::to_string(epoch) + ") go to " + dir.string();
            }
        } else {
            previous = ", \"previous\": {\"server_id\": \"" + current->first +
                       "\", \"epoch\": " + std::to_string(current->second) + "}";
        }
    } else if (current && current->second >= epoch) {
        return dir;  // ours already
    }
    const std::string owner =
        "{\"server_id\": \"" + jsonEscape(server_id) + "\", \"epoch\": " + std::to_string(epoch) + previous + "}\n";
    RETURN_IF_ERROR(writeFileAtomic(dir / "owner.json", owner));
    return dir;
}

void removeReplicaLog(const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::remove(dir / "replica.log", ec);
    std::filesystem::remove(dir / "replica.log.tmp", ec);
}

namespace {

std::optional<InterruptedFinish> removeInterruptedFinish(const std::filesystem::path& dir,
                                                         const std::string& server_id) {
    std::error_code ec;
    const auto owner = readSessionOwner(dir);
    if (!owner || owner->first != server_id) return std::nullopt;
    if (std::filesystem::exists(dir / "summary.json", ec) || std::filesystem::exists(dir / "replica.log", ec)) {
        return std::nullopt;  // finished, or resumable from its replica
    }
    InterruptedFinish cut{dir, {}};
    bool others = false;             // sub-folders (another owner's files beside), kept
    std::vector<std::string> files;  // listed first, removed after: not while the folder is read
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
        const std::string name = entry.path().filename().string();
        if (!entry.is_regular_file(ec) || entry.is_symlink(ec)) {
            others = true;
        } else if (name != "owner.json") {
            files.push_back(name);
        }
    }
    std::sort(files.begin(), files.end());
    for (const std::string& name : files) {
        if (std::filesystem::remove(dir / name, ec)) cut.removed.push_back(name);
    }
    if (cut.removed.empty()) return std::nullopt;
    if (!others) {
        std::filesystem::remove(dir / "owner.json", ec);
        std::filesystem::remove(dir, ec);
    }
    return cut;
}

}  // namespace

std::vector<InterruptedFinish> removeInterruptedFinishes(const std::filesystem::path& data_dir,
                                                         const std::string& server_id) {
    std::vector<InterruptedFinish> out;
    std::error_code ec;
    std::vector<std::filesystem::path> sessions;
    for (const auto& entry : std::filesystem::directory_iterator(data_dir, ec)) {
        if (entry.is_directory(ec) && !entry.is_symlink(ec)) sessions.push_back(entry.path());
    }
    std::sort(sessions.begin(), sessions.end());
    const std::string beside = server_id + ".e";
    for (const std::filesystem::path& session : sessions) {
        std::vector<std::filesystem::path> mine;
        for (const auto& entry : std::filesystem::directory_iterator(session, ec)) {
            const std::string name = entry.path().filename().string();
            if (name.rfind(beside, 0) == 0 && entry.is_directory(ec) && !entry.is_symlink(ec)) {
                mine.push_back(entry.path());
            }
        }
        std::sort(mine.begin(), mine.end());
        for (const std::filesystem::path& dir : mine) {
            if (auto cut = removeInterruptedFinish(dir, server_id)) out.push_back(std::move(*cut));
        }
        if (auto cut = removeInterruptedFinish(session, server_id)) out.push_back(std::move(*cut));
    }
    return out;
}

}  // namespace facescan::service
