#include "recon/mesh_writer.hpp"

#include <Eigen/Geometry>
#include <OpenMesh/Core/IO/IOManager.hh>
#include <OpenMesh/Core/IO/exporter/BaseExporter.hh>
#include <OpenMesh/Core/System/omstream.hh>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <unordered_set>

namespace facescan::recon {
namespace {

using OpenMesh::Vec2f;
using OpenMesh::Vec3d;
using OpenMesh::Vec3f;
using OpenMesh::Vec3uc;
using OpenMesh::Vec3ui;
using OpenMesh::Vec4f;
using OpenMesh::Vec4uc;
using OpenMesh::Vec4ui;
using StatusInfo = OpenMesh::Attributes::StatusInfo;

// OpenMesh's writers see the arrays through this: vertex i is VertexHandle(i), triangle f is FaceHandle(f).
// Colour-less, normal-less queries (faces, edges, texture coordinates, half-edges) answer neutral values: the
// writers ask for them only when the options request them, and ours never do.
class ArrayExporter final : public OpenMesh::IO::BaseExporter {
 public:
    // uv_ply: per-vertex texture coordinates with v up (OBJ's and PLY readers' convention), or null.
    ArrayExporter(const IndexedMesh& mesh, const std::vector<Eigen::Vector3f>& normals,
                  const std::vector<Eigen::Vector2f>* uv_ply = nullptr)
        : mesh_(mesh), normals_(normals), uv_(uv_ply) {}

    Vec3f point(OpenMesh::VertexHandle vh) const override { return vec(mesh_.positions_m[at(vh)]); }
    Vec3d pointd(OpenMesh::VertexHandle vh) const override { return Vec3d(point(vh)); }
    bool is_point_double() const override { return false; }
    Vec3f normal(OpenMesh::VertexHandle vh) const override { return vec(normals_[at(vh)]); }
    Vec3d normald(OpenMesh::VertexHandle vh) const override { return Vec3d(normal(vh)); }
    bool is_normal_double() const override { return false; }
    Vec3uc color(OpenMesh::VertexHandle vh) const override {
        const Rgb8& c = mesh_.colours_rgb[at(vh)];
        return Vec3uc(c[0], c[1], c[2]);
    }
    Vec4uc colorA(OpenMesh::VertexHandle vh) const override {
        const Vec3uc c = color(vh);
        return Vec4uc(c[0], c[1], c[2], 255);
    }
    Vec3ui colori(OpenMesh::VertexHandle vh) const override { return Vec3ui(color(vh)); }
    Vec4ui colorAi(OpenMesh::VertexHandle vh) const override { return Vec4ui(colorA(vh)); }
    Vec3f colorf(OpenMesh::VertexHandle vh) const override { return Vec3f(color(vh)) / 255.0f; }
    Vec4f colorAf(OpenMesh::VertexHandle vh) const override { return Vec4f(colorA(vh)) / 255.0f; }
    Vec2f texcoord(OpenMesh::VertexHandle vh) const override {
        if (!uv_) return Vec2f(0, 0);
        const Eigen::Vector2f& t = (*uv_)[at(vh)];
        return Vec2f(t.x(), t.y());
    }
    Vec2f texcoord(OpenMesh::HalfedgeHandle) const override { return Vec2f(0, 0); }
    StatusInfo status(OpenMesh::VertexHandle) const override { return {}; }

