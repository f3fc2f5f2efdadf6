// Baking the texture atlas (texture_atlas.hpp, steps 2-3): texels rasterised in UV space, projected into every
// view, weighted, evened out in exposure and blended; unseen texels from the vertex colours; charts padded.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "recon/parallel.hpp"
#include "recon/texture_atlas.hpp"
#include "texture_resample.hpp"

namespace facescan::recon {
namespace {

using texture_detail::bicubic;
using texture_detail::bilinear;

// Views kept per texel. Eight rather than four: the JPEG noise of the colour frames averages out over more views,
// and more of them offer a sample near one of their pixel centres (facescan-bench texture at 640x480: +0.14 dB).
constexpr int kTopViews = 8;
// Views a texel weighs at most: those that see its triangle best (see kTopViews).
constexpr int kTriangleViews = 12;
// The exposure gains are estimated from every this many texels (a 640x480 camera's atlas has 200,000 on a face).
constexpr size_t kGainStride = 4;
// A view whose weight for a texel is under this share of the best view's is left out of its blend.
constexpr float kMinShare = 0.01f;

double msSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// A texel on the surface: where it is in the atlas and on the mesh.
struct Texel {
    int x, y;
    uint32_t triangle;  // of the textured mesh
    Eigen::Vector3f p_m, normal;
    Eigen::Vector3f vertex_bgr;  // the vertex colours there (the fallback), 0-255
};

// What one view makes of a texel: the colour in 1/256 steps (the samples of every texel are held at once).
struct Sample {
    int16_t view = -1;
    std::array<uint16_t, 3> bgr256{};
    float weight = 0;

    Eigen::Vector3f bgr() const { return Eigen::Vector3f(bgr256[0], bgr256[1], bgr256[2]) * (1.0f / 256); }
    void setBgr(const Eigen::Vector3f& c) {
        for (int i = 0; i < 3; ++i)
            bgr256[static_cast<size_t>(i)] = static_cast<uint16_t>(std::clamp(c[i], 0.0f, 255.0f) * 256 + 0.5f);
    }
};
using TopSamples = std::array<Sample, kTopViews>;

// The mesh as one view sees it: nearest depth per pixel (metres, +inf where nothing) and each pixel's distance to
// a depth edge (pixels), held only over the box of the image that the mesh covers (and a pixel around it: outside,
// nothing is seen and the distance to an edge is 0).
struct ViewDepth {
    cv::Rect box_px;     // of the colour image
    cv::Mat z_m;         // CV_32F, box_px's size (while it is built)
    cv::Mat edge_dist;   // CV_32F, box_px's size (while it is built)
    cv::Mat z_and_edge;  // CV_32FC2: both, side by side (a texel's lookup touches one cache line, not two)
    float focus = 1;     // sharpness relative to the sharpest view, (0, 1]

    // The depth (+inf where nothing) and the distance to an edge (0 outside the box) at pixel (u, v).
    void at(int u, int v, float& z, float& edge) const {
        u -= box_px.x, v -= box_px.y;
        if (u < 0 || v < 0 || u >= z_and_edge.cols || v >= z_and_edge.rows) {
            z = std::numeric_limits<float>::infinity(), edge = 0;
            return;
        }
        const cv::Vec2f& p = z_and_edge.at<cv::Vec2f>(v, u);
        z = p[0], edge = p[1];
    }
};

// Edge functions of a triangle at a point (twice the signed areas).
inline float edge(const Eigen::Vector2f& a, const Eigen::Vector2f& b, const Eigen::Vector2f& p) {
    return (b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x());
}

// Calls fn(x, y, w0, w1, w2) for each pixel centre inside the triangle (a, b, c) in pixel coordinates (the centre
// of pixel x is x), within [0, width) x [0, height); w are barycentric weights. Both windings.
template <class Fn>
void rasterise(const Eigen::Vector2f& a, const Eigen::Vector2f& b, const Eigen::Vector2f& c, int width, int height,
               Fn&& fn) {
    const float area = edge(a, b, c);
    if (!(std::abs(area) > 1e-12f)) return;
    const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({a.x(), b.x(), c.x()}))));
    const int x1 = std::min(width - 1, static_cast<int>(std::floor(std::max({a.x(), b.x(), c.x()}))));
    const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a.y(), b.y(), c.y()}))));
    const int y1 = std::min(height - 1, static_cast<int>(std::floor(std::max({a.y(), b.y(), c.y()}))));
    const float inv = 1.0f / area;
    for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
            const Eigen::Vector2f p(static_cast<float>(x), static_cast<float>(y));
            const float w0 = edge(b, c, p) * inv, w1 = edge(c, a, p) * inv, w2 = edge(a, b, p) * inv;
            if (w0 >= -1e-5f && w1 >= -1e-5f && w2 >= -1e-5f) fn(x, y, w0, w1, w2);
        }
    }
}

