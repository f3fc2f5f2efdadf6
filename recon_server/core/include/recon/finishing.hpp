// Finishing: what turns the volume's raw extraction into the model a user takes away. Runs on the final mesh of a
// scan, in the server's finish (with the head region the segmentation tracked) and in `facescan mesh` (on the
// mesh it fetched). The steps, in order:
//  1. the head alone: triangles outside the tracked head region (the torso below the chin plane, background) and
//     outside an optional crop box go, then every connected part much smaller than the largest (floating
//     fragments), unless keep = kAll;
//  2. closing: holes up to a size filled with new triangles; the surface that was seen keeps every vertex where it
//     was (closing only adds); or the head closed into a solid with a flat cut below the chin (watertight: a
//     closed manifold for a 3D printer), re-meshed from the volume with its unseen inside filled;
//  3. a triangle budget: quadric error decimation (Garland and Heckbert 1997) through OpenMesh's Decimater,
//     half-edge collapses only (a kept vertex keeps its measured position and colour), with the paper's boundary
//     constraint planes, so the rim of the scan and the holes that were left stay where they were.
// The report says what each step did and how far the result lies from the full mesh.
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <vector>

#include "recon/indexed_mesh.hpp"
#include "recon/mesh_distance.hpp"
#include "recon/model_segmenter.hpp"
#include "recon/status.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {

enum class KeepParts { kHead, kAll };
enum class ClosingMode { kNone, kHoles, kWatertight };

// Fewer triangles than this cannot hold a face (eyes, nose and mouth need a few hundred on their own).
inline constexpr int kMinTriangleBudget = 500;

struct FinishParams {
    int max_triangles = 0;  // triangles; 0 = no budget (full resolution), else at least kMinTriangleBudget
    KeepParts keep = KeepParts::kHead;
    // ratio; with keep = kHead a connected part with fewer triangles than this share of the largest part is a
    // floating fragment (1% of a 80k-triangle head is about 9 cm^2: an ear or the nose never come apart that small)
    float min_part_share = 0.01f;
    std::optional<Eigen::AlignedBox3f> crop_m;  // metres, the mesh's frame; triangles with a vertex outside go
    ClosingMode close = ClosingMode::kNone;
    // metres; closing fills a hole whose boundary loop fits in a ball of this diameter (nostrils, eye corners, pits
    // the sensor did not see); the scan's outer rim is never filled by kHoles
    float max_hole_m = 0.02f;
    // metres; watertight without the scan's volume (`facescan mesh` on a fetched model): the lattice the mesh is
    // turned into a signed distance on (1.5 mm: the server's voxels)
    float watertight_voxel_m = 0.0015f;
    bool measure_distance = true;  // report the distance from the full mesh's vertices to the result's surface

    Status validate() const;
};

// Named triangle budgets: web 20,000 (a page loads it in a moment), avatar 50,000 (a game engine's head),
// print 200,000 (a printer wants the detail: above what a scan holds, so in effect full), full 0 (no budget).
// InvalidArgument naming the presets for any other name.
StatusOr<int> triangleBudgetPreset(const std::string& name);
// "web", "avatar", "print", "full" or a count of triangles: the value of a --max-triangles option.
StatusOr<int> parseTriangleBudget(const std::string& text);
StatusOr<KeepParts> parseKeepParts(const std::string& text);          // head | all
StatusOr<ClosingMode> parseClosingMode(const std::string& text);      // none | holes | watertight
StatusOr<Eigen::AlignedBox3f> parseCropBox(const std::string& text);  // "x0,y0,z0,x1,y1,z1" in metres
const char* keepPartsName(KeepParts keep);
const char* closingModeName(ClosingMode close);

// CPU milliseconds per step of a finish: the calling thread's, plus what the parallel pool's workers spent on its
// calls (parallel.hpp's accounting), so parallelism does not hide cost. The watertight steps: the field (the seen
// band, the views, carving), marching cubes with its largest piece, the pinch checks and the rounds of thickening
// (each meshes again), the final manifold check.
struct FinishCpuMs {
    double parts = 0, close = 0, decimate = 0, distance = 0;
    double close_field = 0, close_march = 0, close_thicken = 0, close_check = 0;  // within close
    double total() const { return parts + close + decimate + distance; }
};

// CPU milliseconds spent so far by the calling thread and, on its behalf, the pool (turns the thread's pool
// accounting on).
double finishCpuNowMs();