    unsigned int get_vhandles(OpenMesh::FaceHandle fh, std::vector<OpenMesh::VertexHandle>& out) const override {
        out.clear();
        for (const uint32_t v : mesh_.triangles[at(fh)]) out.emplace_back(static_cast<int>(v));
        return 3;
    }
    OpenMesh::HalfedgeHandle getHeh(OpenMesh::FaceHandle, OpenMesh::VertexHandle) const override {
        return OpenMesh::HalfedgeHandle();
    }
    unsigned int get_face_texcoords(std::vector<Vec2f>&) const override { return 0; }
    Vec3f normal(OpenMesh::FaceHandle fh) const override {
        const Triangle& t = mesh_.triangles[at(fh)];
        const Eigen::Vector3f& a = mesh_.positions_m[t[0]];
        const Eigen::Vector3f n = (mesh_.positions_m[t[1]] - a).cross(mesh_.positions_m[t[2]] - a);
        const float len = n.norm();
        return len > 0.0f ? vec(n / len) : Vec3f(0, 0, 0);
    }
    Vec3d normald(OpenMesh::FaceHandle fh) const override { return Vec3d(normal(fh)); }
    Vec3uc color(OpenMesh::FaceHandle) const override { return Vec3uc(200, 200, 200); }
    Vec4uc colorA(OpenMesh::FaceHandle) const override { return Vec4uc(200, 200, 200, 255); }
    Vec3ui colori(OpenMesh::FaceHandle) const override { return Vec3ui(200, 200, 200); }
    Vec4ui colorAi(OpenMesh::FaceHandle) const override { return Vec4ui(200, 200, 200, 255); }
    Vec3f colorf(OpenMesh::FaceHandle) const override { return Vec3f(0.8f, 0.8f, 0.8f); }
    Vec4f colorAf(OpenMesh::FaceHandle) const override { return Vec4f(0.8f, 0.8f, 0.8f, 1.0f); }
    StatusInfo status(OpenMesh::FaceHandle) const override { return {}; }
    Vec3uc color(OpenMesh::EdgeHandle) const override { return Vec3uc(0, 0, 0); }
    Vec4uc colorA(OpenMesh::EdgeHandle) const override { return Vec4uc(0, 0, 0, 255); }
    Vec3ui colori(OpenMesh::EdgeHandle) const override { return Vec3ui(0, 0, 0); }
    Vec4ui colorAi(OpenMesh::EdgeHandle) const override { return Vec4ui(0, 0, 0, 255); }
    Vec3f colorf(OpenMesh::EdgeHandle) const override { return Vec3f(0, 0, 0); }
    Vec4f colorAf(OpenMesh::EdgeHandle) const override { return Vec4f(0, 0, 0, 1); }
    StatusInfo status(OpenMesh::EdgeHandle) const override { return {}; }
    int get_halfedge_id(OpenMesh::VertexHandle) override { return -1; }
    int get_halfedge_id(OpenMesh::FaceHandle) override { return -1; }
    int get_next_halfedge_id(OpenMesh::HalfedgeHandle) override { return -1; }
    int get_to_vertex_id(OpenMesh::HalfedgeHandle) override { return -1; }
    int get_face_id(OpenMesh::HalfedgeHandle) override { return -1; }
    StatusInfo status(OpenMesh::HalfedgeHandle) const override { return {}; }

    // OpenMesh's PLY writer looks for custom properties in the kernel: an empty one has none.
    const OpenMesh::BaseKernel* kernel() override { return &no_properties_; }

    size_t n_vertices() const override { return mesh_.vertexCount(); }
    size_t n_faces() const override { return mesh_.triangleCount(); }
    size_t n_edges() const override {  // OFF's header names it; counted once, on demand
        if (edges_ == 0) {
            std::unordered_set<uint64_t> edges;
            edges.reserve(mesh_.triangleCount() * 2);
            for (const Triangle& t : mesh_.triangles) {
                for (int i = 0; i < 3; ++i) {
                    const uint32_t a = std::min(t[i], t[(i + 1) % 3]), b = std::max(t[i], t[(i + 1) % 3]);
                    edges.insert(uint64_t(a) << 32 | b);
                }
            }
            edges_ = edges.size();
        }
        return edges_;
    }
    bool is_triangle_mesh() const override { return true; }
    bool has_vertex_normals() const override { return true; }
    bool has_vertex_colors() const override { return mesh_.hasColours(); }
    bool has_vertex_texcoords() const override { return uv_ != nullptr; }