ViewDepth viewDepth(const IndexedMesh& mesh, const TextureView& view, const TextureParams& params) {
    const Intrinsics& k = view.colour;
    ViewDepth d;
    std::vector<Eigen::Vector3f> p_c(mesh.vertexCount());
    std::vector<Eigen::Vector2f> px(mesh.vertexCount());
    Eigen::Vector2f lo(std::numeric_limits<float>::max(), std::numeric_limits<float>::max());
    Eigen::Vector2f hi = -lo;
    for (size_t i = 0; i < mesh.vertexCount(); ++i) {
        p_c[i] = view.T_colour_mesh * mesh.positions_m[i];
        px[i] = p_c[i].z() > 1e-3f ? k.project(p_c[i]) : Eigen::Vector2f(-1e9f, -1e9f);
        if (p_c[i].z() > 1e-3f) lo = lo.cwiseMin(px[i]), hi = hi.cwiseMax(px[i]);
    }
    // Only the box the mesh covers, with two pixels around it (so that its edges lie inside): a face fills a
    // fraction of the frame, and the maps below cost per pixel.
    const cv::Rect image(0, 0, k.width_px, k.height_px);
    d.box_px = lo.x() <= hi.x() ? cv::Rect(cv::Point(static_cast<int>(std::floor(std::max(lo.x(), -1e6f))) - 2,
                                                     static_cast<int>(std::floor(std::max(lo.y(), -1e6f))) - 2),
                                           cv::Point(static_cast<int>(std::ceil(std::min(hi.x(), 1e6f))) + 3,
                                                     static_cast<int>(std::ceil(std::min(hi.y(), 1e6f))) + 3)) &
                                      image
                                : cv::Rect();
    if (d.box_px.area() == 0) d.box_px = cv::Rect(0, 0, 1, 1);
    const int width = d.box_px.width, height = d.box_px.height;
    const Eigen::Vector2f offset(static_cast<float>(d.box_px.x), static_cast<float>(d.box_px.y));
    d.z_m = cv::Mat(height, width, CV_32F, cv::Scalar(std::numeric_limits<float>::infinity()));
    for (const Triangle& t : mesh.triangles) {
        if (p_c[t[0]].z() <= 1e-3f || p_c[t[1]].z() <= 1e-3f || p_c[t[2]].z() <= 1e-3f) continue;
        // 1/z is linear in the image: interpolated, it gives the exact depth of the triangle at each pixel.
        const float iz0 = 1 / p_c[t[0]].z(), iz1 = 1 / p_c[t[1]].z(), iz2 = 1 / p_c[t[2]].z();
        rasterise(px[t[0]] - offset, px[t[1]] - offset, px[t[2]] - offset, width, height,
                  [&](int x, int y, float w0, float w1, float w2) {
                      const float z = 1.0f / (w0 * iz0 + w1 * iz1 + w2 * iz2);
                      float& zb = d.z_m.at<float>(y, x);
                      if (z < zb) zb = z;
                  });
    }
    // Edges: pixels with nothing, and pixels whose depth jumps against a neighbour.
    cv::Mat not_edge(height, width, CV_8U, cv::Scalar(255));
    for (int y = 0; y < height; ++y) {
        const float* row = d.z_m.ptr<float>(y);
        const float* below = d.z_m.ptr<float>(std::min(y + 1, height - 1));
        uint8_t* out = not_edge.ptr<uint8_t>(y);
        for (int x = 0; x < width; ++x) {
            const float z = row[x];
            const float right = row[std::min(x + 1, width - 1)];
            if (!std::isfinite(z)) {
                out[x] = 0;
            } else if (!(std::abs(right - z) < params.depth_edge_m) ||
                       !(std::abs(below[x] - z) < params.depth_edge_m)) {
                out[x] = 0;
            }
        }
    }
    cv::distanceTransform(not_edge, d.edge_dist, cv::DIST_L2, 3);
    cv::merge(std::vector<cv::Mat>{d.z_m, d.edge_dist}, d.z_and_edge);
    d.z_m.release();
    d.edge_dist.release();
    // Sharpness: the spread of the Laplacian over the pixels the mesh covers (motion blur and defocus lower it).
    cv::Mat grey, lap;
    cv::cvtColor(view.colour_bgr(d.box_px), grey, cv::COLOR_BGR2GRAY);
    cv::Laplacian(grey, lap, CV_32F);
    // Relative to the image's own contrast there, so that a darker view is not taken for a blurred one.
    cv::Scalar mean, lap_sd, grey_sd;
    cv::meanStdDev(lap, mean, lap_sd, not_edge);
    cv::meanStdDev(grey, mean, grey_sd, not_edge);
    d.focus = grey_sd[0] > 1e-3 ? static_cast<float>(lap_sd[0] / grey_sd[0]) : 0.0f;
    return d;
}

