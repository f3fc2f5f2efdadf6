// facescan-bench finish: the finishing stage (recon/finishing.hpp) on a mesh file, e.g. the final mesh of a scan
// (`facescan-bench recon --input synthetic:frames=240,seed=11 --mesh M.ply` makes one the tuning never saw).
//  1. the head alone (parts and crop; no head region here: the largest part is the head), which gives "the full
//     mesh" that the rest is measured against;
//  2. closing and the triangle budget, timed (thread CPU and wall clock);
//  3. distances both ways, in mm: from the full mesh's vertices to the result's surface (what decimation took
//     away) and from the result's vertices to the full surface (what it moved; zero for half-edge collapses);
//  4. with --open3d, Open3D's simplify_quadric_decimation of the same full mesh to the same budget (Debian's
//     python3-open3d: deploy/install-deps.sh --open3d), measured with the same distance function.
// JSON keys: triangles_full triangles cpu_ms wall_ms full_to_result{mean_mm,p99_mm,max_mm}
// result_to_full{...} colours open3d{triangles,cpu_ms,full_to_result{...},result_to_full{...}}.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_command.hpp"
#include "eval/mesh_io.hpp"
#include "recon/finishing.hpp"
#include "recon/mesh_writer.hpp"

namespace {

using namespace facescan;

int usage(std::FILE* out) {
    std::fprintf(out,
                 "usage: facescan-bench finish --mesh M [--max-triangles N|web|avatar|print|full]\n"
                 "                             [--close none|holes|watertight]\n"
                 "                             [--keep head|all] [--crop x0,y0,z0,x1,y1,z1] [--open3d] [--save OUT]\n"
                 "                             [--json]\n"
                 "  Finishes M (PLY, OBJ, OFF, STL) as the server's finish would, times it and reports the distance\n"
                 "  from the result to the full mesh (mean, p99, max mm, both ways). --open3d runs Open3D's quadric\n"
                 "  decimation of the same mesh to the same budget (python3-open3d) and measures it the same way.\n"
                 "  --save OUT writes the finished mesh (PLY). Prints the CPU time of each step (this thread and the\n"
                 "  parallel pool's workers on its behalf; watertight: field, marching cubes, thickening, check).\n");
    return out == stdout ? 0 : 2;
}

double threadMs() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

std::string distJson(const recon::DistanceFigures& d) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "{\"mean_mm\":%.4f,\"p99_mm\":%.4f,\"max_mm\":%.4f}", d.mean_mm, d.p99_mm, d.max_mm);
    return buf;
}

void printRow(const char* what, size_t triangles, double cpu_ms, const recon::DistanceFigures& to_result,
              const recon::DistanceFigures& to_full, bool colours) {
    std::printf("  %-26s %9zu %9.1f %9.4f %9.4f %9.4f %9.4f %9.4f   %s\n", what, triangles, cpu_ms, to_result.mean_mm,
                to_result.p99_mm, to_result.max_mm, to_full.mean_mm, to_full.p99_mm,
                colours ? "colours kept" : "no colours");
}

Status writeBytes(const std::filesystem::path& path, const recon::IndexedMesh& mesh) {
    ASSIGN_OR_RETURN(const std::string bytes, recon::meshFileBytes(mesh, recon::MeshFileFormat::kPly));
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return out.good() ? Status::ok() : unavailable("cannot write " + path.string());
}

struct Open3dResult {
    recon::IndexedMesh mesh;
    double cpu_ms = 0;
};

