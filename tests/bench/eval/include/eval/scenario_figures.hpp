// The robustness figures of a synthetic scenario (facescan-bench recon and the core tests), from the
// renderer's ground truth: how many frames with the head in view were tracked, how long re-acquisition took after each
// loss and how far the head had turned, whether any fused pose was wrong, and whether anything other than the head
// (torso, occluder) was fused.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/mesh.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::eval {

struct ScenarioFigures {
    int frames_in_view = 0;          // frames with the head in view (at least half its usual pixel count)
    int tracked_in_view = 0;         // of which integrated
    int losses = 0;                  // runs of rejected frames after an integrated one
    int reacquired = 0;              // of which ended by an integrated frame
    int worst_reacquire_frames = 0;  // frames from the head being back in view to integrated, worst loss
    double worst_return_deg = 0;     // head rotation between the last frame before a loss and the re-acquired one
    int wrong_poses = 0;             // integrated frames more than kWrongMm or kWrongDeg off the reference
    double max_pose_err_mm = 0, max_pose_err_deg = 0;  // over integrated frames
    int mesh_vertices = 0;
    int foreign_vertices = 0;  // mesh vertices more than kForeignMm from the true head, or nearest to its
                               // neck and shoulders (more than 3 cm under the chin): torso, occluder
    double trackedShare() const {
        return frames_in_view > 0 ? static_cast<double>(tracked_in_view) / frames_in_view : 0;
    }
};

inline constexpr double kWrongMm = 10.0, kWrongDeg = 3.0, kForeignMm = 10.0;

// sim: the sequence's renderer; head_pixels: FrameTruth::head_pixels per frame; T_ref_camera: the true camera
// poses (first camera = world); estimate: per frame, the pose when integrated; mesh: the scan's final mesh.
ScenarioFigures scenarioFigures(const synth::KinectSimulator& sim, const std::vector<int>& head_pixels,
                                const std::vector<std::optional<recon::Pose>>& T_ref_camera,
                                const std::vector<std::optional<recon::Pose>>& estimate, const recon::Mesh& mesh);
void printScenario(const ScenarioFigures& f);
std::string scenarioJson(const ScenarioFigures& f);

}  // namespace facescan::eval
