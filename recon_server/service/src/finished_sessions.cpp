#include "service/finished_sessions.hpp"

#include <algorithm>
#include <fstream>
#include <iterator>
#include <regex>

#include "service/session_store.hpp"
#include "wire/mesh_codec.hpp"
#include "wire/messages.hpp"

namespace facescan::service {

FinishedSessions::FinishedSessions(int keep, double keep_s)
    : keep_(static_cast<size_t>(std::max(0, keep))), keep_ns_(static_cast<int64_t>(keep_s * 1e9)) {}

void FinishedSessions::add(FinishedSession session) {
    std::lock_guard lk(mutex_);
    // A session id that finished here before (reused by a new scan): the newer record replaces the older one.
    std::erase_if(list_, [&](const FinishedSession& f) { return f.stats.session_id == session.stats.session_id; });
    list_.push_back(std::move(session));
}

std::optional<FinishedSession> FinishedSessions::find(const std::string& session_id) const {
    std::lock_guard lk(mutex_);
    for (const FinishedSession& f : list_) {
        if (f.stats.session_id != session_id) continue;
        FinishedSession copy = f;
        copy.claim.reset();
        return copy;
    }
    return std::nullopt;
}

std::optional<FinishedSession> FinishedSessions::remove(const std::string& session_id) {
    std::lock_guard lk(mutex_);
    for (auto it = list_.begin(); it != list_.end(); ++it) {
        if (it->stats.session_id != session_id) continue;
        FinishedSession gone = std::move(*it);
        list_.erase(it);
        return gone;
    }
    return std::nullopt;
}

std::vector<FinishedSession> FinishedSessions::removeIf(const std::function<bool(const SessionStats&)>& drop) {
    std::lock_guard lk(mutex_);
    std::vector<FinishedSession> out;
    for (auto it = list_.begin(); it != list_.end();) {
        if (!drop(it->stats)) {
            ++it;
            continue;
        }
        out.push_back(std::move(*it));
        it = list_.erase(it);
    }
    return out;
}

bool FinishedSessions::replaceClaim(const std::string& session_id, std::shared_ptr<Claim> claim, uint32_t epoch) {
    std::lock_guard lk(mutex_);
    for (FinishedSession& f : list_) {
        if (f.stats.session_id != session_id) continue;
        f.claim = std::move(claim);
        f.stats.epoch = epoch;
        return true;
    }
    return false;
}

std::vector<SessionStats> FinishedSessions::stats() const {
    std::lock_guard lk(mutex_);
    std::vector<SessionStats> out;
    out.reserve(list_.size());
    for (const FinishedSession& f : list_) out.push_back(f.stats);
    return out;
}

size_t FinishedSessions::size() const {
    std::lock_guard lk(mutex_);
    return list_.size();
}

std::vector<FinishedSession> FinishedSessions::expire(int64_t now_ns) {
    std::lock_guard lk(mutex_);
    std::vector<FinishedSession> out;
    while (!list_.empty() && (list_.size() > keep_ || now_ns - list_.front().retired_ns > keep_ns_)) {
        out.push_back(std::move(list_.front()));
        list_.pop_front();
    }
    return out;
}

std::optional<std::filesystem::path> findFinishedSessionDir(const std::filesystem::path& data_dir,
                                                            const std::string& session_id,
                                                            const std::string& server_id) {
    if (!wire::validateSessionId(session_id).isOk()) return std::nullopt;
    const std::filesystem::path main = data_dir / session_id;
    std::error_code ec;
    if (!std::filesystem::is_directory(main, ec)) return std::nullopt;
    const auto complete = [](const std::filesystem::path& dir) {
        std::error_code e;
        return std::filesystem::exists(dir / "summary.json", e);
    };
    if (const auto owner = readSessionOwner(main); owner && owner->first == server_id) {
        return complete(main) ? std::optional(main) : std::nullopt;
    }
    // Written beside another owner's files: SERVER.eEPOCH, the newest epoch first.
    std::optional<std::filesystem::path> best;
    uint32_t best_epoch = 0;
    const std::string prefix = server_id + ".e";
    for (const auto& entry : std::filesystem::directory_iterator(main, ec)) {
        const std::string name = entry.path().filename().string();
        if (name.rfind(prefix, 0) != 0 || !complete(entry.path())) continue;
        const auto owner = readSessionOwner(entry.path());
        if (!owner || owner->first != server_id || (best && owner->second <= best_epoch)) continue;
        best = entry.path();
        best_epoch = owner->second;
    }
    return best;
}

namespace {

std::string readText(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace

StatusOr<std::vector<uint8_t>> readFinishedFile(const std::filesystem::path& dir, const std::string& name) {
    std::ifstream in(dir / name, std::ios::binary);
    if (!in) return notFound("no " + name + " in " + dir.string());
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) return internalError("cannot read " + (dir / name).string());
    return bytes;
}

StatusOr<MeshResult> readFinishedMesh(const std::filesystem::path& dir) {
    std::error_code ec;
    if (!std::filesystem::exists(dir / "mesh.drc", ec)) {
        return notFound("the session finished without a surface (" + dir.string() + " has no mesh.drc)");
    }
    ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, readFinishedFile(dir, "mesh.drc"));
    MeshResult result;
    // The counts as the session reported them (of the mesh before Draco: its decoder may split vertices), from the
    // summary that finalize wrote with the bytes; decoded when the summary does not say.
    const std::string summary = readText(dir / "summary.json");
    static const std::regex kCounts(R"re("mesh"\s*:\s*\{\s*"vertices"\s*:\s*([0-9]{1,9})\s*,)re"
                                    R"re(\s*"triangles"\s*:\s*([0-9]{1,9}))re");
    if (std::smatch m; std::regex_search(summary, m, kCounts)) {
        result.vertex_count = static_cast<uint32_t>(std::stoul(m[1].str()));
        result.triangle_count = static_cast<uint32_t>(std::stoul(m[2].str()));
    } else {
        recon::IndexedMesh mesh;
        RETURN_IF_ERROR(wire::decodeMeshDraco(bytes.data(), bytes.size(), mesh));
        result.vertex_count = static_cast<uint32_t>(mesh.vertexCount());
        result.triangle_count = static_cast<uint32_t>(mesh.triangleCount());
    }
    result.draco = std::make_shared<const std::vector<uint8_t>>(std::move(bytes));
    return result;
}

StatusOr<TexturedResult> readFinishedTexture(const std::filesystem::path& dir) {
    std::error_code ec;
    if (!std::filesystem::exists(dir / "textured.drc", ec) || !std::filesystem::exists(dir / "textured.png", ec)) {
        return notFound("the session finished without a texture (" + dir.string() + " has no textured.drc)");
    }
    ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, readFinishedFile(dir, "textured.drc"));
    TexturedResult result;
    ASSIGN_OR_RETURN(result.png, readFinishedFile(dir, "textured.png"));
    recon::IndexedMesh mesh;
    std::vector<Eigen::Vector2f> uv;
    if (Status s = wire::decodeMeshDraco(bytes.data(), bytes.size(), mesh, uv); !s.isOk()) {
        return dataLoss((dir / "textured.drc").string() + ": " + s.message());
    }
    if (uv.empty()) return dataLoss((dir / "textured.drc").string() + " has no texture coordinates");
    result.mesh.vertex_count = static_cast<uint32_t>(mesh.vertexCount());
    result.mesh.triangle_count = static_cast<uint32_t>(mesh.triangleCount());
    result.mesh.draco = std::make_shared<const std::vector<uint8_t>>(std::move(bytes));
    return result;
}

}  // namespace facescan::service
