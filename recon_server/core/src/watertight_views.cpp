// The watertight closing's views (watertight_views.hpp): rendering the model's orthographic depth maps, and the
// tiles that test a box of voxels against one at once.
#include "watertight_views.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

namespace facescan::recon::watertight_detail {

Eigen::Vector3f fibonacciDirection(int i, int n) {
    const float golden = static_cast<float>(M_PI) * (3.0f - std::sqrt(5.0f));
    const float y = 1.0f - 2.0f * (static_cast<float>(i) + 0.5f) / static_cast<float>(n);
    const float r = std::sqrt(std::max(0.0f, 1.0f - y * y));
    const float phi = golden * static_cast<float>(i);
    return {r * std::cos(phi), y, r * std::sin(phi)};
}

// Rasterises the mesh along `dir` (pixel centres inside a triangle, and every vertex's own pixel, so that
// triangles smaller than a pixel leave no gaps), then marks the empty pixels that the image border cannot reach
// through empty pixels as enclosed gaps. Returns the share of the seen pixels whose first surface faces the view.
float renderView(const IndexedMesh& mesh, const std::vector<Eigen::Vector3f>& face_normals, const Eigen::Vector3f& dir,
                 float pixel_m, DepthView& view) {
    view.dir = dir.normalized();
    view.u = view.dir.unitOrthogonal();
    view.v = view.dir.cross(view.u);
    // Each vertex projected once (u, v, depth along dir), not once per triangle that holds it.
    std::vector<Eigen::Vector3f> projected(mesh.positions_m.size());
    float u_min = std::numeric_limits<float>::max(), v_min = u_min, u_max = -u_min, v_max = -u_min;
    for (size_t i = 0; i < mesh.positions_m.size(); ++i) {
        const Eigen::Vector3f& p = mesh.positions_m[i];
        projected[i] = {p.dot(view.u), p.dot(view.v), p.dot(view.dir)};
        u_min = std::min(u_min, projected[i].x()), u_max = std::max(u_max, projected[i].x());
        v_min = std::min(v_min, projected[i].y()), v_max = std::max(v_max, projected[i].y());
    }
    view.pixel_m = pixel_m;
    view.u0 = u_min - 2 * pixel_m;
    view.v0 = v_min - 2 * pixel_m;
    view.width = static_cast<int>(std::ceil((u_max - u_min) / pixel_m)) + 4;
    view.height = static_cast<int>(std::ceil((v_max - v_min) / pixel_m)) + 4;
    const size_t n = static_cast<size_t>(view.width) * view.height;
    view.depth.assign(n, std::numeric_limits<float>::infinity());
    view.front.assign(n, 0);
    auto put = [&view](int px, int py, float d, bool front) {
        if (px < 0 || py < 0 || px >= view.width || py >= view.height) return;
        const size_t i = static_cast<size_t>(py) * view.width + px;
        if (d < view.depth[i]) view.depth[i] = d, view.front[i] = front;
    };
    for (size_t f = 0; f < mesh.triangles.size(); ++f) {
        const Triangle& t = mesh.triangles[f];
        const bool front = face_normals[f].dot(view.dir) < 0.0f;
        Eigen::Vector2f q[3];
        float d[3];
        for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3f& p = projected[t[k]];
            q[k] = {(p.x() - view.u0) / pixel_m, (p.y() - view.v0) / pixel_m};
            d[k] = p.z();
            put(static_cast<int>(q[k].x()), static_cast<int>(q[k].y()), d[k], front);
        }
        const float area = (q[1] - q[0]).x() * (q[2] - q[0]).y() - (q[1] - q[0]).y() * (q[2] - q[0]).x();
        if (std::abs(area) < 1e-12f) continue;
        // The pixels whose centres (px + 0.5) lie in the triangle's box: a triangle about a pixel wide has one or
        // two, where the box of whole pixels it touches has up to nine.
        const int x0 = static_cast<int>(std::ceil(std::min({q[0].x(), q[1].x(), q[2].x()}) - 0.5f));
        const int x1 = static_cast<int>(std::floor(std::max({q[0].x(), q[1].x(), q[2].x()}) - 0.5f));
        const int y0 = static_cast<int>(std::ceil(std::min({q[0].y(), q[1].y(), q[2].y()}) - 0.5f));
        const int y1 = static_cast<int>(std::floor(std::max({q[0].y(), q[1].y(), q[2].y()}) - 0.5f));
        for (int py = y0; py <= y1; ++py) {
            for (int px = x0; px <= x1; ++px) {
                const Eigen::Vector2f c(static_cast<float>(px) + 0.5f, static_cast<float>(py) + 0.5f);
                auto edge = [&](int a, int b) {
                    return ((q[b] - q[a]).x() * (c - q[a]).y() - (q[b] - q[a]).y() * (c - q[a]).x()) / area;
                };
                const float w0 = edge(1, 2), w1 = edge(2, 0), w2 = edge(0, 1);
                if (w0 < 0 || w1 < 0 || w2 < 0) continue;
                put(px, py, w0 * d[0] + w1 * d[1] + w2 * d[2], front);
            }
        }
    }
    // Empty pixels reachable from the border through empty pixels are free; the rest are gaps in the surface.
    std::vector<uint8_t> reached(n, 0);
    std::vector<int> stack;
    auto seed = [&](int px, int py) {
        const size_t i = static_cast<size_t>(py) * view.width + px;
        if (!reached[i] && std::isinf(view.depth[i])) reached[i] = 1, stack.push_back(static_cast<int>(i));
    };
    for (int px = 0; px < view.width; ++px) seed(px, 0), seed(px, view.height - 1);
    for (int py = 0; py < view.height; ++py) seed(0, py), seed(view.width - 1, py);
    while (!stack.empty()) {
        const int i = stack.back();
        stack.pop_back();
        const int px = i % view.width, py = i / view.width;
        if (px > 0) seed(px - 1, py);
        if (px + 1 < view.width) seed(px + 1, py);
        if (py > 0) seed(px, py - 1);
        if (py + 1 < view.height) seed(px, py + 1);
    }
    size_t seen = 0, front_seen = 0;
    for (size_t i = 0; i < n; ++i) {
        if (std::isinf(view.depth[i]) && !reached[i]) view.depth[i] = -std::numeric_limits<float>::infinity();
        if (std::isfinite(view.depth[i])) ++seen, front_seen += view.front[i];
    }
    return seen == 0 ? 0.0f : static_cast<float>(front_seen) / static_cast<float>(seen);
}

