// Watertight closing (finishing.hpp): the head as a closed solid, cut flat below the chin.
//
// The solid is a signed field on a voxel lattice, meshed by marching cubes (thesis section 4.2.2), whose crack-free
// table gives a closed, oriented surface wherever every cube has all eight corners (each cube face is split the
// same way by both of its cubes). The field:
//  - where the volume observed a voxel (weight > 0) within two voxels of the head's surface (meshVolume: the
//    volume's other parts, torso or fragments, do not count) it keeps D(x) as integrated (thesis eq. 4.22-4.26):
//    marching cubes then gives the very triangles of the open model there, so the seen surface stays in place;
//  - a voxel that was never observed is outside when some view sees it as free space (in front of the surface,
//    or beside it), inside when every view has it behind the surface (space carving with the model's own depth
//    maps). The views are orthographic, from the directions in which the model shows its outside: the front
//    faces fill nearly all of what a view sees. A face scan thus closes behind itself, as far as its sides reach;
//  - below the chin plane, outside the head region and the crop box (intersected with their signed distance, so
//    a cut is flat on its plane), and on the lattice's outer layer, outside.
// Only the largest closed piece is kept (the head; an unseen bubble inside it would be a second piece).
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>

#include "recon/finishing.hpp"
#include "recon/marching_cubes.hpp"
#include "recon/mesh_distance.hpp"
#include "recon/parallel.hpp"
#include "watertight_views.hpp"

