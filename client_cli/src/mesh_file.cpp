// Atomic output files: temporary file in the target's folder (so rename(2) stays on one file system and is
// atomic), fsync, rename; the temporary is removed on every failure path.
#include "client/mesh_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/System/omstream.hh>
#include <algorithm>
#include <cerrno>
#include <cstring>
#include <sstream>

#include "client/gltf_mesh.hpp"
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

// OBJ written here: OpenMesh's OBJ writer keeps colours only as per-face materials in a separate .mtl file, and
// cannot write those into a stream. Vertex colours go on the `v` lines (x y z r g b, colours in [0, 1]), the
// extension MeshLab, Blender, Open3D and OpenMesh's own reader understand.
std::string objText(const recon::Mesh& mesh) {
    std::ostringstream out;
    out.precision(9);
    out << "# facescan mesh: metres, " << mesh.n_vertices() << " vertices, " << mesh.n_faces() << " triangles\n";
    const bool colours = mesh.has_vertex_colors();
    const bool normals = mesh.has_vertex_normals();
    for (const auto vh : mesh.vertices()) {
        const auto& p = mesh.point(vh);
        out << "v " << p[0] << ' ' << p[1] << ' ' << p[2];
        if (colours) {
            const auto& c = mesh.color(vh);
            out.precision(6);
            out << ' ' << c[0] / 255.0 << ' ' << c[1] / 255.0 << ' ' << c[2] / 255.0;
            out.precision(9);
        }
        out << '\n';
    }
    if (normals) {
        for (const auto vh : mesh.vertices()) {
            const auto& n = mesh.normal(vh);
            out << "vn " << n[0] << ' ' << n[1] << ' ' << n[2] << '\n';
        }
    }
    for (const auto fh : mesh.faces()) {
        out << 'f';
        for (const auto vh : mesh.fv_range(fh)) {
            const int i = vh.idx() + 1;  // OBJ indices start at 1
            out << ' ' << i;
            if (normals) out << "//" << i;
        }
        out << '\n';
    }
    return out.str();
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

StatusOr<std::string> encodeMeshFile(const recon::Mesh& mesh, MeshFormat format,
                                     const std::vector<uint8_t>* draco_bytes) {
    if (format == MeshFormat::kDrc && draco_bytes) {
        return std::string(reinterpret_cast<const char*>(draco_bytes->data()), draco_bytes->size());
    }
    if (mesh.n_faces() == 0) return invalidArgument("the mesh has no triangles");
    if (format == MeshFormat::kDrc) {
        std::vector<uint8_t> encoded;
        RETURN_IF_ERROR(wire::encodeMeshDraco(mesh, wire::MeshCodecParams{}, encoded));
        return std::string(reinterpret_cast<const char*>(encoded.data()), encoded.size());
    }
    if (format == MeshFormat::kObj) return objText(mesh);
    if (format == MeshFormat::kGlb) return meshToGlb(mesh);

    using OpenMesh::IO::Options;
    Options opts;
    switch (format) {
        case MeshFormat::kPly: opts = Options(Options::Binary | Options::VertexNormal | Options::VertexColor); break;
        case MeshFormat::kOff: opts = Options(Options::VertexNormal | Options::VertexColor); break;
        case MeshFormat::kStl: opts = Options(Options::Binary); break;
        case MeshFormat::kObj:
        case MeshFormat::kDrc:
        case MeshFormat::kGlb: break;
    }
    if (!mesh.has_vertex_normals()) opts -= Options::VertexNormal;
    if (!mesh.has_vertex_colors()) opts -= Options::VertexColor;
    // OpenMesh writes into memory: its writers report failure only as a bool, so the file itself is written (and
    // its errors reported) by writeFileAtomically.
    std::ostringstream out(std::ios::binary);
    omlog().disable();  // OpenMesh's writers chatter on the log stream ("[STLWriter] : write binary file")
    // Positions in metres: 6 significant digits would round to 1 micron at 1 m; 9 keep floats exact.
    if (!OpenMesh::IO::write_mesh(mesh, out, std::string(".") + meshFormatName(format), opts, 9)) {
        return internalError(std::string("OpenMesh could not encode the mesh as ") + meshFormatName(format));
    }
    return std::move(out).str();
}

Status writeMeshFile(const recon::Mesh& mesh, const fs::path& path, const std::vector<uint8_t>* draco_bytes) {
    ASSIGN_OR_RETURN(const MeshFormat format, meshFormatFor(path));
    auto bytes = encodeMeshFile(mesh, format, draco_bytes);
    if (!bytes.isOk()) {
        if (bytes.status().code() != StatusCode::kInvalidArgument) return bytes.status();
        return invalidArgument(bytes.status().message() + "; nothing to write to '" + path.string() + "'");
    }
    return writeFileAtomically(path, *bytes);
}

}  // namespace facescan::client
