// The ruler of colour: a mesh's colour (per vertex or from a texture) rendered unlit into a camera, and how close
// two such renders are over a set of pixels (PSNR, SSIM). Unlit: the colour a model carries, not a shading of it,
// so a model and the ground-truth head are compared on what they hold.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "recon/camera.hpp"
#include "recon/indexed_mesh.hpp"

namespace facescan::eval {

// What to render: positions (metres, any frame: T_camera_mesh maps them into the camera) and the colour source.
struct ColourMesh {
    const std::vector<Eigen::Vector3f>* positions_m = nullptr;
    const std::vector<recon::Triangle>* triangles = nullptr;
    const std::vector<recon::Rgb8>* colours_rgb = nullptr;  // per vertex; used when there is no texture
    const std::vector<Eigen::Vector2f>* uv = nullptr;       // per vertex, (0, 0) the texture's top-left corner
    const cv::Mat* texture_bgr = nullptr;                   // CV_8UC3, sampled bilinearly
    // With normals (per vertex, mesh frame): lit as the synthetic Kinect lights its colour (synth/kinect_simulator:
    // Lambert from a lamp at lamp_camera_m, shade 0.35 + 0.75 cos), so that colour frames rendered here look like
    // the sensor's; without: unlit, the colour the mesh carries.
    const std::vector<Eigen::Vector3f>* normals = nullptr;
    Eigen::Vector3f lamp_camera_m = Eigen::Vector3f(-0.25f, -0.35f, 0.0f);  // metres, camera frame
};

struct ColourRender {
    cv::Mat bgr;      // CV_8UC3, background black
    cv::Mat hit;      // CV_8U, 255 where the mesh was hit
    cv::Mat point_m;  // CV_32FC3, the surface point hit, in the mesh's frame
};

// Z-buffered, perspective-correct interpolation of colour or uv; both windings drawn.
ColourRender renderColour(const ColourMesh& mesh, const recon::Pose& T_camera_mesh, const recon::Intrinsics& k);

// Peak signal-to-noise ratio (dB, 8-bit peak 255) over the pixels where mask is non-zero, all three channels.
double psnrDb(const cv::Mat& a_bgr, const cv::Mat& b_bgr, const cv::Mat& mask);
// Structural similarity (Wang, Bovik, Sheikh, Simoncelli 2004: 11x11 Gaussian window, sigma 1.5, K1 0.01, K2 0.03)
// of the luma, averaged over the pixels where mask is non-zero. 1 = identical.
double ssim(const cv::Mat& a_bgr, const cv::Mat& b_bgr, const cv::Mat& mask);

}  // namespace facescan::eval