namespace facescan::recon {
namespace {

using watertight_detail::DepthView;
using watertight_detail::fibonacciDirection;
using watertight_detail::renderView;

constexpr int kViewDirections = 48;  // count; directions tried, evenly spread over the sphere (about 30 degrees apart)
constexpr float kMinFrontShare = 0.9f;  // ratio; a view is used when front faces fill this share of what it sees
constexpr int kMarginVox = 3;           // voxels; lattice layers beyond the model's box (the outer one is outside)
// A scan that saw less than this is too little to close: a face from ear to ear is about 400 cm^2, its front
// alone (brows to chin, cheek to cheek) about 200 cm^2.
constexpr double kMinSeenAreaM2 = 0.015;
constexpr float kMinDepthM = 0.04f;  // metres; nor when the surface is flatter than this along its mean normal

double surfaceArea(const IndexedMesh& mesh, Eigen::Vector3f* mean_normal) {
    double area = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const Triangle& t : mesh.triangles) {
        const Eigen::Vector3f c =
            (mesh.positions_m[t[1]] - mesh.positions_m[t[0]]).cross(mesh.positions_m[t[2]] - mesh.positions_m[t[0]]);
        area += 0.5 * c.norm();
        sum += 0.5 * c.cast<double>();
    }
    if (mean_normal)
        *mean_normal = sum.norm() > 0 ? Eigen::Vector3f(sum.normalized().cast<float>()) : Eigen::Vector3f::Zero();
    return area;
}

// The lattice of the solid: the model's box plus a margin, on `observed`'s voxels (so that an observed voxel is
// copied, never resampled), every block of the box allocated.
VoxelBlockGrid makeLattice(const VoxelBlockGrid& observed, const Eigen::AlignedBox3f& box_m, Eigen::Vector3i& offset,
                           Eigen::Vector3i& dims) {
    const float h = observed.voxel_size_m;
    const Eigen::Vector3f lo = (box_m.min() - observed.origin_world) / h;
    const Eigen::Vector3f hi = (box_m.max() - observed.origin_world) / h;
    for (int a = 0; a < 3; ++a) {
        offset[a] = static_cast<int>(std::floor(lo[a])) - kMarginVox;
        dims[a] = static_cast<int>(std::ceil(hi[a])) + kMarginVox - offset[a] + 1;
    }
    VoxelBlockGrid g;
    g.blocks_per_side = (dims.maxCoeff() + kBlockSide - 1) / kBlockSide;
    g.resolution_vox = g.blocks_per_side * kBlockSide;
    g.voxel_size_m = h;
    g.trunc_dist_m = observed.trunc_dist_m;
    g.origin_world = observed.origin_world + offset.cast<float>() * h;
    const size_t bps = static_cast<size_t>(g.blocks_per_side);
    g.block_index.assign(bps * bps * bps, -1);
    const Eigen::Vector3i blocks = (dims.array() + kBlockSide - 1) / kBlockSide;
    for (int bz = 0; bz < blocks.z(); ++bz) {
        for (int by = 0; by < blocks.y(); ++by) {
            for (int bx = 0; bx < blocks.x(); ++bx) {
                g.block_index[(bz * bps + by) * bps + bx] = g.allocated_blocks++;
                g.block_coords.emplace_back(bx, by, bz);
            }
        }
    }
    g.voxels.assign(static_cast<size_t>(g.allocated_blocks) * kBlockVoxels, Voxel{});
    return g;
}

Voxel* voxelAt(VoxelBlockGrid& g, int x, int y, int z) {
    const size_t bps = static_cast<size_t>(g.blocks_per_side);
    const int b = g.block_index[((z >> 3) * bps + (y >> 3)) * bps + (x >> 3)];
    return &g.voxels[static_cast<size_t>(b) * kBlockVoxels + ((z & 7) * 64 + (y & 7) * 8 + (x & 7))];
}

// Where the solid is one voxel thin, marching cubes' surface can touch itself: the two cubes on either side of an
// ambiguous face both fan a loop through it (the same triangle twice, facing opposite ways), or two sheets meet
// in a vertex. The positions of such vertices (on an edge not shared by exactly two triangles, or whose
// triangles form more than one fan); empty for a closed manifold.
std::vector<Eigen::Vector3f> pinches(const IndexedMesh& mesh) {
    // Per vertex, its triangles (a CSR), and the other two vertices of each as (other, triangle) pairs sorted by
    // the other: a run of equal others is one edge at the vertex and its triangles, and joins them into a fan. One
    // pass of small sorts, not a sort of every edge of the solid.
    std::vector<uint32_t> start(mesh.vertexCount() + 1, 0), incident(mesh.triangleCount() * 3);
    for (const Triangle& t : mesh.triangles) ++start[t[0] + 1], ++start[t[1] + 1], ++start[t[2] + 1];
    std::partial_sum(start.begin(), start.end(), start.begin());
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (uint32_t f = 0; f < mesh.triangleCount(); ++f) {
        for (const uint32_t v : mesh.triangles[f]) incident[fill[v]++] = f;
    }
    std::vector<uint8_t> bad(mesh.vertexCount(), 0);
    std::vector<int> parent;
    std::vector<std::pair<uint32_t, int>> others;
    for (uint32_t v = 0; v < mesh.vertexCount(); ++v) {
        const uint32_t n = start[v + 1] - start[v];
        parent.resize(n);
        std::iota(parent.begin(), parent.end(), 0);
        auto root = [&parent](int i) {
            while (parent[i] != i) i = parent[i] = parent[parent[i]];
            return i;
        };
        others.clear();
        for (uint32_t i = 0; i < n; ++i) {
            const Triangle& t = mesh.triangles[incident[start[v] + i]];
            if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) bad[v] = 1;  // a triangle without area
            for (const uint32_t w : t) {
                if (w != v) others.emplace_back(w, static_cast<int>(i));
            }
        }
        for (size_t i = 1; i < others.size(); ++i) {  // insertion sort: a dozen pairs
            for (size_t j = i; j > 0 && others[j] < others[j - 1]; --j) std::swap(others[j], others[j - 1]);
        }
        int fans = static_cast<int>(n);
        for (size_t i = 0; i < others.size();) {
            size_t j = i + 1;
            while (j < others.size() && others[j].first == others[i].first) ++j;
            if (j - i != 2) bad[v] = 1;  // an edge not shared by exactly two triangles (its other end sees it too)
            for (size_t k = i + 1; k < j; ++k) {
                const int a = root(others[i].second), b = root(others[k].second);
                if (a != b) parent[a] = b, --fans;
            }
            i = j;
        }
        if (fans > 1) bad[v] = 1;
    }
    std::vector<Eigen::Vector3f> out;
    for (uint32_t v = 0; v < mesh.vertexCount(); ++v) {
        if (bad[v]) out.push_back(mesh.positions_m[v]);
    }
    return out;
}

}  // namespace

