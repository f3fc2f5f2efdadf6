// The accuracy ruler: how close a reconstructed mesh M is to the ground-truth head G (docs/design.md s6).
//
// Face region of G: the vertices within `face_radius_m` of G's nose tip whose normal faces forward
// (normal . face_direction >= min_facing_cos). M is rigidly aligned to G (point-to-plane ICP from several
// starting poses, or from a given initial guess), then every vertex of M whose nearest point on G lies in the
// face region is a sample; distances are point-to-SURFACE (nearest triangle), never point-to-vertex.
//
// The ruler must not hide a systematic error. A uniform inflation or shrink of the surface is the typical bias of
// TSDF fusion (truncation, weighting), and a rigid alignment over the face alone slides an inflated face back
// towards the truth (a whole-head 1 mm offset read 0.33 mm). So the alignment fits the offset too, as a separate
// unknown that it does NOT apply (fit_offset): the rigid motion then has nothing to gain from absorbing it, and the
// offset stays in the distances. The figures are also reported without any alignment (`unaligned`: M as given,
// or moved by the initial guess, e.g. a synthetic sequence's true first pose), and the offset itself (offset_mm).
// Distances are to the side of G that faces the same way as M (match_facing): a sample in a thin crease (eyelids,
// the lips) is measured to its own wall, not to the opposite one a fraction of a millimetre away.
// Known answers (tests/synth/accuracy_test.cpp): the whole Lee Perry-Smith head moved 1 mm out along its normals
// reads 0.96 mm aligned and unaligned (the rest of the millimetre is real: where the moved surface comes within
// 1 mm of another wall, e.g. an eyelid over the eye, the nearest surface is nearer), 1 mm in reads 0.98 mm.
//
// Completeness is reported twice: over the whole face region, and over its OBSERVABLE part (the face vertices
// that the sensor measured in at least one frame, given by the caller as a per-vertex mask). Eye sockets, nostril
// interiors and the mouth slit are never seen by any camera pose of a sequence, so no scanner can cover them;
// the second figure is what a scanner can be held to, the first says how much of the face the scan holds.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/mesh.hpp"
#include "recon/status.hpp"

namespace facescan::eval {

struct AccuracyParams {
    float face_radius_m = 0.11f;       // metres, face region = G within this of the nose tip...
    float min_facing_cos = 0.0f;       // ...whose normal . face_direction is at least this (0 = facing forward)
    float complete_within_m = 0.002f;  // metres, a G face vertex is "covered" when M is this close
    float outlier_m = 0.005f;          // metres, M samples farther than this from G are outliers
    bool align = true;                 // run ICP; false = measure as given (after the initial guess)
    bool fit_offset = true;            // ICP also fits (and does not apply) a uniform offset along G's normals
    bool match_facing = true;          // distances to G triangles facing M's way (normal . normal > 0)
    // metres; ICP weighs residuals e (around the fitted offset) by min(1, robust_scale_m / |e|): an L1 fit, so the
    // offset is the median one and creases, holes and rims do not pull the pose. 0 = least squares.
    float robust_scale_m = 0.02e-3f;
    int icp_iterations = 40;     // per starting pose
    int max_icp_samples = 6000;  // M vertices used by ICP (uniform subsample)
    // Per G vertex (indexed by vertex idx, size = G's vertex count): 1 = observed (the sensor measured it in at
    // least one frame), 0 = never. Empty = unknown: completeness_observed is then the plain completeness.
    std::vector<uint8_t> observed;

