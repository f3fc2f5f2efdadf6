// The subject of the synthetic Kinect: a head mesh in metres in the HEAD FRAME, with optional colour texture.
//
// Head frame (all subjects): origin on the mid-sagittal plane 0.10 m behind the nose tip at the nose tip's
// height, +x the person's left, +y up, +z the direction the face looks. So the nose tip is at (0, 0, 0.10).
// A camera (x right, y down, looking along +z) sees the face frontally when the head is rotated 180 deg about x:
// R_camera_head = diag(1, -1, -1) (see KinectSimulator::poseAt).
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "recon/mesh.hpp"
#include "recon/status.hpp"

namespace facescan::synth {

struct HeadModel {
    // Metres, head frame. Vertex normals always set; vertex colours set (texture-less subjects are painted);
    // when `texture_bgr` is non-empty the mesh also carries vertex_texcoord2D (u right, v up, OpenGL style).
    recon::Mesh mesh;
    cv::Mat texture_bgr;                                          // CV_8UC3 or empty
    Eigen::Vector3f nose_tip_head = Eigen::Vector3f(0, 0, 0.1f);  // metres, head frame
    // Points of the mesh with head-frame y below this belong to the neck/shoulders (label 2), above it to the
    // head (label 1): a horizontal plane just under the chin. Metres, head frame.
    float neck_cut_y_m = -0.09f;
    std::string name;  // "leeperrysmith", "builtin"
};

// Metres per unit of the Lee Perry-Smith scan: head breadth above the ears 3.1 units = 0.152 m (its README).
inline constexpr float kLeePerrySmithMetresPerUnit = 0.152f / 3.1f;

// Loads a head scan: a folder holding LeePerrySmith_converted.ply (+ Map-COL.jpg), or a PLY/OBJ file.
// The Lee Perry-Smith scan is scaled to metres; other files are taken as metres, y up, face looking along +z.
// The mesh is moved into the head frame (nose tip = the most forward point above the neck).
StatusOr<HeadModel> loadHeadScan(const std::filesystem::path& dir_or_file);

// A procedural head of our own (nose, eyes, brows, mouth, ears, hair, neck), painted, about 0.152 m broad and
// 0.23 m from chin to crown; the fallback subject when the real scan is absent (a fresh machine).
HeadModel builtinHead();

// The Lee Perry-Smith folder: $FACESCAN_DATA_DIR/leeperrysmith, then ../shared/data/leeperrysmith beside the
// executable's checkout (walking up from the executable) or beside the current directory; nullopt when absent.
std::optional<std::filesystem::path> findLeePerrySmith();

// The real scan when it can be found and read, else the built-in head.
HeadModel defaultHead();

// Head breadth: x extent (metres) of the mesh in the band of head-frame y in [y_lo_m, y_hi_m].
float headBreadthM(const HeadModel& head, float y_lo_m, float y_hi_m);

}  // namespace facescan::synth