void DepthView::buildTiles() {
    tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
    tile_max.assign(static_cast<size_t>(tiles_x) * tiles_y, -std::numeric_limits<float>::infinity());
    for (int py = 0; py < height; ++py) {
        float* row = &tile_max[static_cast<size_t>(py / kTile) * tiles_x];
        for (int px = 0; px < width; ++px) {
            row[px / kTile] = std::max(row[px / kTile], depth[static_cast<size_t>(py) * width + px]);
        }
    }
}

// The box's pixels are those between its corners' (a linear map), its points' depths no nearer than its nearest
// corner's: a tile's deepest surface bounds its pixels' from behind.
bool DepthView::hiddenBox(const std::array<Eigen::Vector3f, 8>& corners, float margin_m) const {
    float u_lo = std::numeric_limits<float>::max(), u_hi = -u_lo, v_lo = u_lo, v_hi = -u_lo, d_lo = u_lo;
    for (const Eigen::Vector3f& p : corners) {
        u_lo = std::min(u_lo, p.dot(u)), u_hi = std::max(u_hi, p.dot(u));
        v_lo = std::min(v_lo, p.dot(v)), v_hi = std::max(v_hi, p.dot(v));
        d_lo = std::min(d_lo, p.dot(dir));
    }
    const int px0 = static_cast<int>(std::floor((u_lo - u0) / pixel_m)) - 1;
    const int px1 = static_cast<int>(std::floor((u_hi - u0) / pixel_m)) + 1;
    const int py0 = static_cast<int>(std::floor((v_lo - v0) / pixel_m)) - 1;
    const int py1 = static_cast<int>(std::floor((v_hi - v0) / pixel_m)) + 1;
    if (px0 < 0 || py0 < 0 || px1 >= width || py1 >= height) return false;
    // 1 % of a pixel of slack for the rounding of each voxel's own dot product.
    const float limit = d_lo + margin_m - 0.01f * pixel_m;
    for (int ty = py0 / kTile; ty <= py1 / kTile; ++ty) {
        for (int tx = px0 / kTile; tx <= px1 / kTile; ++tx) {
            if (!(tile_max[static_cast<size_t>(ty) * tiles_x + tx] <= limit)) return false;
        }
    }
    return true;
}

}  // namespace facescan::recon::watertight_detail
