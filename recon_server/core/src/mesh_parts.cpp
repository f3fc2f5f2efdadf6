// The finishing stage's "head alone" (finishing.hpp): triangles outside the tracked head region or the crop box,
// then the floating fragments (connected parts much smaller than the largest).
#include <algorithm>
#include <numeric>

#include "recon/finishing.hpp"

namespace facescan::recon {
namespace {

uint32_t findRoot(std::vector<uint32_t>& parent, uint32_t v) {
    while (parent[v] != v) {
        parent[v] = parent[parent[v]];
        v = parent[v];
    }
    return v;
}

}  // namespace

void keepHead(IndexedMesh& mesh, const FinishParams& params, const HeadRegion* head, FinishReport& report) {
    const bool use_region = params.keep == KeepParts::kHead && head && head->valid;
    if (use_region || params.crop_m) {
        const size_t before = mesh.triangleCount();
        std::vector<uint8_t> inside(mesh.vertexCount(), 1);
        for (size_t v = 0; v < inside.size(); ++v) {
            const Eigen::Vector3f& p = mesh.positions_m[v];
            if (use_region && !head->contains(p)) inside[v] = 0;
            if (params.crop_m && !params.crop_m->contains(p)) inside[v] = 0;
        }
        std::erase_if(mesh.triangles,
                      [&](const Triangle& t) { return !inside[t[0]] || !inside[t[1]] || !inside[t[2]]; });
        report.triangles_outside += before - mesh.triangleCount();
    }
    if (params.keep == KeepParts::kHead && !mesh.triangles.empty()) {
        // Parts: triangles that share a vertex (the mesh is welded by position before this step).
        std::vector<uint32_t> parent(mesh.vertexCount());
        std::iota(parent.begin(), parent.end(), 0u);
        for (const Triangle& t : mesh.triangles) {
            const uint32_t a = findRoot(parent, t[0]);
            for (int k = 1; k < 3; ++k) {
                const uint32_t b = findRoot(parent, t[k]);
                if (b != a) parent[b] = a;
            }
        }
        std::vector<uint32_t> part_triangles(mesh.vertexCount(), 0);
        for (const Triangle& t : mesh.triangles) ++part_triangles[findRoot(parent, t[0])];
        const uint32_t largest = *std::max_element(part_triangles.begin(), part_triangles.end());
        const auto min_triangles = static_cast<uint32_t>(params.min_part_share * static_cast<float>(largest));
        for (const uint32_t n : part_triangles) {
            if (n > 0 && n < min_triangles) {
                ++report.parts_dropped;
                report.parts_triangles += n;
            }
        }
        std::erase_if(mesh.triangles,
                      [&](const Triangle& t) { return part_triangles[findRoot(parent, t[0])] < min_triangles; });
    }
    removeDefects(mesh);  // drops the vertices no triangle uses any more
}

}  // namespace facescan::recon