struct FinishReport {
    size_t triangles_in = 0;
    size_t triangles_out = 0;
    size_t vertices_out = 0;
    size_t triangles_outside = 0;  // dropped outside the head region or the crop box
    size_t parts_dropped = 0;      // floating fragments dropped
    size_t parts_triangles = 0;    // their triangles
    size_t holes_filled = 0;
    size_t holes_left = 0;        // boundary loops left open (the rim, and holes larger than max_hole_m)
    size_t triangles_added = 0;   // by closing
    bool watertight = false;      // closed into a solid (closed, manifold, one piece)
    size_t views_used = 0;        // watertight: the directions whose depth maps carved the free space
    size_t pinches_repaired = 0;  // watertight: rounds of thickening where the surface touched itself
    bool budget_reached = true;   // false when no legal collapse was left before the budget
    // full mesh (after step 1) vertices, at most 30,000 of them evenly spread, -> result surface; zero when not
    // measured
    DistanceFigures distance;
    double ms_parts = 0, ms_close = 0, ms_decimate = 0, ms_distance = 0;  // milliseconds, wall clock
    FinishCpuMs cpu_ms;
    std::vector<std::string> notes;  // what the user should know (a budget not reached, a hole too large, ...)

    std::string summary() const;       // one line for logs and the command line
    std::string json() const;          // one JSON object (summary.json's "finish")
    std::string cpuBreakdown() const;  // one line: CPU ms per step (the watertight steps where it closed)
};

// Finishes `mesh` in place (metres; colours and normals kept, normals recomputed where the mesh changed).
// `head`: where the tracked head can be (the server's Reconstructor::headRegion()); null where it is not known
// (`facescan mesh` on a fetched model): the head is then the largest part. InvalidArgument for bad params; an
// empty mesh stays empty. Every other problem is a note: the user always gets a model.
// `volume`: the scan's TSDF (the server's finish), which watertight closing re-meshes so that the seen surface
// keeps its very triangles; null: watertight turns the mesh itself into a signed distance first (meshVolume), and
// the seen surface moves by what re-meshing at watertight_voxel_m costs (the report's distance says how far).
StatusOr<FinishReport> finishMesh(IndexedMesh& mesh, const FinishParams& params, const HeadRegion* head = nullptr,
                                  const VoxelBlockGrid* volume = nullptr);

// The steps on their own (finishMesh calls them in order).
// Drops triangles outside the region and the crop box, then, with keep = kHead, parts smaller than
// min_part_share of the largest. Unreferenced vertices are removed.
void keepHead(IndexedMesh& mesh, const FinishParams& params, const HeadRegion* head, FinishReport& report);
// Fills holes whose boundary loop spans at most max_hole_m with a fan around a new vertex at the loop's centroid
// (coloured as the loop's mean). Existing vertices and triangles are unchanged; only simple loops (no vertex twice)
// are filled.
void fillHoles(IndexedMesh& mesh, float max_hole_m, FinishReport& report);
// Closes `mesh` (the head alone, after keepHead) into a solid (mesh_watertight.cpp): `observed` keeps its values
// where its weight is above zero, the rest of the lattice around the mesh is inside where every view of the mesh
// has it behind the surface; cut by the head region's chin plane and the crop box; re-meshed by marching cubes.
// False, with a note and `mesh` unchanged, when the mesh saw too little of a head or the result is not a closed
// manifold.
bool closeWatertight(IndexedMesh& mesh, const VoxelBlockGrid& observed, const HeadRegion* head,
                     const FinishParams& params, FinishReport& report);
// A signed distance volume of a mesh's band: voxels within two voxels of a triangle, on its normal's line (not
// beside the rim, where the side is not known), get weight 1 and their signed distance in units of the band, the
// rest weight 0. With `values` (the scan's volume), on its lattice, and the band's voxels take its D(x) and colour
// where it observed them (weight 0 where it did not): the seen head alone, without the volume's other parts.
VoxelBlockGrid meshVolume(const IndexedMesh& mesh, float voxel_m, const VoxelBlockGrid* values = nullptr);
// Quadric decimation down to max_triangles (boundary constraint planes; no collapse that flips a normal).
void decimate(IndexedMesh& mesh, int max_triangles, FinishReport& report);

}  // namespace facescan::recon