VoxelBlockGrid meshVolume(const IndexedMesh& mesh, float voxel_m, const VoxelBlockGrid* values) {
    VoxelBlockGrid g;
    if (mesh.triangles.empty() || !(voxel_m > 0)) return g;
    Eigen::AlignedBox3f box;
    for (const Eigen::Vector3f& p : mesh.positions_m) box.extend(p);
    VoxelBlockGrid unit;  // the lattice: the volume's, or one with its voxel (0,0,0) at the box's corner
    unit.voxel_size_m = values ? values->voxel_size_m : voxel_m;
    unit.trunc_dist_m = 2 * unit.voxel_size_m;
    unit.origin_world = values ? values->origin_world : box.min();
    voxel_m = unit.voxel_size_m;
    Eigen::Vector3i offset, dims;
    g = makeLattice(unit, box, offset, dims);
    g.trunc_dist_m = unit.trunc_dist_m;
    // Per voxel within the band: the distance to the nearest triangle, signed by its side of that triangle. A
    // voxel beside the rim (its nearest point on a boundary edge, off the triangle's normal) stays unobserved:
    // there the side is not known, and the carving decides.
    const float band_m = g.trunc_dist_m, band_sq = band_m * band_m;
    std::vector<float> best(g.voxels.size(), std::numeric_limits<float>::infinity());
    for (const Triangle& t : mesh.triangles) {
        const Eigen::Vector3f &a = mesh.positions_m[t[0]], &b = mesh.positions_m[t[1]], &c = mesh.positions_m[t[2]];
        const Eigen::Vector3f cross = (b - a).cross(c - a);
        if (!(cross.norm() > 0)) continue;
        const Eigen::Vector3f n = cross.normalized();
        Eigen::AlignedBox3f tb(a);
        tb.extend(b).extend(c);
        const Eigen::Vector3f lo = g.toVoxel(tb.min()).array() - band_m / voxel_m;
        const Eigen::Vector3f hi = g.toVoxel(tb.max()).array() + band_m / voxel_m;
        for (int z = std::max(0, static_cast<int>(std::ceil(lo.z())));
             z <= std::min(dims.z() - 1, static_cast<int>(hi.z())); ++z) {
            for (int y = std::max(0, static_cast<int>(std::ceil(lo.y())));
                 y <= std::min(dims.y() - 1, static_cast<int>(hi.y())); ++y) {
                for (int x = std::max(0, static_cast<int>(std::ceil(lo.x())));
                     x <= std::min(dims.x() - 1, static_cast<int>(hi.x())); ++x) {
                    const Eigen::Vector3f p =
                        g.toWorld(Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)));
                    // The distance to the triangle's plane bounds the distance to the triangle from below: most
                    // of the box lies beyond the band or beyond a nearer triangle, and is done without the
                    // closest point.
                    const float to_plane = std::abs((p - a).dot(n));
                    if (to_plane >= band_m) continue;
                    // So does the distance to the triangle's box (the box's corners beside the triangle), with
                    // 0.01 % to spare for the closest point's rounding.
                    const float box_sq = (tb.min() - p).cwiseMax(p - tb.max()).cwiseMax(0.0f).squaredNorm() * 0.9999f;
                    if (box_sq >= band_sq) continue;
                    Voxel* v = voxelAt(g, x, y, z);
                    const size_t i = static_cast<size_t>(v - g.voxels.data());
                    if (to_plane >= best[i] || box_sq >= best[i] * best[i]) continue;
                    const Eigen::Vector3f q = closestPointOnTriangle(p, a, b, c);
                    const float dist = (p - q).norm();
                    if (dist >= band_m || dist >= best[i]) continue;
                    best[i] = dist;
                    const float along = (p - q).dot(n);
                    if (dist > 1e-6f && std::abs(along) < 0.7f * dist) {
                        v->weight = 0;  // beside the rim or an edge: the side is not known here
                        continue;
                    }
                    v->tsdf = std::clamp((along < 0 ? -dist : dist) / band_m, -1.0f, 1.0f);
                    v->weight = 1;
                }
            }
        }
    }
    if (values) {
        // The band's voxels take what the volume integrated (D in its own truncation units, its colour), or are
        // unobserved where it has nothing.
        parallelFor(0, dims.z(), [&](int z_lo, int z_hi) {
            for (int z = z_lo; z < z_hi; ++z) {
                for (int y = 0; y < dims.y(); ++y) {
                    for (int x = 0; x < dims.x(); ++x) {
                        Voxel* v = voxelAt(g, x, y, z);
                        if (!(v->weight > 0)) continue;
                        const Voxel* in = values->voxel(x + offset.x(), y + offset.y(), z + offset.z());
                        *v = in && in->weight > 0 ? *in : Voxel{};
                    }
                }
            }
        });
        g.trunc_dist_m = values->trunc_dist_m;
        return g;
    }
    // Colours: the nearest vertex's, by the triangles' own vertices (good enough for a band two voxels wide).
    if (mesh.hasColours()) {
        for (const Triangle& t : mesh.triangles) {
            for (int k = 0; k < 3; ++k) {
                const Eigen::Vector3f pv = g.toVoxel(mesh.positions_m[t[k]]);
                const int x = static_cast<int>(std::lround(pv.x())), y = static_cast<int>(std::lround(pv.y())),
                          z = static_cast<int>(std::lround(pv.z()));
                if (x < 0 || y < 0 || z < 0 || x >= dims.x() || y >= dims.y() || z >= dims.z()) continue;
                Voxel* v = voxelAt(g, x, y, z);
                v->r = mesh.colours_rgb[t[k]][0], v->g = mesh.colours_rgb[t[k]][1], v->b = mesh.colours_rgb[t[k]][2];
            }
        }
    }
    return g;
}