// Open3D 0.16 (Debian's python3-open3d, so Debian's python3 whatever is first on PATH): TriangleMesh.
// simplify_quadric_decimation, its defaults otherwise.
StatusOr<Open3dResult> runOpen3d(const recon::IndexedMesh& full, int target) {
    char dir_template[] = "/tmp/facescan-bench-finish-XXXXXX";
    if (!mkdtemp(dir_template)) return unavailable("cannot make a temporary folder");
    const std::filesystem::path dir = dir_template;
    RETURN_IF_ERROR(writeBytes(dir / "full.ply", full));
    {
        std::ofstream py(dir / "decimate.py");
        py << "import sys, time\n"
              "import open3d as o3d\n"
              "m = o3d.io.read_triangle_mesh(sys.argv[1])\n"
              "t = time.process_time()\n"
              "s = m.simplify_quadric_decimation(target_number_of_triangles=int(sys.argv[3]))\n"
              "dt = time.process_time() - t\n"
              "o3d.io.write_triangle_mesh(sys.argv[2], s)\n"
              "open(sys.argv[4], 'w').write('%f' % (dt * 1000))\n";
    }
    const std::string cmd = "/usr/bin/python3 " + (dir / "decimate.py").string() + " " + (dir / "full.ply").string() +
                            " " + (dir / "o3d.ply").string() + " " + std::to_string(target) + " " +
                            (dir / "ms.txt").string() + " >/dev/null 2>&1";
    const int rc = std::system(cmd.c_str());
    Open3dResult out;
    auto mesh = eval::readMesh(dir / "o3d.ply");
    std::ifstream ms(dir / "ms.txt");
    ms >> out.cpu_ms;
    std::filesystem::remove_all(dir);
    if (rc != 0 || !mesh.isOk()) {
        return unavailable("Open3D did not run (install it with deploy/install-deps.sh --open3d)");
    }
    out.mesh = recon::fromOpenMesh(*mesh);
    return out;
}

