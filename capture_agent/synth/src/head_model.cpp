// Loading the real head scan (Lee Perry-Smith) into the head frame of head_model.hpp, and finding it on disk.
#include "synth/head_model.hpp"

#include <unistd.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <vector>

namespace facescan::synth {
namespace {

namespace fs = std::filesystem;

// The nose tip of a mesh with y up and the face along +z: the most forward vertex in the upper 60 % of the
// height (the chest of a bust can stick out further than the nose, the head cannot).
Eigen::Vector3f noseTipOf(const recon::Mesh& mesh) {
    float y_min = std::numeric_limits<float>::max(), y_max = -y_min;
    for (const auto vh : mesh.vertices()) {
        y_min = std::min(y_min, mesh.point(vh)[1]);
        y_max = std::max(y_max, mesh.point(vh)[1]);
    }
    const float y_floor = y_min + 0.4f * (y_max - y_min);
    Eigen::Vector3f best(0, 0, -std::numeric_limits<float>::max());
    for (const auto vh : mesh.vertices()) {
        const auto& p = mesh.point(vh);
        if (p[1] >= y_floor && p[2] > best.z()) best = Eigen::Vector3f(p[0], p[1], p[2]);
    }
    return best;
}

// Scales by `metres_per_unit` and translates so the nose tip lands on (0, 0, 0.10): the head frame.
void toHeadFrame(HeadModel& head, float metres_per_unit) {
    for (const auto vh : head.mesh.vertices()) head.mesh.point(vh) *= metres_per_unit;
    const Eigen::Vector3f nose = noseTipOf(head.mesh);
    const OpenMesh::Vec3f shift(-nose.x(), -nose.y(), 0.1f - nose.z());
    for (const auto vh : head.mesh.vertices()) head.mesh.point(vh) += shift;
    head.nose_tip_head = Eigen::Vector3f(0, 0, 0.1f);
}

// ASCII PLY with `x y z [nx ny nz] [s t]` vertices and polygon faces: OpenMesh 9 drops the s/t texture
// coordinates of the converted scan, so it is parsed here (the format is simple and checked line by line).
StatusOr<recon::Mesh> readAsciiPly(const fs::path& path, bool& has_uv) {
    std::ifstream in(path);
    if (!in) return notFound("cannot open " + path.string());
    std::string line;
    std::getline(in, line);
    if (line.rfind("ply", 0) != 0) return dataLoss(path.string() + ": not a PLY file");
    long vertex_count = -1, face_count = -1;
    std::vector<std::string> props;
    bool in_vertex = false, ascii = false;
    while (std::getline(in, line)) {
        std::istringstream ls(line);
        std::string word;
        ls >> word;
        if (word == "format") {
            std::string fmt;
            ls >> fmt;
            ascii = fmt == "ascii";
        } else if (word == "element") {
            std::string what;
            long n = -1;
            ls >> what >> n;
            in_vertex = what == "vertex";
            if (in_vertex) vertex_count = n;
            if (what == "face") face_count = n;
        } else if (word == "property" && in_vertex) {
            std::string type, name;
            ls >> type >> name;
            props.push_back(name);
        } else if (word == "end_header") {
            break;
        }
    }
    if (!ascii) return invalidArgument(path.string() + ": only ASCII PLY is parsed here");
    if (vertex_count <= 0 || face_count <= 0 || vertex_count > 50'000'000 || face_count > 100'000'000) {
        return dataLoss(path.string() + ": bad element counts");
    }
    auto index_of = [&](const char* name) {
        const auto it = std::find(props.begin(), props.end(), name);
        return it == props.end() ? -1 : static_cast<int>(it - props.begin());
    };
    const int ix = index_of("x"), iy = index_of("y"), iz = index_of("z"), is = index_of("s"), it = index_of("t");
    if (ix < 0 || iy < 0 || iz < 0) return dataLoss(path.string() + ": vertices lack x y z");
    has_uv = is >= 0 && it >= 0;
    recon::Mesh mesh;
    if (has_uv) mesh.request_vertex_texcoords2D();
    std::vector<float> values(props.size());
    for (long i = 0; i < vertex_count; ++i) {
        for (auto& v : values) {
            if (!(in >> v)) return dataLoss(path.string() + ": truncated vertex list");
        }
        const auto vh = mesh.add_vertex(recon::Mesh::Point(values[ix], values[iy], values[iz]));
        if (has_uv) mesh.set_texcoord2D(vh, OpenMesh::Vec2f(values[is], values[it]));
    }
    std::vector<recon::Mesh::VertexHandle> corners;
    for (long i = 0; i < face_count; ++i) {
        int n = 0;
        if (!(in >> n) || n < 3 || n > 64) return dataLoss(path.string() + ": bad face");
        corners.clear();
        for (int k = 0; k < n; ++k) {
            long idx = -1;
            if (!(in >> idx) || idx < 0 || idx >= vertex_count) return dataLoss(path.string() + ": bad face index");
            corners.push_back(recon::Mesh::VertexHandle(static_cast<int>(idx)));
        }
        for (int k = 1; k + 1 < n; ++k) mesh.add_face(corners[0], corners[k], corners[k + 1]);  // fan
    }
    return mesh;
}

bool isAsciiPly(const fs::path& path) {
    std::ifstream in(path);
    std::string l1, l2;
    std::getline(in, l1);
    std::getline(in, l2);
    return l1.rfind("ply", 0) == 0 && l2.find("ascii") != std::string::npos;
}

}  // namespace

StatusOr<HeadModel> loadHeadScan(const fs::path& dir_or_file) {
    std::error_code ec;
    fs::path file = dir_or_file;
    fs::path texture_file;
    bool lee_perry_smith = false;
    if (fs::is_directory(dir_or_file, ec)) {
        file = dir_or_file / "LeePerrySmith_converted.ply";
        texture_file = dir_or_file / "Map-COL.jpg";
        lee_perry_smith = true;
    } else if (dir_or_file.filename() == "LeePerrySmith_converted.ply") {
        texture_file = dir_or_file.parent_path() / "Map-COL.jpg";
        lee_perry_smith = true;
    }
    if (!fs::is_regular_file(file, ec)) return notFound("head scan not found: " + file.string());

    HeadModel head;
    bool has_uv = false;
    if (isAsciiPly(file)) {
        ASSIGN_OR_RETURN(head.mesh, readAsciiPly(file, has_uv));
    } else {
        OpenMesh::IO::Options opts;
        if (!OpenMesh::IO::read_mesh(head.mesh, file.string(), opts)) {
            return dataLoss("OpenMesh cannot read " + file.string());
        }
    }
    if (head.mesh.n_faces() < 100) return dataLoss(file.string() + ": too few triangles for a head");
    if (has_uv && !texture_file.empty()) {
        head.texture_bgr = cv::imread(texture_file.string(), cv::IMREAD_COLOR);
    }
    if (head.texture_bgr.empty() && head.mesh.has_vertex_texcoords2D()) head.mesh.release_vertex_texcoords2D();
    toHeadFrame(head, lee_perry_smith ? kLeePerrySmithMetresPerUnit : 1.0f);
    // The scan's chin ends ~0.095 m below the nose tip; the cut sits just under it (head label above).
    head.neck_cut_y_m = -0.10f;
    head.name = lee_perry_smith ? "leeperrysmith" : file.stem().string();
    head.mesh.update_face_normals();
    head.mesh.update_vertex_normals();
    for (const auto vh : head.mesh.vertices()) head.mesh.set_color(vh, recon::Mesh::Color(200, 170, 150));
    return head;
}

std::optional<fs::path> findLeePerrySmith() {
    std::error_code ec;
    if (const char* env = std::getenv("FACESCAN_DATA_DIR"); env && *env) {
        const fs::path p = fs::path(env) / "leeperrysmith";
        if (fs::is_directory(p, ec)) return p;
        return std::nullopt;  // an explicit data dir without the scan means "use the built-in head"
    }
    std::vector<fs::path> starts;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) starts.push_back(exe.parent_path());
    starts.push_back(fs::current_path(ec));
    for (fs::path dir : starts) {
        for (int up = 0; up < 8 && !dir.empty(); ++up) {
            const fs::path p = dir / ".." / "shared" / "data" / "leeperrysmith";
            if (fs::is_regular_file(p / "LeePerrySmith_converted.ply", ec)) return fs::weakly_canonical(p, ec);
            if (dir == dir.parent_path()) break;
            dir = dir.parent_path();
        }
    }
    return std::nullopt;
}

HeadModel defaultHead() {
    if (const auto dir = findLeePerrySmith()) {
        auto head = loadHeadScan(*dir);
        if (head.isOk()) return std::move(head).value();
    }
    return builtinHead();
}

float headBreadthM(const HeadModel& head, float y_lo_m, float y_hi_m) {
    float x_min = std::numeric_limits<float>::max(), x_max = -x_min;
    for (const auto vh : head.mesh.vertices()) {
        const auto& p = head.mesh.point(vh);
        if (p[1] < y_lo_m || p[1] > y_hi_m) continue;
        x_min = std::min(x_min, p[0]);
        x_max = std::max(x_max, p[0]);
    }
    return x_max > x_min ? x_max - x_min : 0.0f;
}

}  // namespace facescan::synth
