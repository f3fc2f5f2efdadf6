// Mesh file I/O through OpenMesh: formats by extension, vertex colours and normals kept when present.
#include "eval/mesh_io.hpp"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <system_error>

namespace facescan::eval {

StatusOr<recon::Mesh> readMesh(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) return notFound("mesh file not found: " + path.string());
    recon::Mesh mesh;
    OpenMesh::IO::Options opts = OpenMesh::IO::Options::VertexColor | OpenMesh::IO::Options::VertexNormal;
    if (!OpenMesh::IO::read_mesh(mesh, path.string(), opts)) {
        return dataLoss("cannot read mesh " + path.string() + " (unknown format or corrupt)");
    }
    if (mesh.n_vertices() == 0) return dataLoss("mesh " + path.string() + " has no vertices");
    mesh.update_face_normals();
    if (!opts.check(OpenMesh::IO::Options::VertexNormal)) mesh.update_vertex_normals();
    return mesh;
}

Status writeMesh(const recon::Mesh& mesh, const std::filesystem::path& path) {
    OpenMesh::IO::Options opts = OpenMesh::IO::Options::VertexNormal | OpenMesh::IO::Options::VertexColor;
    if (path.extension() == ".ply" || path.extension() == ".PLY") opts += OpenMesh::IO::Options::Binary;
    if (path.extension() == ".stl" || path.extension() == ".STL") opts = OpenMesh::IO::Options::Binary;
    if (!OpenMesh::IO::write_mesh(mesh, path.string(), opts)) {
        return unavailable("cannot write mesh " + path.string());
    }
    return Status::ok();
}

}  // namespace facescan::eval
