// Software z-buffer rasteriser: triangles are binned into bands of rows, bands are rendered in parallel.
// Depth is interpolated as 1/z (linear in screen space), attributes with perspective-correct barycentrics.
#include "raster.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/core/utility.hpp>

namespace facescan::synth::detail {
namespace {
constexpr int kBandRows = 16;

struct ScreenVertex {
    float u, v, inv_z;
    bool ok;
};
}  // namespace

void rasterise(const std::vector<Eigen::Vector3f>& points_camera, const std::vector<Eigen::Vector3i>& triangles,
               const recon::Intrinsics& k, GBuffer& g, float near_m) {
    const int w = k.width_px, h = k.height_px;
    g.depth_m.create(h, w, CV_32F);
    g.depth_m.setTo(0);
    g.tri.create(h, w, CV_32S);
    g.tri.setTo(-1);
    g.bary.create(h, w, CV_32FC2);

    std::vector<ScreenVertex> sv(points_camera.size());
    for (size_t i = 0; i < points_camera.size(); ++i) {
        const Eigen::Vector3f& p = points_camera[i];
        if (!(p.z() > near_m) || !p.allFinite()) {
            sv[i] = {0, 0, 0, false};
            continue;
        }
        const Eigen::Vector2f uv = k.project(p);  // thesis eq. 4.8, the one projection helper
        sv[i] = {uv.x(), uv.y(), 1.0f / p.z(), true};
    }

    const int bands = (h + kBandRows - 1) / kBandRows;
    std::vector<std::vector<int>> binned(bands);
    for (int t = 0; t < static_cast<int>(triangles.size()); ++t) {
        const auto& tri = triangles[t];
        const ScreenVertex &a = sv[tri[0]], &b = sv[tri[1]], &c = sv[tri[2]];
        if (!a.ok || !b.ok || !c.ok) continue;
        const float v_lo = std::min({a.v, b.v, c.v}), v_hi = std::max({a.v, b.v, c.v});
        const float u_lo = std::min({a.u, b.u, c.u}), u_hi = std::max({a.u, b.u, c.u});
        if (v_hi < 0 || v_lo > h - 1 || u_hi < 0 || u_lo > w - 1) continue;
        const int band0 = std::max(0, static_cast<int>(std::ceil(v_lo)) / kBandRows);
        const int band1 = std::min(bands - 1, static_cast<int>(std::floor(std::min(v_hi, h - 1.0f))) / kBandRows);
        for (int bi = band0; bi <= band1; ++bi) binned[bi].push_back(t);
    }

    cv::parallel_for_(cv::Range(0, bands), [&](const cv::Range& range) {
        for (int band = range.start; band < range.end; ++band) {
            const int row0 = band * kBandRows, row1 = std::min(h, row0 + kBandRows) - 1;
            for (const int t : binned[band]) {
                const auto& tri = triangles[t];
                const ScreenVertex &a = sv[tri[0]], &b = sv[tri[1]], &c = sv[tri[2]];
                const float area = (b.u - a.u) * (c.v - a.v) - (b.v - a.v) * (c.u - a.u);
                if (std::abs(area) < 1e-9f) continue;
                const float inv_area = 1.0f / area;
                const int v0 = std::max(row0, static_cast<int>(std::ceil(std::min({a.v, b.v, c.v}))));
                const int v1 = std::min(row1, static_cast<int>(std::floor(std::max({a.v, b.v, c.v}))));
                const int u0 = std::max(0, static_cast<int>(std::ceil(std::min({a.u, b.u, c.u}))));
                const int u1 = std::min(w - 1, static_cast<int>(std::floor(std::max({a.u, b.u, c.u}))));
                for (int v = v0; v <= v1; ++v) {
                    float* zrow = g.depth_m.ptr<float>(v);
                    int* trow = g.tri.ptr<int>(v);
                    cv::Vec2f* brow = g.bary.ptr<cv::Vec2f>(v);
                    const float py = static_cast<float>(v);
                    for (int u = u0; u <= u1; ++u) {
                        const float px = static_cast<float>(u);
                        // Edge functions normalised by the signed area: screen-space barycentrics.
                        const float w1 = ((px - a.u) * (c.v - a.v) - (py - a.v) * (c.u - a.u)) * inv_area;
                        const float w2 = ((b.u - a.u) * (py - a.v) - (b.v - a.v) * (px - a.u)) * inv_area;
                        const float w0 = 1.0f - w1 - w2;
                        // A hair of tolerance so that the shared edge of two triangles is never missed by both
                        // (rounding).
                        if (w0 < -1e-6f || w1 < -1e-6f || w2 < -1e-6f) continue;
                        const float inv_z = w0 * a.inv_z + w1 * b.inv_z + w2 * c.inv_z;
                        const float z = 1.0f / inv_z;
                        if (zrow[u] != 0 && z >= zrow[u]) continue;
                        zrow[u] = z;
                        trow[u] = t;
                        // Perspective-correct: attribute weights are w_i / z_i renormalised.
                        brow[u] = cv::Vec2f(w1 * b.inv_z * z, w2 * c.inv_z * z);
                    }
                }
            }
        }
    });
}

}  // namespace facescan::synth::detail
