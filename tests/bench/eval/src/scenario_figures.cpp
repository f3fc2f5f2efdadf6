#include "eval/scenario_figures.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>

#include "eval/accuracy.hpp"

namespace facescan::eval {
namespace {

using recon::Pose;

double angleDeg(const Pose& t) { return Eigen::AngleAxisf(t.linear()).angle() * 57.2957795; }

}  // namespace

ScenarioFigures scenarioFigures(const synth::KinectSimulator& sim, const std::vector<int>& head_pixels,
                                const std::vector<std::optional<Pose>>& T_ref_camera,
                                const std::vector<std::optional<Pose>>& estimate, const recon::Mesh& mesh) {
    ScenarioFigures f;
    const int n = static_cast<int>(estimate.size());
    if (static_cast<int>(head_pixels.size()) != n || static_cast<int>(T_ref_camera.size()) != n) return f;
    std::vector<int> visible;
    for (int px : head_pixels)
        if (px > 0) visible.push_back(px);
    std::sort(visible.begin(), visible.end());
    const int usual = visible.empty() ? 1 : visible[visible.size() / 2];
    auto in_view = [&](int i) { return head_pixels[static_cast<size_t>(i)] * 2 >= usual; };

    for (int i = 0; i < n; ++i) {
        const bool tracked = estimate[static_cast<size_t>(i)].has_value();
        if (in_view(i)) {
            ++f.frames_in_view;
            f.tracked_in_view += tracked;
        }
        if (tracked && T_ref_camera[static_cast<size_t>(i)]) {
            const Pose err = T_ref_camera[static_cast<size_t>(i)]->inverse() * *estimate[static_cast<size_t>(i)];
            const double mm = err.translation().norm() * 1000.0, deg = angleDeg(err);
            f.max_pose_err_mm = std::max(f.max_pose_err_mm, mm);
            f.max_pose_err_deg = std::max(f.max_pose_err_deg, deg);
            f.wrong_poses += mm > kWrongMm || deg > kWrongDeg;
        }
    }
    // Losses: runs of rejected frames after an integrated one.
    int last_tracked = -1;
    for (int i = 0; i < n; ++i) {
        if (estimate[static_cast<size_t>(i)]) {
            last_tracked = i;
            continue;
        }
        if (last_tracked != i - 1 || last_tracked < 0) continue;  // not the first rejected frame of a run
        ++f.losses;
        int back = -1, again = -1;
        for (int j = i; j < n && again < 0; ++j) {
            if (back < 0 && in_view(j)) back = j;
            if (estimate[static_cast<size_t>(j)]) again = j;
        }
        if (again < 0) continue;
        ++f.reacquired;
        f.worst_reacquire_frames = std::max(f.worst_reacquire_frames, back < 0 ? 0 : std::max(0, again - back));
        const auto& a = T_ref_camera[static_cast<size_t>(last_tracked)];
        const auto& b = T_ref_camera[static_cast<size_t>(again)];
        if (a && b) f.worst_return_deg = std::max(f.worst_return_deg, angleDeg(a->inverse() * *b));
    }
    // Foreign surface: mesh vertices far from the ground-truth head.
    f.mesh_vertices = static_cast<int>(mesh.n_vertices());
    const std::vector<uint8_t> head_only = sim.headVertexMask();
    f.foreign_vertices =
        countVerticesFarFrom(mesh, sim.headInFirstCamera(), static_cast<float>(kForeignMm / 1000.0), &head_only);
    return f;
}

void printScenario(const ScenarioFigures& f) {
    std::printf(
        "scenario: %d of %d frames with the head in view tracked (%.1f %%); %d losses, %d re-acquired, worst %d "
        "frames after the head was back in view, head turned up to %.1f deg meanwhile\n",
        f.tracked_in_view, f.frames_in_view, 100.0 * f.trackedShare(), f.losses, f.reacquired, f.worst_reacquire_frames,
        f.worst_return_deg);
    std::printf(
        "scenario: fused poses off the reference by up to %.2f mm / %.2f deg; %d wrong (> %.0f mm or > %.0f deg); "
        "%d of %d mesh vertices more than %.0f mm from the true head (torso, occluder)\n",
        f.max_pose_err_mm, f.max_pose_err_deg, f.wrong_poses, kWrongMm, kWrongDeg, f.foreign_vertices, f.mesh_vertices,
        kForeignMm);
}

std::string scenarioJson(const ScenarioFigures& f) {
    char buf[512];
    std::snprintf(
        buf, sizeof(buf),
        "{\"frames_in_view\":%d,\"tracked_in_view\":%d,\"tracked_share\":%.4f,\"losses\":%d,\"reacquired\":%d,"
        "\"worst_reacquire_frames\":%d,\"worst_return_deg\":%.2f,\"wrong_poses\":%d,\"max_pose_err_mm\":%.3f,"
        "\"max_pose_err_deg\":%.3f,\"mesh_vertices\":%d,\"foreign_vertices\":%d}",
        f.frames_in_view, f.tracked_in_view, f.trackedShare(), f.losses, f.reacquired, f.worst_reacquire_frames,
        f.worst_return_deg, f.wrong_poses, f.max_pose_err_mm, f.max_pose_err_deg, f.mesh_vertices, f.foreign_vertices);
    return buf;
}

}  // namespace facescan::eval
