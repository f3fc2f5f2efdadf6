// Which ground-truth vertices a sensor actually measured over a sequence: the OBSERVABLE part of the ruler's face
// region, over which AccuracyReport::completeness_observed is taken (AccuracyParams::observed), and the
// per-vertex diagnosis behind `facescan-bench recon --gt-misses`.
//
// The rule, for GT vertex p (normal n) in one view (camera pose T_camera_gt, the sensor's depth image):
//   1. p lies in front of the camera, projects into the image (thesis eq. 4.8, recon::Intrinsics::project), and
//      its surface faces the camera (n . p_camera < 0): a surface seen from behind is never measured;
//   2. p is VISIBLE: along the ray from the camera centre to p, no triangle of G (other than those around p) lies
//      more than `surface_tolerance_m` in front of p. This is the noise-free render's "shows this very point, not
//      a surface in front of it", asked by exact ray casting against G on p's own ray rather than on the nearest
//      pixel centre (up to half a pixel off: on an oblique cheek or in a crease that alone moves the rendered
//      depth by over a millimetre). The tolerance is below the 2 mm of completeness on purpose: a point hidden
//      only by a surface less than 1.5 mm in front of it (the folds at the inner eye corners, the line of the
//      lips) has a measured surface that close, so a perfect scan of what the sensor saw covers it and it counts
//      as observable; a point hidden deeper (eye socket, nostril, inside of the mouth) does not;
//   3. the SENSOR returned a depth at p's pixel (> 0 in its depth image): no projector shadow, no dropout, no
//      incidence cut-off, in range. Grazing views need no rule of their own: the Kinect noise model already
//      drops surfaces more oblique than its max_incidence_deg.
// A vertex is observed when this holds in at least one view. Eye sockets, nostril interiors and the inside of
// the mouth fail 2 in every view of a sequence (something is always in front), so no scanner can cover them.
// Only G occludes, moved rigidly by T_camera_gt: in the synthetic sequences (head = G) the torso is below and the
// wall behind the face, and the renderer's neck skinning starts below the chin (head-frame y < -0.12 m), under the
// ruler's face region.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "eval/accuracy.hpp"
#include "recon/camera.hpp"
#include "recon/mesh.hpp"
#include "recon/status.hpp"

namespace facescan::eval {

struct ObservedRegionParams {
    // Metres: a surface crossing p's ray closer than this in front of p does not hide p (rule 2). Keep it below
    // AccuracyParams::complete_within_m, or "observable" stops meaning "a perfect scan would cover it".
    float surface_tolerance_m = 0.0015f;
    float min_cos_angle = 0.0f;  // cosine; "usable angle" in the diagnosis only (the fusion's weight cut-off)

    Status validate() const;
};

// One frame as the sensor saw it. cv::Mat shares its pixels, so views are cheap to copy.
struct SensorView {
    recon::Pose T_camera_gt = recon::Pose::Identity();  // maps G's frame into this view's camera frame
    cv::Mat depth_m;                                    // the sensor's depth, CV_32FC1 metres, 0 = no return
    cv::Mat mask;                                       // CV_8UC1 region the pipeline keeps (head), or empty
};

// Per G vertex, over the views: how many measured it (rule above), of those how many had its pixel inside the
// view's mask, and of those how many saw it at cos(angle to the camera) >= min_cos_angle.
struct VertexSightings {
    int measured = 0;  // views
    int in_mask = 0;   // views, measured and inside the mask (an empty mask = the whole image)
    int good = 0;      // views, measured, inside the mask and at a usable angle
};

// Counts the sightings of every vertex of `gt` (needs faces and vertex normals). Views are processed in
// parallel. InvalidArgument for bad params or intrinsics, an unusable G, or a view whose depth is not
// CV_32FC1 of the intrinsics' size or whose mask is neither empty nor CV_8UC1 of that size.
StatusOr<std::vector<VertexSightings>> countSightings(const recon::Mesh& gt, const recon::Intrinsics& k,
                                                      const std::vector<SensorView>& views,
                                                      const ObservedRegionParams& params = {});

// The ruler's mask (AccuracyParams::observed): 1 where the vertex was measured in at least one view.
std::vector<uint8_t> observedMask(const std::vector<VertexSightings>& sightings);

// Why the GT face vertices (the ruler's region of `ruler`: within face_radius_m of the nose tip, normal . +z >=
// min_facing_cos) are not covered by `mesh` (aligned by acc.T_gt_mesh, covered = within complete_within_m):
// covered / never measured (not observable) / measured, never in the mask / in the mask only at poor angles /
// measured well and still not covered (the reconstruction's fault). Prints the counts and writes a PLY point
// cloud coloured by class (properties distance_mm, miss_class) to `path`.
Status writeMisses(const recon::Mesh& gt, const std::vector<VertexSightings>& sightings, const recon::Mesh& mesh,
                   const AccuracyReport& acc, const Eigen::Vector3f& nose, const AccuracyParams& ruler,
                   const std::string& path);

}  // namespace facescan::eval