    Status validate() const;
};

// Distances from M's face samples to G's surface, one pose of M.
struct DistanceFigures {
    double mean_mm = 0;    // mean |d|, millimetres
    double rms_mm = 0;     // root mean square of d, millimetres
    double median_mm = 0;  // median |d|, millimetres
    double p90_mm = 0;     // 90th percentile |d|, millimetres
    double outliers = 0;   // share of samples farther than outlier_m, [0, 1]
    int samples = 0;       // M vertices over G's face region (0: none at this pose; the figures are then 0)
};

struct AccuracyReport {
    double mean_mm = 0;          // mean |d| over the face samples of M, millimetres
    double rms_mm = 0;           // root mean square of d, millimetres
    double median_mm = 0;        // median |d|, millimetres
    double p90_mm = 0;           // 90th percentile |d|, millimetres
    double completeness = 0;     // share of G's face vertices within complete_within_m of M's surface, [0, 1]
    double outliers = 0;         // share of M's face samples farther than outlier_m from G, [0, 1]
    int mesh_vertices_used = 0;  // M samples in the face region
    int gt_face_vertices = 0;    // G vertices in the face region
    // Share of G's OBSERVED face vertices (AccuracyParams::observed) within complete_within_m of M, [0, 1], and
    // how many there are. Without a mask: equal to completeness and gt_face_vertices (the whole region).
    double completeness_observed = 0;
    int gt_observed_vertices = 0;
    recon::Pose T_gt_mesh = recon::Pose::Identity();  // the alignment found: maps M into G's frame
    // The same distances without alignment: M as given, moved by the initial guess when one was given.
    DistanceFigures unaligned;
    // The uniform offset of M along G's normals that the alignment found (and left in the distances), millimetres;
    // > 0: M lies outside G (inflated), < 0: inside (shrunk). 0 when not fitted.
    double offset_mm = 0;
};

// The report as one JSON object with the stable keys of docs/design.md s6 (mean_mm rms_mm median_mm p90_mm
// completeness completeness_observed observable_share outliers), plus mesh_vertices_used, offset_mm and
// unaligned{mean_mm rms_mm median_mm p90_mm outliers samples}. Every bench and the demo print this one.
std::string accuracyJson(const AccuracyReport& r);

// M with every vertex moved `offset_m` along its vertex normal (outwards for > 0): a uniform inflation or shrink,
// the typical bias of TSDF fusion, and the ruler's known answer (it must read |offset_m|).
recon::Mesh offsetAlongNormals(const recon::Mesh& mesh, float offset_m);

// The nose tip of a head-frame mesh (y up, face along +z): the most forward vertex above the neck.
Eigen::Vector3f findNoseTip(const recon::Mesh& gt_head_frame);

// Measures M against G. `gt_nose_tip` is in G's frame and `face_direction` the way G's face looks (head frame:
// +z). `T_gt_mesh_guess`, when given, is tried first (e.g. inverse of T_camera0_head for a mesh in the first
// camera frame). InvalidArgument for empty meshes or bad params, for an `observed` mask whose size is not G's
// vertex count or that marks no face vertex; NotFound when M never meets G's face.
StatusOr<AccuracyReport> measureAccuracy(const recon::Mesh& mesh, const recon::Mesh& gt,
                                         const Eigen::Vector3f& gt_nose_tip, const AccuracyParams& params = {},
                                         const std::optional<recon::Pose>& T_gt_mesh_guess = std::nullopt,
                                         const Eigen::Vector3f& face_direction = Eigen::Vector3f::UnitZ());

// Point-to-surface distance queries against a mesh (nanoflann k-d tree over vertices, then exact
// point-triangle distance over the one-rings of the k nearest vertices).
class SurfaceDistance {
 public:
    explicit SurfaceDistance(const recon::Mesh& mesh);
    ~SurfaceDistance();
    SurfaceDistance(const SurfaceDistance&) = delete;
    SurfaceDistance& operator=(const SurfaceDistance&) = delete;

    struct Hit {
        float distance_m = 0;
        Eigen::Vector3f closest = Eigen::Vector3f::Zero();  // nearest point on the surface
        Eigen::Vector3f normal = Eigen::Vector3f::UnitZ();  // normal of the triangle hit
        int face = -1;                                      // triangle index
        int nearest_vertex = -1;
    };
    Hit query(const Eigen::Vector3f& p) const;
    // The nearest point among the triangles whose normal points the way of `facing` (dot > 0), so that a point
    // between two close walls of a crease is matched to the wall it belongs to; the plain nearest point when no
    // nearby triangle faces that way.
    Hit query(const Eigen::Vector3f& p, const Eigen::Vector3f& facing) const;

 private:
    Hit nearest(const Eigen::Vector3f& p, const Eigen::Vector3f* facing) const;

    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// How many vertices of `mesh` lie farther than max_distance_m from `reference`'s surface, or nearest to a reference
// vertex that `allowed` (per reference vertex, when given) marks 0: what a scan holds that is not the reference
// (a fused torso or occluder). Both meshes in the same frame, metres.
int countVerticesFarFrom(const recon::Mesh& mesh, const recon::Mesh& reference, float max_distance_m,
                         const std::vector<uint8_t>* allowed = nullptr);

}  // namespace facescan::eval
