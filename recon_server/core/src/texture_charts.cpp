// The texture atlas's UV charts (texture_atlas.hpp, step 1): a cylindrical unwrap of the head around its vertical
// axis with the cut at the back, planar caps for the crown and under the chin, packed on shelves.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <unordered_map>

#include "recon/texture_atlas.hpp"

namespace facescan::recon {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kDefaultTexelM = 0.001f;  // metres; without views nor texel_m: a millimetre per texel

struct Chart {
    std::vector<uint32_t> triangles;         // indices into the input mesh
    std::vector<Eigen::Vector2f> corners_m;  // 3 per triangle: chart coordinates in metres (x right, y down)
    std::vector<uint8_t> wrapped;            // 1 per corner: the copy past the cylinder's cut
    Eigen::AlignedBox2f box;                 // of corners_m
    int width_px = 0, height_px = 0, x_px = 0, y_px = 0;  // placed size and top-left corner, padding included
};

struct HeadAxes {
    Eigen::Vector3f centre, up, front, right;  // metres; unit vectors, right = up x front (a photo's x)
};

HeadAxes headAxes(const IndexedMesh& mesh, const std::vector<TextureView>& views) {
    HeadAxes a;
    a.centre = Eigen::Vector3f::Zero();
    for (const Eigen::Vector3f& p : mesh.positions_m) a.centre += p;
    a.centre /= static_cast<float>(std::max<size_t>(1, mesh.vertexCount()));
    a.up = Eigen::Vector3f(0, -1, 0);  // a camera frame: y down
    Eigen::Vector3f towards_camera = -a.centre;
    if (!views.empty()) {
        // The first view's up (cameras are held upright); the front: towards the mean camera centre.
        a.up = -(views[0].T_colour_mesh.linear().transpose() * Eigen::Vector3f::UnitY());
        Eigen::Vector3f mean_centre = Eigen::Vector3f::Zero();
        for (const TextureView& v : views) mean_centre += v.T_colour_mesh.inverse().translation();
        towards_camera = mean_centre / static_cast<float>(views.size()) - a.centre;
    }
    a.up.normalize();
    a.front = towards_camera - towards_camera.dot(a.up) * a.up;
    if (a.front.norm() < 1e-6f) a.front = a.up.unitOrthogonal();
    a.front.normalize();
    a.right = a.up.cross(a.front);
    return a;
}

float texelSize(const IndexedMesh& mesh, const std::vector<TextureView>& views, const TextureParams& params,
                const Eigen::Vector3f& centre) {
    if (params.texel_m > 0) return params.texel_m;
    std::vector<float> sizes;
    for (const TextureView& v : views) {
        const float z = (v.T_colour_mesh * centre).z();
        if (z > 0 && v.colour.fx_px > 0) sizes.push_back(z / v.colour.fx_px / params.texels_per_pixel);
    }
    (void)mesh;
    if (sizes.empty()) return kDefaultTexelM;
    std::nth_element(sizes.begin(), sizes.begin() + sizes.size() / 2, sizes.end());
    return sizes[sizes.size() / 2];
}

uint32_t findRoot(std::vector<uint32_t>& parent, uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
}

// The cylinder holds one layer of surface only where the head is star-shaped about its axis. A solid closed
// behind the face (ClosingMode::kWatertight) is not: the surfaces the carving left inside it, and folds such as
// an ear against the head, unwrap onto the same place as the surface the views see, and the texels of the two
// would be one (the bake gives each texel to one triangle: the other shows its colours, or leaves flat vertex
// colours on the face). So the cylinder's triangles claim its texels outermost first (by their distance from the
// axis: the one the cameras see), and a triangle whose texels are already taken leaves the cylinder for charts of
// its own.
// The charts of surface that left the cylinder hold this many texels a side per texel of the rest: on a solid it
// is mostly surface no camera saw (inside, the back), and at full resolution it tripled the atlas at 1280x720
// (facescan-bench texture: the solid's texture 39.53 dB at 0.5, 39.56 at 0.25; the open model's unchanged).
constexpr float kLayerScale = 0.25f;

void splitOverlaps(const IndexedMesh& mesh, const HeadAxes& axes, float texel_m, std::vector<Chart>& charts) {
    Chart& cylinder = charts[0];
    const size_t n = cylinder.triangles.size();
    if (n == 0) return;
    Eigen::AlignedBox2f box;
    for (const Eigen::Vector2f& p : cylinder.corners_m) box.extend(p);
    const Eigen::Vector2f size = box.sizes() / texel_m;
    if (!(size.x() < 32768 && size.y() < 32768)) return;  // beyond any atlas: textureCharts refuses it
    const int width = static_cast<int>(size.x()) + 2, height = static_cast<int>(size.y()) + 2;
    std::vector<uint8_t> taken(size_t(width) * size_t(height), 0);
    std::vector<float> radius(n);
    for (size_t j = 0; j < n; ++j) {
        const Triangle& t = mesh.triangles[cylinder.triangles[j]];
        const Eigen::Vector3f d =
            (mesh.positions_m[t[0]] + mesh.positions_m[t[1]] + mesh.positions_m[t[2]]) / 3 - axes.centre;
        radius[j] = std::hypot(d.dot(axes.right), d.dot(axes.front));
    }
    std::vector<size_t> order(n);
    std::iota(order.begin(), order.end(), size_t{0});
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return radius[a] > radius[b]; });
    std::vector<uint8_t> leaves(n, 0);
    std::vector<size_t> cells;
    for (const size_t j : order) {
        Eigen::Vector2f c[3];
        for (int k = 0; k < 3; ++k) c[k] = (cylinder.corners_m[j * 3 + k] - box.min()) / texel_m;
        const float area = (c[1] - c[0]).x() * (c[2] - c[0]).y() - (c[1] - c[0]).y() * (c[2] - c[0]).x();
        if (!(std::abs(area) > 1e-9f)) continue;
        const int x0 = std::max(0, static_cast<int>(std::floor(std::min({c[0].x(), c[1].x(), c[2].x()}))));
        const int x1 = std::min(width - 1, static_cast<int>(std::ceil(std::max({c[0].x(), c[1].x(), c[2].x()}))));
        const int y0 = std::max(0, static_cast<int>(std::floor(std::min({c[0].y(), c[1].y(), c[2].y()}))));
        const int y1 = std::min(height - 1, static_cast<int>(std::ceil(std::max({c[0].y(), c[1].y(), c[2].y()}))));
        // Texel centres strictly inside (a centre on an edge two neighbours share is neither's).
        cells.clear();
        bool overlaps = false;
        for (int y = y0; y <= y1 && !overlaps; ++y) {
            for (int x = x0; x <= x1; ++x) {
                const Eigen::Vector2f p(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f);
                bool inside = true;
                for (int k = 0; k < 3 && inside; ++k) {
                    const Eigen::Vector2f& a = c[k];
                    const Eigen::Vector2f& b = c[(k + 1) % 3];
                    const float e = ((b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x())) / area;
                    inside = e > 1e-4f;
                }
                if (!inside) continue;
                const size_t cell = size_t(y) * size_t(width) + size_t(x);
                if (taken[cell]) {
                    overlaps = true;
                    break;
                }
                cells.push_back(cell);
            }
        }
        if (overlaps) {
            leaves[j] = 1;
        } else {
            for (const size_t cell : cells) taken[cell] = 1;
        }
    }
    // The triangles that left: each goes with the one of the head's six directions (front, back, right, left,
    // up, down) that its normal is nearest, and each connected piece of a direction (through shared vertices) is
    // a chart seen along it, as a cube map's face. One projection for a whole piece that wraps around would fold
    // it onto itself.
    const Eigen::Vector3f directions[6] = {axes.front, -axes.front, axes.right, -axes.right, axes.up, -axes.up};
    const size_t n_vertices = mesh.vertexCount();
    std::vector<uint8_t> direction(n, 0);
    std::vector<uint32_t> parent(n_vertices * 6);
    std::iota(parent.begin(), parent.end(), 0u);
    for (size_t j = 0; j < n; ++j) {
        if (!leaves[j]) continue;
        const Triangle& t = mesh.triangles[cylinder.triangles[j]];
        const Eigen::Vector3f& a = mesh.positions_m[t[0]];
        const Eigen::Vector3f normal = (mesh.positions_m[t[1]] - a).cross(mesh.positions_m[t[2]] - a);
        int best = 0;
        for (int d = 1; d < 6; ++d) {
            if (normal.dot(directions[d]) > normal.dot(directions[best])) best = d;
        }
        direction[j] = static_cast<uint8_t>(best);
        const uint32_t side = static_cast<uint32_t>(size_t(best) * n_vertices);
        for (int k = 1; k < 3; ++k) parent[findRoot(parent, t[0] + side)] = findRoot(parent, t[k] + side);
    }
    std::unordered_map<uint32_t, std::vector<size_t>> pieces;
    Chart kept;
    for (size_t j = 0; j < n; ++j) {
        if (leaves[j]) {
            const uint32_t side = static_cast<uint32_t>(size_t(direction[j]) * n_vertices);
            pieces[findRoot(parent, mesh.triangles[cylinder.triangles[j]][0] + side)].push_back(j);
            continue;
        }
        kept.triangles.push_back(cylinder.triangles[j]);
        for (int k = 0; k < 3; ++k) {
            kept.corners_m.push_back(cylinder.corners_m[j * 3 + k]);
            kept.wrapped.push_back(cylinder.wrapped[j * 3 + k]);
        }
    }
    if (pieces.empty()) return;
    std::vector<Chart> more;
    for (auto& [root, members] : pieces) {
        const Eigen::Vector3f& normal = directions[direction[members.front()]];
        // Seen from outside along the direction: x right, y down in that view (the head's up, or its front for
        // the up and down directions).
        const Eigen::Vector3f y_axis = std::abs(normal.dot(axes.up)) > 0.5f ? -axes.front : -axes.up;
        const Eigen::Vector3f x_axis = y_axis.cross(normal);
        Chart c;
        for (const size_t j : members) {
            const Triangle& t = mesh.triangles[cylinder.triangles[j]];
            c.triangles.push_back(cylinder.triangles[j]);
            for (int k = 0; k < 3; ++k) {
                const Eigen::Vector3f d = mesh.positions_m[t[k]] - axes.centre;
                c.corners_m.emplace_back(kLayerScale * d.dot(x_axis), kLayerScale * d.dot(y_axis));
                c.wrapped.push_back(0);
            }
        }
        more.push_back(std::move(c));
    }
    charts[0] = std::move(kept);
    for (Chart& c : more) charts.push_back(std::move(c));
}

}  // namespace

