// Atomic output files: temporary file in the target's folder (so rename(2) stays on one file system and is
// atomic), fsync, rename; the temporary is removed on every failure path.
#include "client/mesh_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <sstream>

#include "client/gltf_mesh.hpp"
#include "recon/mesh_writer.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::client {
namespace fs = std::filesystem;

namespace {

std::string lowerExtension(const fs::path& path) {
    std::string ext = path.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    return ext;
}

Status cannotWrite(const fs::path& path, const std::string& why) {
    return unavailable("cannot write '" + path.string() + "': " + why);
}

fs::path folderOf(const fs::path& path) {
    const fs::path parent = path.parent_path();
    return parent.empty() ? fs::path(".") : parent;
}

}  // namespace

StatusOr<MeshFormat> meshFormatFor(const fs::path& path) {
    const std::string ext = lowerExtension(path);
    if (ext == ".ply") return MeshFormat::kPly;
    if (ext == ".obj") return MeshFormat::kObj;
    if (ext == ".stl") return MeshFormat::kStl;
    if (ext == ".off") return MeshFormat::kOff;
    if (ext == ".drc") return MeshFormat::kDrc;
    if (ext == ".glb") return MeshFormat::kGlb;
    return invalidArgument("unknown mesh format '" + (ext.empty() ? path.string() : ext) +
                           "': use .ply .obj .stl .off .drc or .glb");
}

const char* meshFormatName(MeshFormat format) {
    switch (format) {
        case MeshFormat::kPly: return "ply";
        case MeshFormat::kObj: return "obj";
        case MeshFormat::kStl: return "stl";
        case MeshFormat::kOff: return "off";
        case MeshFormat::kDrc: return "drc";
        case MeshFormat::kGlb: return "glb";
    }
    return "?";
}

const char* meshMimeType(MeshFormat format) {
    switch (format) {
        case MeshFormat::kPly: return "application/x-ply";  // no registered type; MeshLab's and Blender's name
        case MeshFormat::kObj: return "model/obj";
        case MeshFormat::kStl: return "model/stl";
        case MeshFormat::kGlb: return "model/gltf-binary";
        case MeshFormat::kOff:
        case MeshFormat::kDrc: break;
    }
    return "application/octet-stream";
}

bool formatHasColours(MeshFormat format) { return format != MeshFormat::kStl; }

Status checkWritable(const fs::path& path) {
    std::error_code ec;
    if (path.empty()) return cannotWrite(path, "empty file name");
    if (fs::is_directory(path, ec)) return cannotWrite(path, "it is a folder");
    const fs::path folder = folderOf(path);
    if (!fs::exists(folder, ec)) return cannotWrite(path, "folder '" + folder.string() + "' does not exist");
    if (!fs::is_directory(folder, ec)) return cannotWrite(path, "'" + folder.string() + "' is not a folder");
    // The temporary file is created in the folder, so the folder (not only the file) must be writable.
    if (::access(folder.c_str(), W_OK | X_OK) != 0) {
        return cannotWrite(path, "folder '" + folder.string() + "' is not writable (" + std::strerror(errno) + ")");
    }
    return Status::ok();
}

Status writeFileAtomically(const fs::path& path, std::string_view bytes) {
    RETURN_IF_ERROR(checkWritable(path));
    // Hidden, unique per process and call: concurrent writers of one target never share a temporary.
    static int counter = 0;
    const fs::path tmp = folderOf(path) / ("." + path.filename().string() + ".tmp" + std::to_string(::getpid()) + "-" +
                                           std::to_string(counter++));
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) return cannotWrite(path, std::strerror(errno));
    size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const std::string why = n < 0 ? std::strerror(errno) : "short write";
            ::close(fd);
            ::unlink(tmp.c_str());
            return cannotWrite(path, why);
        }
        done += static_cast<size_t>(n);
    }
    // fsync before rename: after a crash the target is either the old file or the complete new one.
    if (::fsync(fd) != 0 || ::close(fd) != 0) {
        const std::string why = std::strerror(errno);
        ::unlink(tmp.c_str());
        return cannotWrite(path, why);
    }
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
        const std::string why = std::strerror(errno);
        ::unlink(tmp.c_str());
        return cannotWrite(path, why);
    }
    return Status::ok();
}

StatusOr<std::string> encodeMeshFile(const recon::IndexedMesh& mesh, MeshFormat format,
                                     const std::vector<uint8_t>* draco_bytes) {
    if (format == MeshFormat::kDrc && draco_bytes) {
        return std::string(reinterpret_cast<const char*>(draco_bytes->data()), draco_bytes->size());
    }
    if (mesh.triangles.empty()) return invalidArgument("the mesh has no triangles");
    switch (format) {
        case MeshFormat::kDrc: {
            std::vector<uint8_t> encoded;
            RETURN_IF_ERROR(wire::encodeMeshDraco(mesh, wire::MeshCodecParams{}, encoded));
            return std::string(reinterpret_cast<const char*>(encoded.data()), encoded.size());
        }
        case MeshFormat::kGlb: return meshToGlb(mesh);
        case MeshFormat::kPly: return recon::meshFileBytes(mesh, recon::MeshFileFormat::kPly);
        case MeshFormat::kObj: return recon::meshFileBytes(mesh, recon::MeshFileFormat::kObj);
        case MeshFormat::kStl: return recon::meshFileBytes(mesh, recon::MeshFileFormat::kStl);
        case MeshFormat::kOff: return recon::meshFileBytes(mesh, recon::MeshFileFormat::kOff);
    }
    return invalidArgument("unknown mesh format");
}

StatusOr<std::string> encodeMeshFile(const recon::Mesh& mesh, MeshFormat format,
                                     const std::vector<uint8_t>* draco_bytes) {
    return encodeMeshFile(recon::fromOpenMesh(mesh), format, draco_bytes);
}

Status writeMeshFile(const recon::IndexedMesh& mesh, const fs::path& path, const std::vector<uint8_t>* draco_bytes) {
    ASSIGN_OR_RETURN(const MeshFormat format, meshFormatFor(path));
    auto bytes = encodeMeshFile(mesh, format, draco_bytes);
    if (!bytes.isOk()) {
        if (bytes.status().code() != StatusCode::kInvalidArgument) return bytes.status();
        return invalidArgument(bytes.status().message() + "; nothing to write to '" + path.string() + "'");
    }
    return writeFileAtomically(path, *bytes);
}

}  // namespace facescan::client

namespace facescan::client {

Status writeMeshFile(const recon::Mesh& mesh, const fs::path& path, const std::vector<uint8_t>* draco_bytes) {
    return writeMeshFile(recon::fromOpenMesh(mesh), path, draco_bytes);
}

}  // namespace facescan::client