// The blend of a texel's samples under per-view gains; false when no view saw it.
bool blend(const TopSamples& s, const std::vector<Eigen::Vector3f>& gains, Eigen::Vector3f& out) {
    float w = 0;
    out.setZero();
    for (const Sample& v : s) {
        if (v.view < 0) break;
        out += v.weight * gains[static_cast<size_t>(v.view)].cwiseProduct(v.bgr());
        w += v.weight;
    }
    if (!(w > 0)) return false;
    out /= w;
    return true;
}

std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.4g", v);
    return buf;
}

}  // namespace

std::string TextureReport::summary() const {
    std::string s = "texture " + std::to_string(atlas_width_px) + "x" + std::to_string(atlas_height_px) + ", " +
                    std::to_string(charts) + " charts, " + num(texel_mm) + " mm per texel, " +
                    std::to_string(views_used) + " of " + std::to_string(views_given) + " views";
    if (texels_surface > 0) s += ", " + num(100.0 * double(texels_unseen) / double(texels_surface)) + "% unseen";
    for (const std::string& n : notes) s += "; " + n;
    return s;
}

std::string TextureReport::json() const {
    std::string j = "{\"width\": " + std::to_string(atlas_width_px) +
                    ", \"height\": " + std::to_string(atlas_height_px) + ", \"charts\": " + std::to_string(charts) +
                    ", \"texel_mm\": " + num(texel_mm) + ", \"texels\": " + std::to_string(texels_surface) +
                    ", \"unseen\": " + std::to_string(texels_unseen) + ", \"views\": " + std::to_string(views_given) +
                    ", \"views_used\": " + std::to_string(views_used) +
                    ", \"views_dark\": " + std::to_string(views_dark) + ", \"ms\": {\"charts\": " + num(ms_charts) +
                    ", \"visibility\": " + num(ms_visibility) + ", \"bake\": " + num(ms_bake) + "}, \"notes\": [";
    for (size_t i = 0; i < notes.size(); ++i) {
        std::string e;
        for (const char c : notes[i]) {
            if (c == '"' || c == '\\') e += '\\';
            if (static_cast<unsigned char>(c) >= 0x20) e += c;
        }
        j += (i ? ", \"" : "\"") + e + "\"";
    }
    return j + "]}";
}