 private:
    static Vec3f vec(const Eigen::Vector3f& v) { return Vec3f(v.x(), v.y(), v.z()); }
    template <class Handle>
    static size_t at(Handle h) {
        return static_cast<size_t>(h.idx());
    }
    const IndexedMesh& mesh_;
    const std::vector<Eigen::Vector3f>& normals_;
    const std::vector<Eigen::Vector2f>* uv_;
    mutable size_t edges_ = 0;
    OpenMesh::BaseKernel no_properties_;
};

// uv (glTF's convention, v down) as OBJ and PLY readers take it: v up.
std::vector<Eigen::Vector2f> uvUp(const std::vector<Eigen::Vector2f>& uv) {
    std::vector<Eigen::Vector2f> out;
    out.reserve(uv.size());
    for (const Eigen::Vector2f& t : uv) out.emplace_back(t.x(), 1.0f - t.y());
    return out;
}

Status checkTextured(const TexturedMesh& mesh) {
    if (mesh.mesh.triangles.empty()) return invalidArgument("the mesh has no triangles");
    if (mesh.uv.size() != mesh.mesh.vertexCount() || mesh.atlas_bgr.empty()) {
        return invalidArgument("the mesh has no texture: texture coordinates and an atlas are needed");
    }
    return Status::ok();
}

// `uv_up`: texture coordinates to write (vt lines, faces v/vt/vn) and `mtl`: the material file to name, or null.
std::string objText(const IndexedMesh& mesh, const std::vector<Eigen::Vector3f>& normals,
                    const std::vector<Eigen::Vector2f>* uv_up = nullptr, const std::string& mtl = {}) {
    std::ostringstream out;
    out.precision(9);
    out << "# facescan mesh: metres, " << mesh.vertexCount() << " vertices, " << mesh.triangleCount() << " triangles\n";
    if (uv_up) out << "mtllib " << mtl << "\nusemtl facescan\n";
    const bool colours = mesh.hasColours();
    for (size_t i = 0; i < mesh.vertexCount(); ++i) {
        const Eigen::Vector3f& p = mesh.positions_m[i];
        out << "v " << p.x() << ' ' << p.y() << ' ' << p.z();
        if (colours) {  // the `v x y z r g b` extension that MeshLab, Blender, Open3D and OpenMesh read
            const Rgb8& c = mesh.colours_rgb[i];
            out.precision(6);
            out << ' ' << c[0] / 255.0 << ' ' << c[1] / 255.0 << ' ' << c[2] / 255.0;
            out.precision(9);
        }
        out << '\n';
    }
    if (uv_up) {
        for (const Eigen::Vector2f& t : *uv_up) out << "vt " << t.x() << ' ' << t.y() << '\n';
    }
    for (const Eigen::Vector3f& n : normals) out << "vn " << n.x() << ' ' << n.y() << ' ' << n.z() << '\n';
    const char* sep = uv_up ? "/" : "//";
    for (const Triangle& t : mesh.triangles) {
        out << 'f';
        for (const uint32_t v : t) {  // OBJ indices start at 1; vertex, texture and normal indices coincide
            out << ' ' << v + 1 << sep;
            if (uv_up) out << v + 1 << '/';
            out << v + 1;
        }
        out << '\n';
    }
    return out.str();
}

}  // namespace

StatusOr<std::string> atlasPngBytes(const TexturedMesh& mesh) {
    RETURN_IF_ERROR(checkTextured(mesh));
    std::vector<uint8_t> png;
    if (!cv::imencode(".png", mesh.atlas_bgr, png)) return internalError("OpenCV could not encode the texture as PNG");
    return std::string(png.begin(), png.end());
}

StatusOr<TexturedObjFiles> texturedObjFiles(const TexturedMesh& mesh, const std::string& stem) {
    RETURN_IF_ERROR(checkTextured(mesh));
    if (stem.empty() || stem.find_first_of("/\\ \n\r") != std::string::npos) {
        return invalidArgument("the OBJ's file name stem must be a plain name without spaces or folders, got '" + stem +
                               "'");
    }
    const std::vector<Eigen::Vector3f> normals = mesh.mesh.hasNormals() ? mesh.mesh.normals : vertexNormals(mesh.mesh);
    const std::vector<Eigen::Vector2f> uv = uvUp(mesh.uv);
    TexturedObjFiles files;
    files.obj = objText(mesh.mesh, normals, &uv, stem + ".mtl");
    // A matte material: the texture is the surface's colour as lit when scanned.
    files.mtl = "# facescan texture\nnewmtl facescan\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd " + stem + ".png\n";
    ASSIGN_OR_RETURN(files.png, atlasPngBytes(mesh));
    return files;
}

StatusOr<std::string> texturedPlyBytes(const TexturedMesh& mesh, const std::string& texture_file) {
    RETURN_IF_ERROR(checkTextured(mesh));
    const std::vector<Eigen::Vector3f> normals = mesh.mesh.hasNormals() ? mesh.mesh.normals : vertexNormals(mesh.mesh);
    const std::vector<Eigen::Vector2f> uv = uvUp(mesh.uv);
    using OpenMesh::IO::Options;
    Options opts(Options::Binary | Options::VertexNormal | Options::VertexTexCoord);
    if (mesh.mesh.hasColours()) opts += Options::VertexColor;
    ArrayExporter exporter(mesh.mesh, normals, &uv);
    std::ostringstream out(std::ios::binary);
    omlog().disable();
    if (!OpenMesh::IO::IOManager().write(out, ".ply", exporter, opts, 9)) {
        return internalError("OpenMesh could not write the textured mesh as PLY");
    }
    std::string bytes = std::move(out).str();
    // The image's name in the header, after the format line (MeshLab's `comment TextureFile`).
    const size_t format_end = bytes.find('\n', bytes.find("format "));
    if (format_end == std::string::npos) return internalError("OpenMesh's PLY has no format line");
    bytes.insert(format_end + 1, "comment TextureFile " + texture_file + "\n");
    return bytes;
}

StatusOr<std::string> meshFileBytes(const IndexedMesh& mesh, MeshFileFormat format) {
    if (mesh.triangles.empty()) return invalidArgument("the mesh has no triangles");
    std::vector<Eigen::Vector3f> computed;
    if (!mesh.hasNormals() && format != MeshFileFormat::kStl) computed = vertexNormals(mesh);
    const std::vector<Eigen::Vector3f>& normals = mesh.hasNormals() ? mesh.normals : computed;
    if (format == MeshFileFormat::kObj) return objText(mesh, normals);

    using OpenMesh::IO::Options;
    Options opts;
    const char* ext = ".ply";
    switch (format) {
        case MeshFileFormat::kPly: opts = Options(Options::Binary | Options::VertexNormal); break;
        case MeshFileFormat::kOff: opts = Options(Options::VertexNormal), ext = ".off"; break;
        case MeshFileFormat::kStl: opts = Options(Options::Binary), ext = ".stl"; break;
        case MeshFileFormat::kObj: break;
    }
    if (mesh.hasColours() && format != MeshFileFormat::kStl) opts += Options::VertexColor;
    ArrayExporter exporter(mesh, normals);
    std::ostringstream out(std::ios::binary);
    omlog().disable();  // OpenMesh's writers chatter on the log stream ("[STLWriter] : write binary file")
    // Positions in metres: 6 significant digits would round to 1 micron at 1 m; 9 keep floats exact.
    if (!OpenMesh::IO::IOManager().write(out, ext, exporter, opts, 9)) {
        return internalError(std::string("OpenMesh could not write the mesh as ") + (ext + 1));
    }
    return std::move(out).str();
}

}  // namespace facescan::recon