int runFinish(const std::vector<std::string>& args) {
    std::string mesh_path, save_path;
    recon::FinishParams params;
    params.max_triangles = 20'000;
    bool json = false, open3d = false;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const bool v = i + 1 < args.size();
        Status st = Status::ok();
        if (a == "--json") {
            json = true;
        } else if (a == "--open3d") {
            open3d = true;
        } else if (a == "--mesh" && v) {
            mesh_path = args[++i];
        } else if (a == "--save" && v) {
            save_path = args[++i];
        } else if (a == "--max-triangles" && v) {
            auto n = recon::parseTriangleBudget(args[++i]);
            st = n.status();
            if (n.isOk()) params.max_triangles = *n;
        } else if (a == "--close" && v) {
            auto c = recon::parseClosingMode(args[++i]);
            st = c.status();
            if (c.isOk()) params.close = *c;
        } else if (a == "--keep" && v) {
            auto k = recon::parseKeepParts(args[++i]);
            st = k.status();
            if (k.isOk()) params.keep = *k;
        } else if (a == "--crop" && v) {
            auto b = recon::parseCropBox(args[++i]);
            st = b.status();
            if (b.isOk()) params.crop_m = *b;
        } else if (a == "--help" || a == "-h") {
            return usage(stdout);
        } else {
            std::fprintf(stderr, "finish: unknown or incomplete option '%s'\n", a.c_str());
            return usage(stderr);
        }
        if (!st.isOk()) {
            std::fprintf(stderr, "finish: %s\n", st.message().c_str());
            return 2;
        }
    }
    if (mesh_path.empty()) return usage(stderr);
    auto read = eval::readMesh(mesh_path);
    if (!read.isOk()) {
        std::fprintf(stderr, "finish: %s\n", read.status().toString().c_str());
        return 1;
    }
    // Step 1 alone gives the full mesh of the comparison.
    recon::IndexedMesh full = recon::fromOpenMesh(*read);
    const size_t triangles_read = full.triangleCount();
    recon::FinishParams parts_only = params;
    parts_only.max_triangles = 0;
    parts_only.close = recon::ClosingMode::kNone;
    auto parts = recon::finishMesh(full, parts_only);
    if (!parts.isOk()) {
        std::fprintf(stderr, "finish: %s\n", parts.status().message().c_str());
        return 2;
    }
    // Steps 2-3 timed as the server runs them (the report's distance included: the server measures it too).
    recon::IndexedMesh result = full;
    recon::FinishParams rest = params;
    rest.keep = recon::KeepParts::kAll;
    rest.crop_m.reset();
    const double cpu0 = threadMs();
    const auto wall0 = std::chrono::steady_clock::now();
    auto report = recon::finishMesh(result, rest);
    const double cpu_ms = threadMs() - cpu0;
    const double wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall0).count();
    if (!report.isOk()) {
        std::fprintf(stderr, "finish: %s\n", report.status().message().c_str());
        return 2;
    }
    const recon::DistanceFigures to_result = recon::vertexToSurfaceDistance(full, result);
    const recon::DistanceFigures to_full = recon::vertexToSurfaceDistance(result, full);
    std::printf("finish %s: %zu triangles read, %zu after the head alone (%s)\n", mesh_path.c_str(), triangles_read,
                full.triangleCount(), parts->summary().c_str());
    std::printf("  budget %d, close %s: %s\n", params.max_triangles, recon::closingModeName(params.close),
                report->summary().c_str());
    std::printf(
        "  steps ms (wall): parts %.1f, close %.1f, decimate %.1f, distance %.1f; whole finish %.1f ms CPU "
        "(this thread), %.1f ms wall\n",
        parts->ms_parts, report->ms_close, report->ms_decimate, report->ms_distance, cpu_ms, wall_ms);
    std::printf("  %s\n", report->cpuBreakdown().c_str());
    std::printf("  %-26s %9s %9s %9s %9s %9s %9s %9s\n", "", "triangles", "cpu ms", "full->res", "p99", "max",
                "res->full", "p99");
    std::printf("  %-26s %9s %9s %9s %9s %9s %9s %9s\n", "", "", "", "mean mm", "mm", "mm", "mean mm", "mm");
    printRow("facescan (OpenMesh)", result.triangleCount(), cpu_ms, to_result, to_full, result.hasColours());
    const recon::MeshDefects before = recon::countDefects(full), after = recon::countDefects(result);
    std::printf(
        "  defects (full -> result): boundary edges %zu -> %zu, non-manifold edges %zu -> %zu, non-manifold "
        "vertices %zu -> %zu, clean %s -> %s\n",
        before.boundary_edges, after.boundary_edges, before.non_manifold_edges, after.non_manifold_edges,
        before.non_manifold_vertices, after.non_manifold_vertices, before.clean() ? "yes" : "no",
        after.clean() ? "yes" : "no");
    std::string o3d_json = "null";
    if (open3d && params.max_triangles > 0) {
        auto o3d = runOpen3d(full, params.max_triangles);
        if (!o3d.isOk()) {
            std::printf("  open3d: %s\n", o3d.status().message().c_str());
        } else {
            const auto o_to_result = recon::vertexToSurfaceDistance(full, o3d->mesh);
            const auto o_to_full = recon::vertexToSurfaceDistance(o3d->mesh, full);
            printRow("Open3D 0.16 quadric", o3d->mesh.triangleCount(), o3d->cpu_ms, o_to_result, o_to_full,
                     o3d->mesh.hasColours());
            o3d_json = "{\"triangles\":" + std::to_string(o3d->mesh.triangleCount()) +
                       ",\"cpu_ms\":" + std::to_string(o3d->cpu_ms) + ",\"full_to_result\":" + distJson(o_to_result) +
                       ",\"result_to_full\":" + distJson(o_to_full) + "}";
        }
    }
    if (!save_path.empty()) {
        if (const Status st = writeBytes(save_path, result); !st.isOk()) {
            std::fprintf(stderr, "finish: %s\n", st.message().c_str());
            return 1;
        }
        std::printf("  wrote %s\n", save_path.c_str());
    }
    if (json) {
        std::printf(
            "{\"triangles_full\":%zu,\"triangles\":%zu,\"cpu_ms\":%.2f,\"wall_ms\":%.2f,\"full_to_result\":%s,"
            "\"result_to_full\":%s,\"colours\":%s,\"open3d\":%s}\n",
            full.triangleCount(), result.triangleCount(), cpu_ms, wall_ms, distJson(to_result).c_str(),
            distJson(to_full).c_str(), result.hasColours() ? "true" : "false", o3d_json.c_str());
    }
    return 0;
}

}  // namespace

FACESCAN_BENCH_COMMAND("finish", "finishing: head alone, holes, triangle budget; distance to the full mesh, time",
                       runFinish);