Status TextureParams::validate() const {
    if (!(texel_m >= 0 && texel_m < 0.1f))
        return invalidArgument("texel_m must be metres in [0, 0.1) (0: the camera's)");
    if (!(texels_per_pixel > 0 && texels_per_pixel <= 4)) {
        return invalidArgument("texels_per_pixel must be in (0, 4]");
    }
    if (max_atlas_px < 64 || max_atlas_px > kMaxAtlasPxLimit) {
        return invalidArgument("max_atlas_px must be in [64, " + std::to_string(kMaxAtlasPxLimit) + "]");
    }
    if (max_memory_bytes < (size_t{1} << 20)) return invalidArgument("max_memory_bytes must be at least 1 MiB");
    if (padding_px < 0 || padding_px > 64) return invalidArgument("padding_px must be in [0, 64] texels");
    if (!(cap_cos > 0 && cap_cos <= 1)) return invalidArgument("cap_cos must be in (0, 1]");
    if (!(min_view_cos >= 0 && min_view_cos < 1)) return invalidArgument("min_view_cos must be in [0, 1)");
    if (!(occlusion_m > 0) || !(depth_edge_m > 0) || !(edge_band_px >= 0)) {
        return invalidArgument("occlusion_m and depth_edge_m must be positive metres, edge_band_px at least 0");
    }
    if (!(weight_power >= 1 && weight_power <= 16)) return invalidArgument("weight_power must be in [1, 16]");
    if (!(pixel_centre_sigma_px >= 0 && pixel_centre_sigma_px <= 10)) {
        return invalidArgument("pixel_centre_sigma_px must be in [0, 10] pixels (0: off)");
    }
    if (!(min_mean_luma >= 0 && min_mean_luma < 255)) return invalidArgument("min_mean_luma must be in [0, 255)");
    return Status::ok();
}

