// The watertight closing's views (mesh_watertight.cpp): orthographic depth maps of the model, from the directions
// in which it shows its outside, that carve the space no scan observed. Internal to recon_core.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "recon/indexed_mesh.hpp"

namespace facescan::recon::watertight_detail {

// An orthographic depth map of the model seen along `dir`.
struct DepthView {
    Eigen::Vector3f dir, u, v;  // dir looks into the scene; u, v span the image plane
    float u0 = 0, v0 = 0;       // metres; the image plane position of pixel (0, 0)'s corner
    float pixel_m = 0;
    int width = 0, height = 0;
    // metres along dir of the first surface; +inf: nothing (free); -inf: an enclosed gap in the surface (a hole
    // the model did not close: covered, so that no view carves a tunnel through the solid)
    std::vector<float> depth;
    std::vector<uint8_t> front;  // per pixel, the first surface faces the view

    // The deepest first surface of each kTile x kTile pixels (+inf where one is free): what a box of voxels is
    // tested against at once (hiddenBox).
    static constexpr int kTile = 8;
    int tiles_x = 0, tiles_y = 0;
    std::vector<float> tile_max;

    bool freeAt(const Eigen::Vector3f& p, float margin_m) const {
        const int px = static_cast<int>(std::floor((p.dot(u) - u0) / pixel_m));
        const int py = static_cast<int>(std::floor((p.dot(v) - v0) / pixel_m));
        if (px < 0 || py < 0 || px >= width || py >= height) return true;
        return p.dot(dir) < depth[static_cast<size_t>(py) * width + px] - margin_m;
    }

    // Fills tile_max from depth.
    void buildTiles();
    // True when freeAt(p, margin_m) is false for every point p of the box spanned by `corners` (the box's eight
    // corners): its pixels (a pixel more on each side, against rounding) all lie in the image and its nearest
    // point is behind the deepest of their surfaces. False says nothing: its points are tested one by one.
    bool hiddenBox(const std::array<Eigen::Vector3f, 8>& corners, float margin_m) const;
};

// Direction i of n, evenly spread over the sphere (a Fibonacci lattice).
Eigen::Vector3f fibonacciDirection(int i, int n);

// Rasterises the mesh along `dir` (pixel centres inside a triangle, and every vertex's own pixel, so that
// triangles smaller than a pixel leave no gaps), then marks the empty pixels that the image border cannot reach
// through empty pixels as enclosed gaps. Returns the share of the seen pixels whose first surface faces the view.
float renderView(const IndexedMesh& mesh, const std::vector<Eigen::Vector3f>& face_normals, const Eigen::Vector3f& dir,
                 float pixel_m, DepthView& view);

}  // namespace facescan::recon::watertight_detail
