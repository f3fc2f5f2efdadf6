// facescan-bench accuracy: the ruler. Rigidly aligns a mesh to the ground-truth head and reports point-to-surface
// distances over the face region, completeness and outliers (docs/design.md s6). --baseline-frame measures one raw
// noisy synthetic frame, back-projected, against the truth: the baseline that fusion must beat by far; its
// completeness_observed is taken over what that frame measured (eval/observed_region.hpp). A mesh measured with
// --mesh comes without sensor views, so its completeness_observed is the whole-region completeness.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bench_command.hpp"
#include "eval/accuracy.hpp"
#include "eval/depth_mesh.hpp"
#include "eval/heat_map.hpp"
#include "eval/mesh_io.hpp"
#include "eval/observed_region.hpp"
#include "synth/kinect_simulator.hpp"

namespace {

using namespace facescan;

int usage(std::FILE* out) {
    std::fprintf(
        out,
        "usage: facescan-bench accuracy --mesh M --gt G [--nose X,Y,Z] [--init FILE] [--no-align] [--json]\n"
        "                               [--offset-mm D] [--save-mesh OUT] [--heat-map FILE.png [--heat-max-mm E]]\n"
        "       facescan-bench accuracy --baseline-frame [--distance M] [--head builtin|scan] [--frame I]"
        " [--json]\n"
        "  G is a head-frame mesh (y up, face along +z; e.g. head_gt.ply of a synthetic TUM folder); its nose\n"
        "  tip is found unless --nose gives it. --init FILE: 4x4 row-major T_gt_mesh guess, or a\n"
        "  T_camera0_head.txt (mesh in the first camera frame), whose inverse is used when --init-inverse.\n"
        "  Face region: G within 0.11 m of the nose tip, facing forward. Distances in mm, M to G surface.\n"
        "  --offset-mm D moves every vertex of M D mm along its normal first (a uniform inflation, the known\n"
        "  answer: `--mesh G --gt G --offset-mm 1` must read 1 mm); --save-mesh OUT writes M as measured.\n"
        "  --heat-map FILE.png draws each vertex's distance to G on M (aligned) from the front and both sides\n"
        "  with a colour bar in mm, as the thesis' Figure 5.2 (grey: farther than 0.11 m from the nose tip, not\n"
        "  measured); the bar tops out at E mm (default: the 99th percentile, rounded up to 0.5 mm).\n");
    return out == stdout ? 0 : 2;
}

std::optional<recon::Pose> readPose(const std::string& path) {
    std::ifstream in(path);
    Eigen::Matrix4f m;
    for (int i = 0; i < 16; ++i) {
        if (!(in >> m(i / 4, i % 4))) return std::nullopt;
    }
    recon::Pose T;
    T.matrix() = m;
    return T;
}

// M moved into G's frame by the alignment found, its per-vertex distances to G, drawn (eval/heat_map.hpp).
int writeHeatMap(const recon::Mesh& mesh, const recon::Mesh& gt, const eval::AccuracyReport& rep,
                 const Eigen::Vector3f& nose, eval::HeatMapParams heat, const std::string& path,
                 const std::string& mesh_path) {
    recon::Mesh moved = mesh;
    for (const auto vh : moved.vertices()) {
        const auto& q = moved.point(vh);
        const Eigen::Vector3f p = rep.T_gt_mesh * Eigen::Vector3f(q[0], q[1], q[2]);
        moved.set_point(vh, recon::Mesh::Point(p.x(), p.y(), p.z()));
    }
    moved.update_normals();
    const std::vector<float> errors = eval::vertexErrorsMm(moved, gt);
    char title[256];
    std::snprintf(title, sizeof title, "%s: distance to ground truth, face mean %.3f mm, p90 %.3f mm",
                  std::filesystem::path(mesh_path).filename().c_str(), rep.mean_mm, rep.p90_mm);
    heat.title = title;
    auto image = eval::renderErrorHeatMap(moved, errors, nose, heat);
    if (!image.isOk()) {
        std::fprintf(stderr, "accuracy: %s\n", image.status().toString().c_str());
        return 2;
    }
    if (!cv::imwrite(path, *image)) {
        std::fprintf(stderr, "accuracy: cannot write the heat map to %s (is it a .png in a writable folder?)\n",
                     path.c_str());
        return 1;
    }
    std::printf("wrote the heat map %s (%dx%d)\n", path.c_str(), image->cols, image->rows);
    return 0;
}

void printReport(const char* what, const eval::AccuracyReport& r, bool json) {
    std::printf("%s\n", what);
    const eval::DistanceFigures& u = r.unaligned;
    std::printf("  %-30s %9s %12s\n", "", "aligned", "unaligned");
    std::printf("  %-30s %9.3f %12.3f\n  %-30s %9.3f %12.3f\n  %-30s %9.3f %12.3f\n  %-30s %9.3f %12.3f\n",
                "mean |d| (mm)", r.mean_mm, u.mean_mm, "RMS (mm)", r.rms_mm, u.rms_mm, "median (mm)", r.median_mm,
                u.median_mm, "p90 (mm)", r.p90_mm, u.p90_mm);
    std::printf("  %-30s %9d %12d\n", "samples over the face", r.mesh_vertices_used, u.samples);
    std::printf("  %-30s %9.3f   (> 0: M inflated, found and left in the distances)\n", "uniform normal offset (mm)",
                r.offset_mm);
    std::printf("  %-30s %9.4f %12.4f\n", "outliers (> 5 mm)", r.outliers, u.outliers);
    std::printf("  %-30s %9.4f\n  %-30s %9.4f\n  %-30s %9d\n  %-30s %9d\n", "completeness (<= 2 mm)", r.completeness,
                "completeness, observed part", r.completeness_observed, "GT face vertices", r.gt_face_vertices,
                "GT face vertices observed", r.gt_observed_vertices);
    if (json) std::printf("%s\n", eval::accuracyJson(r).c_str());
}

int runAccuracy(const std::vector<std::string>& args) {
    std::string mesh_path, gt_path, init_path, head_arg = "default", save_path, heat_path;
    float offset_mm = 0;
    eval::HeatMapParams heat;
    std::optional<Eigen::Vector3f> nose;
    bool json = false, baseline = false, init_inverse = false;
    eval::AccuracyParams params;
    synth::SequenceParams seq;
    int frame_index = 0;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const bool v = i + 1 < args.size();
        if (a == "--json") {
            json = true;
        } else if (a == "--baseline-frame") {
            baseline = true;
        } else if (a == "--no-align") {
            params.align = false;
        } else if (a == "--init-inverse") {
            init_inverse = true;
        } else if (a == "--mesh" && v) {
            mesh_path = args[++i];
        } else if (a == "--gt" && v) {
            gt_path = args[++i];
        } else if (a == "--offset-mm" && v) {
            offset_mm = std::strtof(args[++i].c_str(), nullptr);
        } else if (a == "--heat-map" && v) {
            heat_path = args[++i];
        } else if (a == "--heat-max-mm" && v) {
            heat.max_error_mm = std::strtof(args[++i].c_str(), nullptr);
        } else if (a == "--save-mesh" && v) {
            save_path = args[++i];
        } else if (a == "--init" && v) {
            init_path = args[++i];
        } else if (a == "--head" && v) {
            head_arg = args[++i];
        } else if (a == "--distance" && v) {
            seq.distance_m = std::strtof(args[++i].c_str(), nullptr);
        } else if (a == "--frame" && v) {
            frame_index = std::atoi(args[++i].c_str());
        } else if (a == "--nose" && v) {
            Eigen::Vector3f p;
            if (std::sscanf(args[++i].c_str(), "%f,%f,%f", &p.x(), &p.y(), &p.z()) != 3) return usage(stderr);
            nose = p;
        } else if (a == "--help" || a == "-h") {
            return usage(stdout);
        } else {
            std::fprintf(stderr, "accuracy: unknown or incomplete option '%s'\n", a.c_str());
            return usage(stderr);
        }
    }
    if (baseline) {
        if (const auto st = seq.validate(); !st.isOk()) {
            std::fprintf(stderr, "accuracy: %s\n", st.toString().c_str());
            return 2;
        }
        synth::HeadModel head = head_arg == "builtin" ? synth::builtinHead() : synth::defaultHead();
        if (head_arg == "scan" && head.name != "leeperrysmith") {
            std::fprintf(stderr, "accuracy: the Lee Perry-Smith scan was not found (set FACESCAN_DATA_DIR)\n");
            return 1;
        }
        const synth::KinectSimulator sim(std::move(head), seq);
        recon::RgbdFrame frame;
        synth::FrameTruth truth;
        sim.render(frame_index, frame, &truth);
        const cv::Mat head_mask = truth.label == static_cast<int>(synth::PixelLabel::kHead);
        const recon::Mesh raw = eval::meshFromDepth(frame.depth_m, sim.intrinsics(), head_mask);
        const auto sightings =
            eval::countSightings(sim.head().mesh, sim.intrinsics(), {{truth.T_camera_head, frame.depth_m, head_mask}});
        if (!sightings.isOk()) {
            std::fprintf(stderr, "accuracy: %s\n", sightings.status().toString().c_str());
            return 1;
        }
        params.observed = eval::observedMask(*sightings);
        const auto rep = eval::measureAccuracy(raw, sim.head().mesh, sim.head().nose_tip_head, params,
                                               truth.T_camera_head.inverse());
        if (!rep.isOk()) {
            std::fprintf(stderr, "accuracy: %s\n", rep.status().toString().c_str());
            return 1;
        }
        char title[160];
        std::snprintf(title, sizeof title, "single raw frame %d of %s at %.2f m (noisy, back-projected, head pixels)",
                      frame_index, sim.head().name.c_str(), seq.distance_m);
        printReport(title, *rep, json);
        return 0;
    }
    if (mesh_path.empty() || gt_path.empty()) return usage(stderr);
    auto mesh = eval::readMesh(mesh_path);
    auto gt = eval::readMesh(gt_path);
    if (!mesh.isOk() || !gt.isOk()) {
        std::fprintf(stderr, "accuracy: %s\n", (!mesh.isOk() ? mesh.status() : gt.status()).toString().c_str());
        return 1;
    }
    if (offset_mm != 0) *mesh = eval::offsetAlongNormals(*mesh, offset_mm * 1e-3f);
    if (!save_path.empty()) {
        if (const Status st = eval::writeMesh(*mesh, save_path); !st.isOk()) {
            std::fprintf(stderr, "accuracy: %s\n", st.toString().c_str());
            return 1;
        }
    }
    std::optional<recon::Pose> init;
    if (!init_path.empty()) {
        init = readPose(init_path);
        if (!init) {
            std::fprintf(stderr, "accuracy: %s does not hold a 4x4 matrix\n", init_path.c_str());
            return 1;
        }
        if (init_inverse) init = init->inverse();
    }
    const auto rep = eval::measureAccuracy(*mesh, *gt, nose.value_or(eval::findNoseTip(*gt)), params, init);
    if (!rep.isOk()) {
        std::fprintf(stderr, "accuracy: %s\n", rep.status().toString().c_str());
        return 1;
    }
    if (!heat_path.empty()) {
        if (const int rc =
                writeHeatMap(*mesh, *gt, *rep, nose.value_or(eval::findNoseTip(*gt)), heat, heat_path, mesh_path);
            rc != 0) {
            return rc;
        }
    }
    printReport(("accuracy of " + mesh_path + " against " + gt_path).c_str(), *rep, json);
    return 0;
}

}  // namespace

FACESCAN_BENCH_COMMAND("accuracy", "mesh vs ground-truth head: mean/RMS/median/p90 mm, completeness, outliers",
                       runAccuracy);
