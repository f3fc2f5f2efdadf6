#include "recon/marching_cubes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numeric>
#include <unordered_map>
#include <vector>

namespace facescan::recon {
namespace {

// The 12 cube edges: edge a*4 + j joins corner kEdgeCorner[e][0] to [1] along axis a. Corner c = x + 2y + 4z.
struct EdgeTable {
    std::array<std::array<int, 2>, 12> corners{};
    std::array<int, 12> axis{};
    // Per configuration (bit c set = corner c inside, D < 0): triangles as edge triples, -1 terminated.
    std::array<std::array<int8_t, 37>, 256> tris{};
};

Eigen::Vector3f cornerPos(int c) { return Eigen::Vector3f(c & 1, (c >> 1) & 1, (c >> 2) & 1); }

// Builds the triangle table instead of copying Lorensen's: on every cube face the crossing points are joined
// into segments (an ambiguous face always cuts its inside corners off separately, so the two cubes sharing the
// face agree and the surface has no cracks), oriented so that the inside is on a fixed side; the segments chain
// into closed loops, and each loop is fanned into triangles whose normals point to the outside (D > 0).
EdgeTable buildTable() {
    EdgeTable t;
    for (int a = 0; a < 3; ++a) {
        int j = 0;
        for (int c = 0; c < 8; ++c) {
            if (c & (1 << a)) continue;
            t.corners[a * 4 + j] = {c, c | (1 << a)};
            t.axis[a * 4 + j] = a;
            ++j;
        }
    }
    auto edgeOf = [&](int c0, int c1) {
        for (int e = 0; e < 12; ++e) {
            if ((t.corners[e][0] == c0 && t.corners[e][1] == c1) || (t.corners[e][0] == c1 && t.corners[e][1] == c0))
                return e;
        }
        return -1;
    };
    auto mid = [&](int e) -> Eigen::Vector3f {
        return 0.5f * (cornerPos(t.corners[e][0]) + cornerPos(t.corners[e][1]));
    };
    for (int config = 0; config < 256; ++config) {
        std::array<int, 12> next;
        next.fill(-1);
        auto inside = [&](int c) { return (config >> c) & 1; };
        // Adds segment e1-e2 oriented so that ((B - A) x (C - A)) . N < 0 for the inside corner C.
        auto addSegment = [&](int e1, int e2, int c_in, const Eigen::Vector3f& n_out) {
            const Eigen::Vector3f a = mid(e1), b = mid(e2), c = cornerPos(c_in);
            if ((b - a).cross(c - a).dot(n_out) < 0.0f) {
                next[e1] = e2;
            } else {
                next[e2] = e1;
            }
        };
        for (int a = 0; a < 3; ++a) {
            const int b_axis = (a + 1) % 3, c_axis = (a + 2) % 3;
            for (int side = 0; side < 2; ++side) {
                Eigen::Vector3f n_out = Eigen::Vector3f::Zero();
                n_out[a] = side ? 1.0f : -1.0f;
                std::array<int, 4> q;  // the face's corners in cyclic order
                const int base = side << a;
                q[0] = base;
                q[1] = base | (1 << b_axis);
                q[2] = base | (1 << b_axis) | (1 << c_axis);
                q[3] = base | (1 << c_axis);
                int n_in = 0;
                for (int i = 0; i < 4; ++i) n_in += inside(q[i]);
                if (n_in == 0 || n_in == 4) continue;
                const bool ambiguous = n_in == 2 && inside(q[0]) == inside(q[2]);
                if (ambiguous) {
                    for (int i = 0; i < 4; ++i) {
                        if (!inside(q[i])) continue;
                        addSegment(edgeOf(q[(i + 3) % 4], q[i]), edgeOf(q[i], q[(i + 1) % 4]), q[i], n_out);
                    }
                    continue;
                }
                int crossing[2], k = 0, c_in = -1;
                for (int i = 0; i < 4; ++i) {
                    if (inside(q[i])) c_in = q[i];
                    if (inside(q[i]) != inside(q[(i + 1) % 4])) crossing[k++] = edgeOf(q[i], q[(i + 1) % 4]);
                }
                addSegment(crossing[0], crossing[1], c_in, n_out);
            }
        }
        std::array<bool, 12> used{};
        int out = 0;
        for (int start = 0; start < 12; ++start) {
            if (next[start] < 0 || used[start]) continue;
            std::array<int, 12> loop;
            int len = 0;
            for (int e = start; !used[e]; e = next[e]) {
                used[e] = true;
                loop[len++] = e;
            }
            for (int i = 1; i + 1 < len; ++i) {
                t.tris[config][out++] = static_cast<int8_t>(loop[0]);
                t.tris[config][out++] = static_cast<int8_t>(loop[i]);
                t.tris[config][out++] = static_cast<int8_t>(loop[i + 1]);
            }
        }
        t.tris[config][out] = -1;
    }
    return t;
}

const EdgeTable& table() {
    static const EdgeTable t = buildTable();
    return t;
}

int findRoot(std::vector<int>& parent, int i) {
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

}  // namespace

Status MeshParams::validate() const {
    if (stride_vox < 1 || stride_vox > 8) return invalidArgument("mesh stride_vox must be in [1, 8]");
    if (!(min_weight >= 0.0f)) return invalidArgument("mesh min_weight must be >= 0");
    if (!(min_crossing >= 0.0f && min_crossing < 0.25f))
        return invalidArgument("mesh min_crossing must be in [0, 0.25)");
    if (!(min_fragment_share >= 0.0f && min_fragment_share <= 1.0f))
        return invalidArgument("mesh min_fragment_share must be in [0, 1]");
    return Status::ok();
}

namespace {

void meshBlock(const VoxelBlockGrid& grid, int block, const MeshParams& p, BlockMesh& out) {
    out.clear();
    const EdgeTable& tab = table();
    const int stride = p.stride_vox;
    const int64_t n = grid.resolution_vox;
    const Eigen::Vector3i base = grid.block_coords[block] * kBlockSide;
    // Vertices are shared within the block through this map (key -> local index); small, so a sorted probe of
    // the few edges of one cube would not beat it.
    std::unordered_map<int64_t, uint32_t>& local = out.scratch;
    for (int iz = 0; iz < kBlockSide; ++iz) {
        for (int iy = 0; iy < kBlockSide; ++iy) {
            for (int ix = 0; ix < kBlockSide; ++ix) {
                const int x = base.x() + ix, y = base.y() + iy, z = base.z() + iz;
                if (x % stride || y % stride || z % stride) continue;
                float val[8];
                int config = 0;
                bool ok = true;
                for (int c = 0; c < 8 && ok; ++c) {
                    const Voxel* vx =
                        grid.voxel(x + (c & 1) * stride, y + ((c >> 1) & 1) * stride, z + (c >> 2) * stride);
                    ok = vx != nullptr && vx->weight > p.min_weight;
                    if (!ok) break;
                    val[c] = vx->tsdf;
                    if (val[c] < 0.0f) config |= 1 << c;
                }
                if (!ok || config == 0 || config == 255) continue;
                uint32_t vid[12];
                for (const int8_t* e = tab.tris[config].data(); *e >= 0; ++e) {
                    const int edge = *e;
                    const int c0 = tab.corners[edge][0], c1 = tab.corners[edge][1];
                    const int x0 = x + (c0 & 1) * stride, y0 = y + ((c0 >> 1) & 1) * stride,
                              z0 = z + (c0 >> 2) * stride;
                    const int64_t key = ((static_cast<int64_t>(z0) * n + y0) * n + x0) * 3 + tab.axis[edge];
                    auto [it, inserted] = local.try_emplace(key, static_cast<uint32_t>(out.keys.size()));
                    if (inserted) {
                        // The zero crossing along the edge, linear in D (the marching cubes refinement).
                        const float tt =
                            std::clamp(val[c0] / (val[c0] - val[c1]), p.min_crossing, 1.0f - p.min_crossing);
                        Eigen::Vector3f pv(static_cast<float>(x0), static_cast<float>(y0), static_cast<float>(z0));
                        pv[tab.axis[edge]] += tt * static_cast<float>(stride);
                        out.keys.push_back(key);
                        out.positions_vox.push_back(pv);
                        Eigen::Vector3f bgr(200.0f, 200.0f, 200.0f);
                        if (p.colours) grid.interpolateColour(pv, bgr);
                        out.colours_rgb.push_back({static_cast<uint8_t>(std::clamp(bgr[2], 0.0f, 255.0f)),
                                                   static_cast<uint8_t>(std::clamp(bgr[1], 0.0f, 255.0f)),
                                                   static_cast<uint8_t>(std::clamp(bgr[0], 0.0f, 255.0f))});
                    }
                    vid[edge] = it->second;
                }
                for (const int8_t* e = tab.tris[config].data(); *e >= 0; e += 3) {
                    const Triangle tri = {vid[e[0]], vid[e[1]], vid[e[2]]};
                    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) continue;
                    out.triangles.push_back(tri);
                }
            }
        }
    }
    local.clear();
}

IndexedMesh assembleBlocks(const VoxelBlockGrid& grid, const std::vector<const BlockMesh*>& blocks,
                           const MeshParams& p) {
    IndexedMesh mesh;
    size_t key_count = 0, tri_count = 0;
    for (const BlockMesh* b : blocks) key_count += b->keys.size(), tri_count += b->triangles.size();
    if (tri_count == 0) return mesh;
    // Blocks emit the vertices on their shared faces each: weld them by edge key.
    std::unordered_map<int64_t, uint32_t> global;
    global.reserve(key_count);
    std::vector<Eigen::Vector3f> positions_vox;
    std::vector<Rgb8> colours;
    positions_vox.reserve(key_count);
    colours.reserve(key_count);
    std::vector<Triangle> triangles;
    triangles.reserve(tri_count);
    std::vector<uint32_t> to_global;
    for (const BlockMesh* b : blocks) {
        to_global.resize(b->keys.size());
        for (size_t i = 0; i < b->keys.size(); ++i) {
            auto [it, inserted] = global.try_emplace(b->keys[i], static_cast<uint32_t>(positions_vox.size()));
            if (inserted) positions_vox.push_back(b->positions_vox[i]), colours.push_back(b->colours_rgb[i]);
            to_global[i] = it->second;
        }
        for (const Triangle& t : b->triangles) triangles.push_back({to_global[t[0]], to_global[t[1]], to_global[t[2]]});
    }

    // Connected pieces by union-find over shared vertices; drop the ones far smaller than the largest.
    std::vector<int> parent(positions_vox.size());
    std::iota(parent.begin(), parent.end(), 0);
    for (const auto& t : triangles) {
        const int r0 = findRoot(parent, static_cast<int>(t[0]));
        parent[findRoot(parent, static_cast<int>(t[1]))] = r0;
        parent[findRoot(parent, static_cast<int>(t[2]))] = r0;
    }
    std::vector<int> piece_tris(positions_vox.size(), 0);
    for (const auto& t : triangles) ++piece_tris[findRoot(parent, static_cast<int>(t[0]))];
    const int largest = *std::max_element(piece_tris.begin(), piece_tris.end());
    const float keep_min = p.min_fragment_share * static_cast<float>(largest);

    constexpr uint32_t kNone = ~0u;
    std::vector<uint32_t> out_index(positions_vox.size(), kNone);
    mesh.positions_m.reserve(positions_vox.size());
    mesh.colours_rgb.reserve(positions_vox.size());
    mesh.triangles.reserve(triangles.size());
    for (const auto& t : triangles) {
        if (static_cast<float>(piece_tris[findRoot(parent, static_cast<int>(t[0]))]) < keep_min) continue;
        Triangle out;
        for (int i = 0; i < 3; ++i) {
            if (out_index[t[i]] == kNone) {
                out_index[t[i]] = static_cast<uint32_t>(mesh.positions_m.size());
                mesh.positions_m.push_back(grid.toWorld(positions_vox[t[i]]));
                mesh.colours_rgb.push_back(colours[t[i]]);
            }
            out[i] = out_index[t[i]];
        }
        mesh.triangles.push_back(out);
    }
    if (p.gradient_normals) {
        // Normals from the gradient of D (thesis eq. 4.30); where it is unavailable (the rim of the observed
        // region), the area-weighted face normal.
        const std::vector<Eigen::Vector3f> from_faces = vertexNormals(mesh);
        mesh.normals.resize(mesh.positions_m.size());
        for (size_t i = 0; i < positions_vox.size(); ++i) {
            if (out_index[i] == kNone) continue;
            Eigen::Vector3f g;
            const bool ok = grid.gradient(positions_vox[i], g) && g.norm() > 0.0f;
            mesh.normals[out_index[i]] = ok ? g.normalized() : from_faces[out_index[i]];
        }
    }
    if (!p.colours) mesh.colours_rgb.clear();
    return mesh;
}

}  // namespace

void BlockMesh::clear() {
    keys.clear();
    positions_vox.clear();
    colours_rgb.clear();
    triangles.clear();
}

IndexedMesh extractTriangles(const VoxelBlockGrid& grid, const MeshParams& p) {
    if (grid.allocated_blocks == 0 || !p.validate().isOk()) return {};
    std::vector<BlockMesh> blocks(static_cast<size_t>(grid.allocated_blocks));
    std::vector<const BlockMesh*> views;
    views.reserve(blocks.size());
    for (int b = 0; b < grid.allocated_blocks; ++b) {
        meshBlock(grid, b, p, blocks[static_cast<size_t>(b)]);
        views.push_back(&blocks[static_cast<size_t>(b)]);
    }
    return assembleBlocks(grid, views, p);
}

Mesh extractMesh(const VoxelBlockGrid& grid, const MeshParams& p) {
    MeshParams with_normals = p;
    with_normals.gradient_normals = true;
    return toOpenMesh(extractTriangles(grid, with_normals));
}

}  // namespace facescan::recon