bool closeWatertight(IndexedMesh& mesh, const VoxelBlockGrid& observed, const HeadRegion* head,
                     const FinishParams& params, FinishReport& report) {
    auto tooLittle = [&report](const std::string& why) {
        report.notes.push_back("watertight: the scan saw too little of the head to close it (" + why +
                               "): delivered the open mesh; scan the face and both sides, turning the head");
        return false;
    };
    if (mesh.triangles.empty() || observed.voxels.empty()) return tooLittle("nothing to close");
    Eigen::Vector3f mean_normal;
    const double area_m2 = surfaceArea(mesh, &mean_normal);
    char buf[96];
    if (area_m2 < kMinSeenAreaM2) {
        std::snprintf(buf, sizeof buf, "%.0f cm^2 seen, a face needs %.0f", area_m2 * 1e4, kMinSeenAreaM2 * 1e4);
        return tooLittle(buf);
    }
    if (mean_normal.squaredNorm() > 0) {
        float lo = std::numeric_limits<float>::max(), hi = -lo;
        for (const Eigen::Vector3f& p : mesh.positions_m)
            lo = std::min(lo, p.dot(mean_normal)), hi = std::max(hi, p.dot(mean_normal));
        if (hi - lo < kMinDepthM) {
            std::snprintf(buf, sizeof buf, "%.0f mm deep, a head is over %.0f", (hi - lo) * 1e3, kMinDepthM * 1e3);
            return tooLittle(buf);
        }
    }
    const float h = observed.voxel_size_m;
    double c0 = finishCpuNowMs();

    // The views that show the model's outside.
    std::vector<Eigen::Vector3f> face_normals(mesh.triangles.size());
    for (size_t f = 0; f < mesh.triangles.size(); ++f) {
        const Triangle& t = mesh.triangles[f];
        face_normals[f] =
            (mesh.positions_m[t[1]] - mesh.positions_m[t[0]]).cross(mesh.positions_m[t[2]] - mesh.positions_m[t[0]]);
    }
    std::vector<DepthView> candidates(kViewDirections);
    std::vector<float> share(kViewDirections);
    parallelFor(0, kViewDirections, [&](int lo, int hi) {
        for (int i = lo; i < hi; ++i)
            share[i] = renderView(mesh, face_normals, fibonacciDirection(i, kViewDirections), h, candidates[i]);
    });
    std::vector<DepthView> views;
    for (int i = 0; i < kViewDirections; ++i) {
        if (share[i] >= kMinFrontShare) views.push_back(std::move(candidates[i]));
    }
    candidates.clear();
    if (views.empty()) return tooLittle("no direction shows its outside");
    parallelFor(0, static_cast<int>(views.size()), [&](int lo, int hi) {
        for (int i = lo; i < hi; ++i) views[static_cast<size_t>(i)].buildTiles();
    });

    // The field.
    Eigen::AlignedBox3f box;
    for (const Eigen::Vector3f& p : mesh.positions_m) box.extend(p);
    Eigen::Vector3i offset, dims;
    VoxelBlockGrid solid = makeLattice(observed, box, offset, dims);
    // Unobserved voxels take the mean colour of the observed surface (the texture atlas paints the model anyway).
    Eigen::Vector3d colour_sum = Eigen::Vector3d::Zero();
    double colour_n = 0;
    for (int b = 0; b < observed.allocated_blocks; ++b) {
        for (int i = 0; i < kBlockVoxels; ++i) {
            const Voxel& v = observed.voxels[static_cast<size_t>(b) * kBlockVoxels + i];
            if (v.weight > 0 && std::abs(v.tsdf) < 0.5f) colour_sum += Eigen::Vector3d(v.b, v.g, v.r), colour_n += 1;
        }
    }
    const Eigen::Vector3d fill = colour_n > 0 ? Eigen::Vector3d(colour_sum / colour_n) : Eigen::Vector3d(200, 200, 200);
    // Exact zeros would put a crossing on a corner, shared by several cube edges: kept off it (the crossings
    // keep off corners anyway: MeshParams::min_crossing below).
    constexpr float kNudge = 1e-4f;
    // Signed distance to the region that stays (negative inside): the head region's sphere and chin plane, and
    // the crop box.
    const float trunc_m = std::max(observed.trunc_dist_m, h);
    auto cutDistance = [&](const Eigen::Vector3f& p) {
        float d = -std::numeric_limits<float>::infinity();
        if (head && head->valid) {
            const Eigen::Vector3f r = p - head->centre_world;
            d = std::max(r.norm() - head->radius_m, r.dot(head->down_world) - head->below_centre_m);
        }
        if (params.crop_m) {
            const Eigen::Vector3f below = params.crop_m->min() - p, above = p - params.crop_m->max();
            const Eigen::Vector3f outside = below.cwiseMax(above);
            const float to_box = outside.maxCoeff() <= 0 ? outside.maxCoeff() : outside.cwiseMax(0.0f).norm();
            d = std::max(d, to_box);
        }
        return d;
    };
    // Voxels beside the band behind the seen surface (its rim, where the band ends) are inside, so that the solid
    // there is never a sheet one voxel thin (marching cubes would pinch it): the observed negative voxels, dilated
    // by one voxel (a 3x3x3 box, as three passes of one axis each).
    const size_t nx = static_cast<size_t>(dims.x()), ny = static_cast<size_t>(dims.y()),
                 nz = static_cast<size_t>(dims.z());
    auto at = [nx, ny](int x, int y, int z) {
        return (static_cast<size_t>(z) * ny + static_cast<size_t>(y)) * nx + static_cast<size_t>(x);
    };
    std::vector<uint8_t> behind(nx * ny * nz, 0), pass(nx * ny * nz, 0);
    parallelFor(0, dims.z(), [&](int z_lo, int z_hi) {
        for (int z = z_lo; z < z_hi; ++z)
            for (int y = 0; y < dims.y(); ++y)
                for (int x = 0; x < dims.x(); ++x) {
                    const Voxel* in = observed.voxel(x + offset.x(), y + offset.y(), z + offset.z());
                    behind[at(x, y, z)] = in && in->weight > 0 && in->tsdf < 0;
                }
    });
    for (int axis = 0; axis < 3; ++axis) {
        const size_t stride = axis == 0 ? 1 : axis == 1 ? nx : nx * ny;
        const int len = dims[axis];
        parallelFor(0, dims.z(), [&](int z_lo, int z_hi) {
            for (int z = z_lo; z < z_hi; ++z)
                for (int y = 0; y < dims.y(); ++y)
                    for (int x = 0; x < dims.x(); ++x) {
                        const size_t i = at(x, y, z);
                        const int c = axis == 0 ? x : axis == 1 ? y : z;
                        pass[i] = behind[i] | (c > 0 ? behind[i - stride] : 0) | (c + 1 < len ? behind[i + stride] : 0);
                    }
        });
        behind.swap(pass);
    }
    // The voxels deep inside the solid are the dearest to carve: every view is asked before they are found
    // inside. A block of the lattice that every view has wholly behind its surface is inside at once (the same
    // answer as each of its voxels would get, see DepthView::hiddenBox).
    const Eigen::Vector3i blocks = (dims.array() + kBlockSide - 1) / kBlockSide;
    std::vector<uint8_t> block_hidden(static_cast<size_t>(blocks.prod()), 0);
    auto blockOf = [&blocks](int x, int y, int z) {
        return (static_cast<size_t>(z / kBlockSide) * blocks.y() + static_cast<size_t>(y / kBlockSide)) * blocks.x() +
               static_cast<size_t>(x / kBlockSide);
    };
    parallelFor(0, blocks.z(), [&](int bz_lo, int bz_hi) {
        std::array<Eigen::Vector3f, 8> corners;
        for (int bz = bz_lo; bz < bz_hi; ++bz) {
            for (int by = 0; by < blocks.y(); ++by) {
                for (int bx = 0; bx < blocks.x(); ++bx) {
                    const Eigen::Vector3i lo(bx * kBlockSide, by * kBlockSide, bz * kBlockSide);
                    const Eigen::Vector3i hi = (lo.array() + (kBlockSide - 1)).min(dims.array() - 1);
                    for (int c = 0; c < 8; ++c) {
                        corners[static_cast<size_t>(c)] = solid.toWorld(Eigen::Vector3f(
                            static_cast<float>(c & 1 ? hi.x() : lo.x()), static_cast<float>(c & 2 ? hi.y() : lo.y()),
                            static_cast<float>(c & 4 ? hi.z() : lo.z())));
                    }
                    block_hidden[blockOf(lo.x(), lo.y(), lo.z())] = std::all_of(
                        views.begin(), views.end(), [&](const DepthView& v) { return v.hiddenBox(corners, h); });
                }
            }
        }
    });
    parallelFor(0, dims.z(), [&](int z_lo, int z_hi) {
        // The view that found the last voxel free is asked first: its neighbour is most often free in it too.
        size_t last_free = 0;
        auto anyFree = [&](const Eigen::Vector3f& p) {
            if (views[last_free].freeAt(p, h)) return true;
            for (size_t i = 0; i < views.size(); ++i) {
                if (i != last_free && views[i].freeAt(p, h)) {
                    last_free = i;
                    return true;
                }
            }
            return false;
        };
        for (int z = z_lo; z < z_hi; ++z) {
            for (int y = 0; y < dims.y(); ++y) {
                for (int x = 0; x < dims.x(); ++x) {
                    Voxel* out = voxelAt(solid, x, y, z);
                    const Eigen::Vector3f p = solid.toWorld(
                        Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)));
                    out->weight = 1.0f;
                    out->b = static_cast<uint8_t>(fill[0]), out->g = static_cast<uint8_t>(fill[1]),
                    out->r = static_cast<uint8_t>(fill[2]);
                    if (x == 0 || y == 0 || z == 0 || x == dims.x() - 1 || y == dims.y() - 1 || z == dims.z() - 1) {
                        out->tsdf = 1.0f;  // the lattice's border: outside, so that the field is closed
                        continue;
                    }
                    float value = 0;
                    const Voxel* in = observed.voxel(x + offset.x(), y + offset.y(), z + offset.z());
                    if (in && in->weight > 0) {
                        value = in->tsdf;
                        out->b = in->b, out->g = in->g, out->r = in->r;
                    } else {
                        const bool free = !behind[at(x, y, z)] && !block_hidden[blockOf(x, y, z)] && anyFree(p);
                        value = free ? 1.0f : -1.0f;
                    }
                    // The cuts (chin plane, head sphere, crop box) as the intersection of two solids: the larger
                    // of the two signed distances, so that a cut lies on its plane, not a voxel beyond it.
                    value = std::min(std::max(value, cutDistance(p) / trunc_m), 1.0f);
                    out->tsdf = std::abs(value) < kNudge ? (value < 0 ? -kNudge : kNudge) : value;
                }
            }
        }
    });

    MeshParams mp;
    mp.min_fragment_share = 1.0f;  // the largest piece alone
    // No crossing within 4% of a voxel (0.06 mm) of a corner: what the wire's grid (0.05 mm) moves a vertex can
    // then never merge two vertices. Only crossings that near a corner move, by at most that much.
    mp.min_crossing = 0.04f;
    // Where the surface pinches, the solid is made thicker (the cubes around the pinch inside) and meshed again;
    // a pinch is rare (a few on a head), and this moves the surface there by at most a voxel.
    constexpr int kRepairRounds = 4;
    IndexedMesh closed;
    report.cpu_ms.close_field += finishCpuNowMs() - c0;
    c0 = finishCpuNowMs();
    // A round of thickening changes the voxels around a few pinches: the mesher meshes again only the blocks
    // whose voxels changed (and their neighbours), the same mesh as extractTriangles. It keeps the grid it was
    // given, hence a copy.
    IncrementalMesher mesher(mp);
    for (int round = 0;; ++round) {
        VoxelBlockGrid meshed = solid;
        closed = mesher.update(meshed);
        if (round == 0) {
            const double c1 = finishCpuNowMs();
            report.cpu_ms.close_march = c1 - c0;
            c0 = c1;
        }
        const std::vector<Eigen::Vector3f> spots = pinches(closed);
        if (spots.empty() || round == kRepairRounds) break;
        for (const Eigen::Vector3f& spot : spots) {
            const Eigen::Vector3f pv = solid.toVoxel(spot);
            for (int c = 0; c < 8; ++c) {
                const int x = static_cast<int>(pv.x()) + (c & 1), y = static_cast<int>(pv.y()) + ((c >> 1) & 1),
                          z = static_cast<int>(pv.z()) + (c >> 2);
                if (x <= 0 || y <= 0 || z <= 0 || x >= dims.x() - 1 || y >= dims.y() - 1 || z >= dims.z() - 1) continue;
                Voxel* v = voxelAt(solid, x, y, z);
                v->tsdf = -std::max(std::abs(v->tsdf), kNudge);
            }
        }
        ++report.pinches_repaired;
    }
    report.cpu_ms.close_thicken = finishCpuNowMs() - c0;
    c0 = finishCpuNowMs();
    removeDefects(closed);
    const MeshDefects defects = countDefects(closed);
    report.cpu_ms.close_check = finishCpuNowMs() - c0;
    if (closed.triangles.empty() || defects.boundary_edges > 0 || defects.non_manifold_edges > 0 ||
        defects.non_manifold_vertices > 0) {
        report.notes.push_back("watertight: the closed model came out with " + std::to_string(defects.boundary_edges) +
                               " open and " +
                               std::to_string(defects.non_manifold_edges + defects.non_manifold_vertices) +
                               " non-manifold edges or vertices: delivered the open mesh");
        return false;
    }
    report.triangles_added =
        closed.triangleCount() > mesh.triangleCount() ? closed.triangleCount() - mesh.triangleCount() : 0;
    report.watertight = true;
    report.views_used = views.size();
    mesh = std::move(closed);
    return true;
}

}  // namespace facescan::recon
