// The error drawn on the model, as the thesis' Figure 5.2 does: every vertex of a mesh coloured by its distance to
// the ground-truth surface, rendered from the front and from both sides, with a colour bar in millimetres.
// A small software rasteriser (orthographic, z-buffered, Lambert-shaded so the shape reads) and OpenCV's drawing.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "recon/mesh.hpp"
#include "recon/status.hpp"

namespace facescan::eval {

struct HeatMapParams {
    float max_error_mm = 0;         // mm; the top of the colour bar (0: the 99th percentile, rounded up to 0.5 mm)
    float region_radius_m = 0.11f;  // metres; vertices farther than this from the nose tip are drawn grey
    int view_width_px = 420;        // pixels; each of the three views
    int view_height_px = 520;       // pixels
    std::string title;              // drawn above the views (e.g. the file names and the mean error)
    Status validate() const;
};

// `mesh`: in G's head frame (y up, the face along +z; measureAccuracy's T_gt_mesh applied); `error_mm`: one
// distance per vertex of `mesh`, millimetres (negative: not measured, drawn grey); `nose_tip`: G's nose tip (head
// frame). A BGR image: front, the subject's left side and right side, and the colour bar. InvalidArgument for a
// mesh without triangles or a per-vertex list of the wrong size.
StatusOr<cv::Mat> renderErrorHeatMap(const recon::Mesh& mesh, const std::vector<float>& error_mm,
                                     const Eigen::Vector3f& nose_tip, const HeatMapParams& params = {});

// Per vertex of `mesh_in_gt` (already in G's frame), the distance in mm to G's surface, to the wall facing the
// vertex's way (as the ruler measures).
std::vector<float> vertexErrorsMm(const recon::Mesh& mesh_in_gt, const recon::Mesh& gt);

}  // namespace facescan::eval