StatusOr<TextureReport> bakeTexture(const IndexedMesh& mesh, const std::vector<TextureView>& views,
                                    const TextureParams& params, TexturedMesh& out) {
    out = TexturedMesh{};
    RETURN_IF_ERROR(params.validate());
    if (views.empty()) {
        return invalidArgument(
            "no colour frames to texture from (the camera sent no colour): the model keeps its "
            "vertex colours");
    }
    if (views.size() > static_cast<size_t>(std::numeric_limits<int16_t>::max())) {
        return invalidArgument("too many colour frames to texture from (" + std::to_string(views.size()) +
                               "): keep at most " + std::to_string(std::numeric_limits<int16_t>::max()));
    }
    // Bad views are refused before anything is built; dark ones are left out.
    std::vector<int> usable;
    int dark = 0;
    double darkest_luma = 255;
    for (size_t i = 0; i < views.size(); ++i) {
        const TextureView& v = views[i];
        if (v.colour_bgr.type() != CV_8UC3 || !v.colour.valid() || v.colour_bgr.cols != v.colour.width_px ||
            v.colour_bgr.rows != v.colour.height_px || v.colour_bgr.cols < 2 || v.colour_bgr.rows < 2) {
            return invalidArgument("colour view " + std::to_string(i) + ": a " + std::to_string(v.colour_bgr.cols) +
                                   "x" + std::to_string(v.colour_bgr.rows) +
                                   " 8-bit BGR image is needed that matches its camera's " +
                                   std::to_string(v.colour.width_px) + "x" + std::to_string(v.colour.height_px));
        }
        if (!v.T_colour_mesh.matrix().allFinite()) {
            return invalidArgument("colour view " + std::to_string(i) + ": its pose is not finite");
        }
        const cv::Scalar m = cv::mean(v.colour_bgr);
        const double luma = 0.114 * m[0] + 0.587 * m[1] + 0.299 * m[2];
        if (luma < params.min_mean_luma) {
            ++dark;
            darkest_luma = std::min(darkest_luma, luma);
            continue;
        }
        usable.push_back(static_cast<int>(i));
    }
    if (usable.empty()) {
        return invalidArgument("every colour frame is dark (mean brightness " + num(darkest_luma) + " of 255, below " +
                               num(params.min_mean_luma) +
                               "): the model keeps its vertex colours; light the face and scan again");
    }
    auto charted = textureCharts(mesh, views, params, out);
    if (!charted.isOk()) {
        out = TexturedMesh{};
        return charted.status();
    }
    TextureReport report = *charted;
    // Every texel may be on the surface: its working state, the atlas and the masks, bounded before allocating.
    const double atlas_texels = double(out.atlas_bgr.cols) * double(out.atlas_bgr.rows);
    const double need = atlas_texels * double(sizeof(Texel) + sizeof(TopSamples) + sizeof(int) + 3 + 2);
    if (need > double(params.max_memory_bytes)) {
        const std::string size = std::to_string(out.atlas_bgr.cols) + "x" + std::to_string(out.atlas_bgr.rows);
        out = TexturedMesh{};
        return resourceExhausted("baking a " + size + " texture needs about " + std::to_string(int(need / (1 << 20))) +
                                 " MiB, more than the " + std::to_string(params.max_memory_bytes >> 20) +
                                 " MiB allowed: give a coarser texel (fewer texels per pixel) or allow more memory");
    }
    report.views_given = static_cast<int>(views.size());
    report.views_dark = dark;
    if (dark > 0) report.notes.push_back(std::to_string(dark) + " dark colour frames left out");
    const IndexedMesh& m = out.mesh;
    const std::vector<Eigen::Vector3f> normals = m.hasNormals() ? m.normals : vertexNormals(m);
    const int width = out.atlas_bgr.cols, height = out.atlas_bgr.rows;

    // The texels: rasterised in UV space (texel centres), position and normal interpolated.
    auto t0 = std::chrono::steady_clock::now();
    cv::Mat owner(height, width, CV_32S, cv::Scalar(-1));
    std::vector<Texel> texels;
    // As many as the atlas has texels at most (the memory bound above counts them): the vector is not copied as it
    // grows, and the pages past the texels that come are never touched.
    texels.reserve(static_cast<size_t>(width) * static_cast<size_t>(height));
    for (size_t ti = 0; ti < m.triangles.size(); ++ti) {
        const Triangle& t = m.triangles[ti];
        const Eigen::Vector2f scale(static_cast<float>(width), static_cast<float>(height));
        const Eigen::Vector2f half(0.5f, 0.5f);
        const Eigen::Vector2f a = out.uv[t[0]].cwiseProduct(scale) - half, b = out.uv[t[1]].cwiseProduct(scale) - half,
                              c = out.uv[t[2]].cwiseProduct(scale) - half;
        rasterise(a, b, c, width, height, [&](int x, int y, float w0, float w1, float w2) {
            int& o = owner.at<int>(y, x);
            if (o >= 0) return;
            o = static_cast<int>(texels.size());
            Texel tx;
            tx.x = x, tx.y = y;
            tx.triangle = static_cast<uint32_t>(ti);
            tx.p_m = w0 * m.positions_m[t[0]] + w1 * m.positions_m[t[1]] + w2 * m.positions_m[t[2]];
            tx.normal = (w0 * normals[t[0]] + w1 * normals[t[1]] + w2 * normals[t[2]]).normalized();
            tx.vertex_bgr = Eigen::Vector3f(128, 128, 128);
            if (m.hasColours()) {
                tx.vertex_bgr.setZero();
                const float w[3] = {w0, w1, w2};
                for (int k = 0; k < 3; ++k) {
                    const Rgb8& rgb = m.colours_rgb[t[k]];
                    tx.vertex_bgr += w[k] * Eigen::Vector3f(rgb[2], rgb[1], rgb[0]);
                }
            }
            texels.push_back(tx);
        });
    }
    report.texels_surface = texels.size();

    // Visibility: each usable view's z-buffer of the mesh, its edges and its sharpness.
    std::vector<ViewDepth> depth(views.size());
    parallelFor(0, static_cast<int>(usable.size()), [&](int lo, int hi) {
        for (int i = lo; i < hi; ++i) depth[static_cast<size_t>(usable[i])] = viewDepth(mesh, views[usable[i]], params);
    });
    float sharpest = 0;
    for (const int v : usable) sharpest = std::max(sharpest, depth[static_cast<size_t>(v)].focus);
    for (const int v : usable) {
        ViewDepth& d = depth[static_cast<size_t>(v)];
        d.focus = sharpest > 0 ? std::clamp(d.focus / sharpest, 0.05f, 1.0f) : 1.0f;
    }
    report.ms_visibility = msSince(t0);

    // The views each triangle's texels try: those that may see it (its normal at a corner faces the view, with
    // some slack as a texel's normal is interpolated, its corners do not all lie behind the view or on one side
    // outside its image, nor all behind other surface in its z-buffer: inside a solid, the back of the head), at most
    // the kTriangleViews that see it best (cos^2 / z^2 and sharpness at its corners, as the texels' weights without the
    // edges and pixel centres): a texel then weighs a dozen views rather than all that face it, and the views it keeps
    // are among them.
    t0 = std::chrono::steady_clock::now();
    const size_t n_usable = usable.size();
    std::vector<float> triangle_score(m.triangles.size() * n_usable, 0.0f);
    parallelFor(0, static_cast<int>(n_usable), [&](int lo, int hi) {
        std::vector<float> score(m.vertexCount());
        std::vector<uint8_t> faces(m.vertexCount()), side(m.vertexCount()), hidden(m.vertexCount());
        for (int j = lo; j < hi; ++j) {
            const int v = usable[static_cast<size_t>(j)];
            const TextureView& view = views[static_cast<size_t>(v)];
            const Intrinsics& k = view.colour;
            const ViewDepth& d = depth[static_cast<size_t>(v)];
            for (size_t i = 0; i < m.vertexCount(); ++i) {
                const Eigen::Vector3f p_c = view.T_colour_mesh * m.positions_m[i];
                const bool ahead = p_c.z() > 1e-3f;
                const float cos_view = -(view.T_colour_mesh.linear() * normals[i]).dot(p_c.normalized());
                faces[i] = ahead && cos_view >= params.min_view_cos - 0.2f;
                score[i] = ahead && cos_view > 0 ? cos_view * cos_view / (p_c.z() * p_c.z()) : 0.0f;
                const Eigen::Vector2f px = ahead ? k.project(p_c) : Eigen::Vector2f::Zero();
                // Outside the image by side (bits: left, right, above, below), or all four when behind the camera.
                side[i] = ahead ? static_cast<uint8_t>((px.x() < -1 ? 1 : 0) | (px.x() > float(k.width_px) ? 2 : 0) |
                                                       (px.y() < -1 ? 4 : 0) | (px.y() > float(k.height_px) ? 8 : 0))
                                : 15;
                // Behind the view's z-buffer by twice what hides a texel (the texels' own test decides near it).
                int u = 0, w = 0;
                float z_view = 0, edge_dist = 0;
                hidden[i] = 0;
                if (ahead && k.nearestPixel(px, u, w)) {
                    d.at(u, w, z_view, edge_dist);
                    hidden[i] = p_c.z() > z_view + 2 * params.occlusion_m;
                }
            }
            const float focus = d.focus;
            for (size_t t = 0; t < m.triangles.size(); ++t) {
                const Triangle& tri = m.triangles[t];
                const bool facing = faces[tri[0]] || faces[tri[1]] || faces[tri[2]];
                const bool outside = (side[tri[0]] & side[tri[1]] & side[tri[2]]) != 0;
                const bool behind = hidden[tri[0]] && hidden[tri[1]] && hidden[tri[2]];
                if (facing && !outside && !behind) {
                    triangle_score[t * n_usable + static_cast<size_t>(j)] =
                        focus * (score[tri[0]] + score[tri[1]] + score[tri[2]]) + 1e-12f;
                }
            }
        }
    });
    std::vector<int16_t> triangle_views(m.triangles.size() * kTriangleViews, -1);
    parallelFor(0, static_cast<int>(m.triangles.size()), [&](int lo, int hi) {
        std::vector<std::pair<float, int16_t>> ranked;
        for (int t = lo; t < hi; ++t) {
            ranked.clear();
            for (size_t j = 0; j < n_usable; ++j) {
                const float score = triangle_score[static_cast<size_t>(t) * n_usable + j];
                if (score > 0) ranked.emplace_back(score, static_cast<int16_t>(j));
            }
            const size_t keep = std::min(ranked.size(), static_cast<size_t>(kTriangleViews));
            std::partial_sort(ranked.begin(), ranked.begin() + static_cast<std::ptrdiff_t>(keep), ranked.end(),
                              [](const auto& a, const auto& b) { return a.first > b.first; });
            for (size_t r = 0; r < keep; ++r) {
                triangle_views[static_cast<size_t>(t) * kTriangleViews + r] = ranked[r].second;
            }
        }
    });
    // Each texel's best views: weighed first, sampled after (only the kept ones).
    std::vector<TopSamples> samples(texels.size());
    const float inv_two_sigma2 = params.pixel_centre_sigma_px > 0
                                     ? 1.0f / (2 * params.pixel_centre_sigma_px * params.pixel_centre_sigma_px)
                                     : 0.0f;
    parallelFor(0, static_cast<int>(texels.size()), [&](int lo, int hi) {
        std::array<Eigen::Vector2f, kTopViews> top_px;
        for (int i = lo; i < hi; ++i) {
            const Texel& tx = texels[static_cast<size_t>(i)];
            TopSamples& top = samples[static_cast<size_t>(i)];
            const int16_t* candidates = &triangle_views[size_t{tx.triangle} * kTriangleViews];
            for (size_t c = 0; c < static_cast<size_t>(kTriangleViews) && candidates[c] >= 0; ++c) {
                const size_t j = static_cast<size_t>(candidates[c]);
                const int v = usable[j];
                const TextureView& view = views[static_cast<size_t>(v)];
                const ViewDepth& d = depth[static_cast<size_t>(v)];
                const Eigen::Vector3f p_c = view.T_colour_mesh * tx.p_m;
                if (p_c.z() <= 1e-3f) continue;
                const Eigen::Vector2f px = view.colour.project(p_c);
                int u = 0, w = 0;
                if (!view.colour.nearestPixel(px, u, w)) continue;
                float z_view = 0, edge_dist = 0;
                d.at(u, w, z_view, edge_dist);
                if (p_c.z() > z_view + params.occlusion_m) continue;  // hidden from this view
                const float cos_view = -(view.T_colour_mesh.linear() * tx.normal).dot(p_c.normalized());
                if (cos_view < params.min_view_cos) continue;
                const float edge_w =
                    params.edge_band_px > 0 ? std::clamp(edge_dist / params.edge_band_px, 0.02f, 1.0f) : 1.0f;
                // cos^2: foreshortening; 1/z^2: pixels per area of surface; scaled so that 1 m is 1.
                const float base = cos_view * cos_view / (p_c.z() * p_c.z()) * edge_w * d.focus;
                float weight = params.weight_power == 1.0f ? base : std::pow(base, params.weight_power);
                // Near a pixel centre the view holds the point's own colour; between centres only an interpolation
                // of its neighbours, which blurs. Views see the surface at different sub-pixel offsets, so the
                // blend leans on those that sampled the point itself (a scattered-data reconstruction from all
                // views' pixels rather than an average of interpolated ones).
                if (inv_two_sigma2 > 0) {
                    const float dx = px.x() - static_cast<float>(u), dy = px.y() - static_cast<float>(w);
                    // exp(-x) as (1 - x/8)^8, three squarings instead of a call (within 0.02 of it for x in
                    // [0, 4], where a texel half a pixel's diagonal off a centre lands with sigma 0.25 px)
                    const float x = std::min((dx * dx + dy * dy) * inv_two_sigma2, 7.9f);
                    float e = 1.0f - x * 0.125f;
                    e *= e, e *= e, e *= e;
                    weight *= e;
                }
                if (!(weight > 0)) continue;
                // Insert into the top list, kept sorted by weight.
                int slot = kTopViews;
                while (slot > 0 && (top[static_cast<size_t>(slot - 1)].view < 0 ||
                                    top[static_cast<size_t>(slot - 1)].weight < weight))
                    --slot;
                if (slot >= kTopViews) continue;
                for (int s = kTopViews - 1; s > slot; --s) {
                    top[static_cast<size_t>(s)] = top[static_cast<size_t>(s - 1)];
                    top_px[static_cast<size_t>(s)] = top_px[static_cast<size_t>(s - 1)];
                }
                top[static_cast<size_t>(slot)].view = static_cast<int16_t>(v);
                top[static_cast<size_t>(slot)].weight = weight;
                top_px[static_cast<size_t>(slot)] = px;
            }
            for (size_t s = 0; s < top.size() && top[s].view >= 0; ++s) {
                if (top[s].weight < kMinShare * top[0].weight) {  // it would not show: not worth its sampling
                    for (size_t r = s; r < top.size(); ++r) top[r] = Sample{};
                    break;
                }
                const cv::Mat& img = views[static_cast<size_t>(top[s].view)].colour_bgr;
                const Eigen::Vector2f& px = top_px[s];
                top[s].setBgr(params.bicubic ? bicubic(img, px.x(), px.y()) : bilinear(img, px.x(), px.y()));
            }
        }
    });

    // Exposure: per-view, per-channel gains that match each view to what the other views saw of the same texels
    // (leave-one-out: a view that dominates its texels would otherwise match itself), a few rounds.
    std::vector<Eigen::Vector3f> gains(views.size(), Eigen::Vector3f::Ones());
    if (params.even_exposure && usable.size() > 1) {
        for (int round = 0; round < 3; ++round) {
            std::vector<Eigen::Vector3d> num_sum(views.size(), Eigen::Vector3d::Zero()),
                den_sum(views.size(), Eigen::Vector3d::Zero());
            // Every kGainStride-th texel: a view's gain is a ratio of sums over tens of thousands of texels.
            for (size_t i = 0; i < samples.size(); i += kGainStride) {
                const TopSamples& s = samples[i];
                if (s[1].view < 0) continue;  // only texels that views share
                // The others' blend is the whole blend less the view's own share.
                // (in double: where one view dominates, the others' share is a small difference of large sums).
                Eigen::Vector3d all = Eigen::Vector3d::Zero();
                double w_all = 0;
                for (const Sample& o : s) {
                    if (o.view < 0) break;
                    all += o.weight * gains[static_cast<size_t>(o.view)].cwiseProduct(o.bgr()).cast<double>();
                    w_all += o.weight;
                }
                for (const Sample& v : s) {
                    if (v.view < 0) break;
                    const Eigen::Vector3d bgr = v.bgr().cast<double>();
                    const double w_others = w_all - v.weight;
                    if (!(w_others > 1e-9 * w_all)) continue;
                    const Eigen::Vector3d others =
                        (all - v.weight * gains[static_cast<size_t>(v.view)].cast<double>().cwiseProduct(bgr)) /
                        w_others;
                    // Where both are well seen: the lesser of the two weights, flattened (every view counts).
                    const double w = std::sqrt(std::min(static_cast<double>(v.weight), w_others));
                    num_sum[static_cast<size_t>(v.view)] += w * others.cwiseMax(0.0);
                    den_sum[static_cast<size_t>(v.view)] += w * bgr;
                }
            }
            std::vector<float> per_channel[3];
            for (const int v : usable) {
                const size_t i = static_cast<size_t>(v);
                for (int c = 0; c < 3; ++c) {
                    if (den_sum[i][c] > 1e-6)
                        gains[i][c] = std::clamp(float(num_sum[i][c] / den_sum[i][c]), 0.5f, 2.0f);
                    per_channel[c].push_back(gains[i][c]);
                }
            }
            // Most views are exposed alike: the median gain is 1, and the odd view is brought to the others.
            for (int c = 0; c < 3; ++c) {
                std::vector<float>& g = per_channel[c];
                std::nth_element(g.begin(), g.begin() + g.size() / 2, g.end());
                const float median = g[g.size() / 2];
                if (median > 0) {
                    for (Eigen::Vector3f& gain : gains) gain[c] /= median;
                }
            }
        }
    }
    report.gains = gains;

    // The atlas: blended texels, vertex colours where no view saw, then padding.
    cv::Mat filled(height, width, CV_8U, cv::Scalar(0));
    std::vector<uint8_t> painted_by(views.size(), 0);
    for (size_t i = 0; i < texels.size(); ++i) {
        Eigen::Vector3f bgr;
        if (!blend(samples[i], gains, bgr)) {
            bgr = texels[i].vertex_bgr;
            ++report.texels_unseen;
        } else {
            for (const Sample& s : samples[i]) {
                if (s.view >= 0) painted_by[static_cast<size_t>(s.view)] = 1;
            }
        }
        cv::Vec3b& px = out.atlas_bgr.at<cv::Vec3b>(texels[i].y, texels[i].x);
        for (int c = 0; c < 3; ++c) px[c] = cv::saturate_cast<uint8_t>(bgr[c]);
        filled.at<uint8_t>(texels[i].y, texels[i].x) = 1;
    }
    for (const uint8_t p : painted_by) report.views_used += p;
    // Padding, a ring of texels a pass: each empty texel next to a filled one takes their mean. Only the ring is
    // visited (a dilation of the filled mask finds it), not the whole atlas.
    const cv::Mat box3 = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
    std::vector<cv::Point> ring;
    for (int pass = 0; pass < params.padding_px + 1; ++pass) {
        cv::Mat grown;
        cv::dilate(filled, grown, box3);
        cv::findNonZero(grown - filled, ring);
        if (ring.empty()) break;
        for (const cv::Point& at : ring) {
            Eigen::Vector3f sum = Eigen::Vector3f::Zero();
            int count = 0;
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    const int nx = at.x + dx, ny = at.y + dy;
                    if (nx < 0 || ny < 0 || nx >= width || ny >= height || !filled.at<uint8_t>(ny, nx)) continue;
                    const cv::Vec3b& c = out.atlas_bgr.at<cv::Vec3b>(ny, nx);
                    sum += Eigen::Vector3f(c[0], c[1], c[2]);
                    ++count;
                }
            }
            if (count == 0) continue;
            sum /= static_cast<float>(count);
            out.atlas_bgr.at<cv::Vec3b>(at) =
                cv::Vec3b(cv::saturate_cast<uint8_t>(sum[0]), cv::saturate_cast<uint8_t>(sum[1]),
                          cv::saturate_cast<uint8_t>(sum[2]));
        }
        for (const cv::Point& at : ring) filled.at<uint8_t>(at) = 1;
    }
    report.ms_bake = msSince(t0);
    if (report.texels_surface > 0 && report.texels_unseen * 5 > report.texels_surface) {
        report.notes.push_back(num(100.0 * double(report.texels_unseen) / double(report.texels_surface)) +
                               "% of the surface was seen by no colour frame: painted from the vertex colours");
    }
    return report;
}

}  // namespace facescan::recon