namespace facescan::recon {

void IncrementalMesher::reset() {
    previous_ = VoxelBlockGrid();
    cache_.clear();
}

IndexedMesh IncrementalMesher::update(VoxelBlockGrid& grid) {
    stats_ = Stats{grid.allocated_blocks, 0, 0};
    if (grid.allocated_blocks == 0 || !params_.validate().isOk()) {
        reset();
        return {};
    }
    // Blocks keep their pool index for the volume's life; a reset or a re-placed cube breaks that.
    const bool same_volume =
        previous_.resolution_vox == grid.resolution_vox && previous_.origin_world == grid.origin_world &&
        previous_.voxel_size_m == grid.voxel_size_m && previous_.allocated_blocks <= grid.allocated_blocks &&
        std::equal(previous_.block_coords.begin(), previous_.block_coords.begin() + previous_.allocated_blocks,
                   grid.block_coords.begin());
    if (!same_volume) cache_.clear();
    const int old_blocks = same_volume ? previous_.allocated_blocks : 0;
    cache_.resize(static_cast<size_t>(grid.allocated_blocks));

    std::vector<char> stale(static_cast<size_t>(grid.allocated_blocks), 0);
    constexpr size_t kBlockBytes = sizeof(Voxel) * kBlockVoxels;
    const int bps = grid.blocks_per_side;
    for (int b = 0; b < grid.allocated_blocks; ++b) {
        const size_t offset = static_cast<size_t>(b) * kBlockVoxels;
        if (b < old_blocks && std::memcmp(&grid.voxels[offset], &previous_.voxels[offset], kBlockBytes) == 0) continue;
        ++stats_.blocks_changed;
        // The block and the 7 blocks whose cubes read its voxels (its -x/-y/-z neighbours).
        const Eigen::Vector3i c = grid.block_coords[b];
        for (int d = 0; d < 8; ++d) {
            const Eigen::Vector3i nb = c - Eigen::Vector3i(d & 1, (d >> 1) & 1, d >> 2);
            if (nb.minCoeff() < 0) continue;
            const int i = grid.block_index[(static_cast<size_t>(nb.z()) * bps + nb.y()) * bps + nb.x()];
            if (i >= 0) stale[static_cast<size_t>(i)] = 1;
        }
    }
    std::vector<const BlockMesh*> views;
    views.reserve(cache_.size());
    for (int b = 0; b < grid.allocated_blocks; ++b) {
        if (stale[static_cast<size_t>(b)])
            meshBlock(grid, b, params_, cache_[static_cast<size_t>(b)]), ++stats_.blocks_remeshed;
        views.push_back(&cache_[static_cast<size_t>(b)]);
    }
    IndexedMesh mesh = assembleBlocks(grid, views, params_);
    std::swap(previous_, grid);
    return mesh;
}

}  // namespace facescan::recon