StatusOr<TextureReport> textureCharts(const IndexedMesh& mesh, const std::vector<TextureView>& views,
                                      const TextureParams& params, TexturedMesh& out) {
    RETURN_IF_ERROR(params.validate());
    out = TexturedMesh{};
    if (mesh.triangles.empty()) return invalidArgument("the mesh has no triangles: nothing to texture");
    const auto t0 = std::chrono::steady_clock::now();
    TextureReport report;
    const HeadAxes axes = headAxes(mesh, views);
    const float texel_m = texelSize(mesh, views, params, axes.centre);
    report.texel_mm = texel_m * 1000.0f;

    // Which chart each triangle joins: 0 the cylinder, else a cap (connected pieces of up- or down-facing
    // triangles, joined through shared vertices).
    const size_t n_tri = mesh.triangleCount();
    std::vector<int8_t> cap(n_tri, 0);  // +1 faces up, -1 faces down, 0 the cylinder
    for (size_t f = 0; f < n_tri; ++f) {
        const Triangle& t = mesh.triangles[f];
        const Eigen::Vector3f& a = mesh.positions_m[t[0]];
        const Eigen::Vector3f n = (mesh.positions_m[t[1]] - a).cross(mesh.positions_m[t[2]] - a);
        const float len = n.norm();
        if (len <= 0) continue;
        const float c = n.dot(axes.up) / len;
        cap[f] = c > params.cap_cos ? 1 : (c < -params.cap_cos ? -1 : 0);
    }
    std::vector<uint32_t> parent(mesh.vertexCount() * 2);  // vertex copies per cap side
    std::iota(parent.begin(), parent.end(), 0u);
    for (size_t f = 0; f < n_tri; ++f) {
        if (cap[f] == 0) continue;
        const uint32_t side = cap[f] > 0 ? 0 : static_cast<uint32_t>(mesh.vertexCount());
        const Triangle& t = mesh.triangles[f];
        for (int k = 1; k < 3; ++k) parent[findRoot(parent, t[0] + side)] = findRoot(parent, t[k] + side);
    }
    std::vector<Chart> charts(1);
    std::unordered_map<uint32_t, size_t> chart_of_root;
    std::vector<float> radii;
    radii.reserve(mesh.vertexCount());
    for (const Eigen::Vector3f& p : mesh.positions_m) {
        const Eigen::Vector3f d = p - axes.centre;
        radii.push_back(std::hypot(d.dot(axes.right), d.dot(axes.front)));
    }
    // The cylinder's radius: u = angle * radius keeps texels square where the head is this far from its axis;
    // the 75th percentile, so that little of the head gets fewer texels than the camera's pixels.
    std::vector<float> sorted_radii = radii;
    std::nth_element(sorted_radii.begin(), sorted_radii.begin() + sorted_radii.size() * 3 / 4, sorted_radii.end());
    const float radius_m = std::max(1e-3f, sorted_radii[sorted_radii.size() * 3 / 4]);
    for (size_t f = 0; f < n_tri; ++f) {
        const Triangle& t = mesh.triangles[f];
        if (cap[f] == 0) {
            Chart& c = charts[0];
            float angle[3];
            for (int k = 0; k < 3; ++k) {
                const Eigen::Vector3f d = mesh.positions_m[t[k]] - axes.centre;
                angle[k] = std::atan2(d.dot(axes.right), d.dot(axes.front));  // 0 at the face, +-pi at the back
            }
            const bool straddles =
                std::max({angle[0], angle[1], angle[2]}) - std::min({angle[0], angle[1], angle[2]}) > kPi;
            c.triangles.push_back(static_cast<uint32_t>(f));
            for (int k = 0; k < 3; ++k) {
                const bool wrap = straddles && angle[k] < 0;  // the triangle across the cut goes to the +pi side
                const float a = angle[k] + (wrap ? 2 * kPi : 0.0f);
                const Eigen::Vector3f d = mesh.positions_m[t[k]] - axes.centre;
                c.corners_m.emplace_back(a * radius_m, -d.dot(axes.up));
                c.wrapped.push_back(wrap ? 1 : 0);
            }
            continue;
        }
        const uint32_t side = cap[f] > 0 ? 0 : static_cast<uint32_t>(mesh.vertexCount());
        const uint32_t root = findRoot(parent, t[0] + side);
        auto [it, added] = chart_of_root.try_emplace(root, charts.size());
        if (added) charts.emplace_back();
        Chart& c = charts[it->second];
        c.triangles.push_back(static_cast<uint32_t>(f));
        for (int k = 0; k < 3; ++k) {
            const Eigen::Vector3f d = mesh.positions_m[t[k]] - axes.centre;
            // Seen along the axis; the down-facing caps mirrored so that they are not seen from behind.
            const float x = d.dot(axes.right) * (cap[f] > 0 ? 1.0f : -1.0f);
            c.corners_m.emplace_back(x, d.dot(axes.front));
            c.wrapped.push_back(0);
        }
    }
    splitOverlaps(mesh, axes, texel_m, charts);
    if (charts[0].triangles.empty()) charts.erase(charts.begin());

    // Shelf packing: tallest first, rows as wide as the square the charts' area would fill (or the widest chart).
    const int pad = params.padding_px;
    double area_px = 0;
    int widest = 0;
    for (Chart& c : charts) {
        for (const Eigen::Vector2f& p : c.corners_m) c.box.extend(p);
        const Eigen::Vector2f size = c.box.sizes() / texel_m;
        c.width_px = static_cast<int>(std::ceil(std::min(size.x(), 1e6f))) + 2 * pad + 2;
        c.height_px = static_cast<int>(std::ceil(std::min(size.y(), 1e6f))) + 2 * pad + 2;
        area_px += double(c.width_px) * c.height_px;
        widest = std::max(widest, c.width_px);
    }
    std::vector<size_t> order(charts.size());
    std::iota(order.begin(), order.end(), size_t{0});
    std::sort(order.begin(), order.end(),
              [&](size_t a, size_t b) { return charts[a].height_px > charts[b].height_px; });
    const int shelf_px = std::max(widest, static_cast<int>(std::ceil(std::sqrt(area_px * 1.1))));
    int x = 0, y = 0, row_h = 0;
    for (const size_t i : order) {
        Chart& c = charts[i];
        if (x + c.width_px > shelf_px) x = 0, y += row_h, row_h = 0;
        c.x_px = x, c.y_px = y;
        x += c.width_px;
        row_h = std::max(row_h, c.height_px);
    }
    const int width_px = (shelf_px + 3) / 4 * 4, height_px = (y + row_h + 3) / 4 * 4;
    report.atlas_width_px = width_px;
    report.atlas_height_px = height_px;
    report.charts = static_cast<int>(charts.size());
    if (width_px > params.max_atlas_px || height_px > params.max_atlas_px) {
        const double mib = double(width_px) * height_px * 3 / (1 << 20);
        return resourceExhausted("a texture of " + std::to_string(width_px) + "x" + std::to_string(height_px) +
                                 " texels (" + std::to_string(static_cast<int>(mib)) + " MiB) at " +
                                 std::to_string(report.texel_mm) + " mm per texel exceeds the largest atlas side, " +
                                 std::to_string(params.max_atlas_px) +
                                 " texels: give a coarser texel size or a larger atlas limit");
    }

    // Vertices split per (vertex, chart, side of the cut); uv in glTF's convention.
    std::unordered_map<uint64_t, uint32_t> copy_of;
    copy_of.reserve(mesh.vertexCount() * 2);
    out.mesh.triangles.reserve(n_tri);
    const bool normals = mesh.hasNormals(), colours = mesh.hasColours();
    for (size_t ci = 0; ci < charts.size(); ++ci) {
        const Chart& c = charts[ci];
        for (size_t j = 0; j < c.triangles.size(); ++j) {
            const Triangle& t = mesh.triangles[c.triangles[j]];
            Triangle nt;
            for (int k = 0; k < 3; ++k) {
                const size_t corner = j * 3 + k;
                const uint64_t key = (uint64_t(t[k]) << 32) | (uint64_t(ci) << 1) | c.wrapped[corner];
                auto [it, added] = copy_of.try_emplace(key, static_cast<uint32_t>(out.mesh.positions_m.size()));
                if (added) {
                    out.mesh.positions_m.push_back(mesh.positions_m[t[k]]);
                    if (normals) out.mesh.normals.push_back(mesh.normals[t[k]]);
                    if (colours) out.mesh.colours_rgb.push_back(mesh.colours_rgb[t[k]]);
                    out.source_vertex.push_back(t[k]);
                    const Eigen::Vector2f px = (c.corners_m[corner] - c.box.min()) / texel_m +
                                               Eigen::Vector2f(c.x_px + pad + 1, c.y_px + pad + 1);
                    out.uv.emplace_back(px.x() / width_px, px.y() / height_px);
                }
                nt[k] = it->second;
            }
            out.mesh.triangles.push_back(nt);
        }
    }
    out.atlas_bgr = cv::Mat(height_px, width_px, CV_8UC3, cv::Scalar::all(0));
    report.ms_charts = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return report;
}

}  // namespace facescan::recon
