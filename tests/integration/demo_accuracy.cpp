// facescan-demo-accuracy: the demo's last line. Measures a fetched mesh against the ground truth of the
// synthetic subject the agent filmed (the same head, distance and seed give the same first-camera pose, which is
// the frame of the server's mesh), with the project's one accuracy ruler (facescan_eval).
//
//   facescan-demo-accuracy --mesh out/face.ply [--subject auto|builtin|scan] [--distance 0.7] [--seed 1]
//                          [--export-gt DIR] [--json]
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "eval/accuracy.hpp"
#include "eval/mesh_io.hpp"
#include "synth/kinect_simulator.hpp"

namespace {

using namespace facescan;

constexpr const char* kUsage =
    "usage: facescan-demo-accuracy --mesh FILE [--subject auto|builtin|scan] [--distance M] [--seed S]\n"
    "                              [--export-gt DIR] [--json]\n"
    "Measures FILE (a facescan mesh in the first camera's frame) against the synthetic subject the agent filmed\n"
    "with `--source synthetic:subject=..,distance=..,seed=..` (give the same values). --export-gt writes\n"
    "DIR/head_gt.ply (head frame) and DIR/T_camera0_head.txt for `facescan-bench accuracy --gt --init`.\n"
    "exit codes: 0 measured, 1 error, 2 usage\n";

int usage(const std::string& message) {
    std::fprintf(stderr, "facescan-demo-accuracy: %s\n%s", message.c_str(), kUsage);
    return 2;
}

StatusOr<synth::HeadModel> loadSubject(const std::string& subject) {
    if (subject == "auto") return synth::defaultHead();
    if (subject == "builtin") return synth::builtinHead();
    if (subject == "scan") {
        const auto dir = synth::findLeePerrySmith();
        if (!dir) return notFound("subject=scan: the Lee Perry-Smith scan was not found (set FACESCAN_DATA_DIR)");
        return synth::loadHeadScan(*dir);
    }
    return synth::loadHeadScan(subject);
}

Status exportGroundTruth(const synth::KinectSimulator& sim, const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    RETURN_IF_ERROR(eval::writeMesh(sim.head().mesh, dir / "head_gt.ply"));
    std::ofstream out(dir / "T_camera0_head.txt");
    const Eigen::Matrix4f T = sim.poseAt(0).matrix();
    for (int r = 0; r < 4; ++r) {
        out << T(r, 0) << ' ' << T(r, 1) << ' ' << T(r, 2) << ' ' << T(r, 3) << '\n';
    }
    return out ? Status::ok() : unavailable("cannot write " + (dir / "T_camera0_head.txt").string());
}

}  // namespace

int main(int argc, char** argv) {
    std::string mesh_path, subject = "auto", export_dir;
    synth::SequenceParams params;  // the agent's defaults; only distance and seed move the first pose
    bool json = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const bool has_value = i + 1 < argc;
        if (a == "--help" || a == "-h") {
            std::fputs(kUsage, stdout);
            return 0;
        } else if (a == "--json") {
            json = true;
        } else if (a == "--mesh" && has_value) {
            mesh_path = argv[++i];
        } else if (a == "--subject" && has_value) {
            subject = argv[++i];
        } else if (a == "--distance" && has_value) {
            params.distance_m = std::strtof(argv[++i], nullptr);
        } else if (a == "--seed" && has_value) {
            params.seed = std::strtoull(argv[++i], nullptr, 10);
        } else if (a == "--export-gt" && has_value) {
            export_dir = argv[++i];
        } else {
            return usage("unknown or incomplete option '" + a + "'");
        }
    }
    if (mesh_path.empty() && export_dir.empty()) return usage("--mesh FILE (or --export-gt DIR) is required");
    if (Status s = params.validate(); !s.isOk()) return usage(s.message());

    auto head = loadSubject(subject);
    if (!head.isOk()) {
        std::fprintf(stderr, "facescan-demo-accuracy: %s\n", head.status().message().c_str());
        return 1;
    }
    const std::string head_name = head->name;
    const synth::KinectSimulator sim(std::move(head).value(), params);
    if (!export_dir.empty()) {
        if (Status s = exportGroundTruth(sim, export_dir); !s.isOk()) {
            std::fprintf(stderr, "facescan-demo-accuracy: %s\n", s.message().c_str());
            return 1;
        }
        if (mesh_path.empty()) return 0;
    }

    auto mesh = eval::readMesh(mesh_path);
    if (!mesh.isOk()) {
        std::fprintf(stderr, "facescan-demo-accuracy: %s\n", mesh.status().message().c_str());
        return 1;
    }
    const recon::Mesh& gt = sim.head().mesh;
    // The mesh is in the first camera's frame; the ruler wants T_gt_mesh = T_head_camera0 as its first guess.
    auto report = eval::measureAccuracy(*mesh, gt, eval::findNoseTip(gt), {}, sim.poseAt(0).inverse());
    if (!report.isOk()) {
        std::fprintf(stderr, "facescan-demo-accuracy: %s\n", report.status().message().c_str());
        return 1;
    }
    const eval::AccuracyReport& r = *report;
    std::printf(
        "accuracy against the %s head's ground truth: mean %.2f mm, RMS %.2f mm, median %.2f mm, "
        "p90 %.2f mm, completeness %.1f%% (within 2 mm), outliers %.1f%%\n",
        head_name.c_str(), r.mean_mm, r.rms_mm, r.median_mm, r.p90_mm, 100 * r.completeness, 100 * r.outliers);
    std::printf(
        "  without alignment (the true first camera pose): mean %.2f mm, RMS %.2f mm; uniform offset %+.2f mm\n",
        r.unaligned.mean_mm, r.unaligned.rms_mm, r.offset_mm);
    if (json) std::printf("%s\n", eval::accuracyJson(r).c_str());
    return 0;
}
