#include "recon/indexed_mesh.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cstring>
#include <numeric>

namespace facescan::recon {
namespace {

// Exact position as a hash key (-0 folded into +0 so that equal positions give equal keys).
struct PosKey {
    uint32_t bits[3];
    bool operator==(const PosKey& o) const { return std::memcmp(bits, o.bits, sizeof bits) == 0; }
};
struct PosKeyHash {
    size_t operator()(const PosKey& k) const {
        uint64_t h = 0x9e3779b97f4a7c15ull;
        for (const uint32_t b : k.bits) h = (h ^ b) * 0xff51afd7ed558ccdull;
        return static_cast<size_t>(h ^ (h >> 29));
    }
};
PosKey keyOf(const Eigen::Vector3f& p) {
    PosKey k;
    for (int i = 0; i < 3; ++i) {
        const float v = p[i] + 0.0f;
        std::memcpy(&k.bits[i], &v, sizeof v);
    }
    return k;
}

// A flat open-addressing table (linear probing) of indices: the meshes here have ~100k elements, and
// std::unordered_map's node per element made cleaning cost half of the Draco encode (12.8 of 26 ms).
class IndexTable {
 public:
    explicit IndexTable(size_t count) {
        size_t n = 16;
        while (n < 2 * count) n <<= 1;
        slots_.assign(n, 0);
    }
    // The index already stored that `same` accepts, else `candidate` (stored now).
    template <class Same>
    uint32_t findOrInsert(uint32_t candidate, size_t hash, Same same) {
        const size_t mask = slots_.size() - 1;
        for (size_t i = hash & mask;; i = (i + 1) & mask) {
            if (slots_[i] == 0) {
                slots_[i] = candidate + 1;
                return candidate;
            }
            if (same(slots_[i] - 1)) return slots_[i] - 1;
        }
    }

 private:
    std::vector<uint32_t> slots_;  // index + 1; 0 = empty
};

// canonical[i] = the first vertex with vertex i's position.
std::vector<uint32_t> canonicalByPosition(const IndexedMesh& mesh) {
    std::vector<uint32_t> canonical(mesh.vertexCount());
    std::vector<PosKey> keys(mesh.vertexCount());
    IndexTable table(mesh.vertexCount());
    for (uint32_t i = 0; i < mesh.vertexCount(); ++i) {
        keys[i] = keyOf(mesh.positions_m[i]);
        canonical[i] = table.findOrInsert(i, PosKeyHash()(keys[i]), [&](uint32_t j) { return keys[j] == keys[i]; });
    }
    return canonical;
}

double twiceArea(const IndexedMesh& mesh, const Triangle& t) {
    const Eigen::Vector3d a = mesh.positions_m[t[0]].cast<double>();
    const Eigen::Vector3d b = mesh.positions_m[t[1]].cast<double>();
    const Eigen::Vector3d c = mesh.positions_m[t[2]].cast<double>();
    return (b - a).cross(c - a).norm();
}

bool zeroArea(const IndexedMesh& mesh, const Triangle& t) {
    return t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || 0.5 * twiceArea(mesh, t) <= kZeroAreaM2;
}

uint64_t edgeKey(uint32_t a, uint32_t b) { return a < b ? (uint64_t(a) << 32 | b) : (uint64_t(b) << 32 | a); }

struct TriKeyHash {
    size_t operator()(const Triangle& t) const {
        return std::hash<uint64_t>()((uint64_t(t[0]) * 0x9e3779b97f4a7c15ull) ^ (uint64_t(t[1]) << 21) ^
                                     (uint64_t(t[2]) * 0xff51afd7ed558ccdull));
    }
};
// Marks each triangle whose vertex set (any order) an earlier one has: keeps[t] = false for those.
class TriangleSet {
 public:
    explicit TriangleSet(size_t count) : table_(count) { sorted_.reserve(count); }
    // True when `t` is new (and remembers it).
    bool insert(const Triangle& t) {
        Triangle k = t;
        std::sort(k.begin(), k.end());
        const uint32_t candidate = static_cast<uint32_t>(sorted_.size());
        sorted_.push_back(k);
        const uint32_t found =
            table_.findOrInsert(candidate, TriKeyHash()(k), [&](uint32_t j) { return sorted_[j] == k; });
        if (found != candidate) sorted_.pop_back();
        return found == candidate;
    }

 private:
    IndexTable table_;
    std::vector<Triangle> sorted_;
};

int findRoot(std::vector<uint32_t>& parent, uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return static_cast<int>(i);
}

}  // namespace

void IndexedMesh::clear() {
    positions_m.clear();
    normals.clear();
    colours_rgb.clear();
    triangles.clear();
}

std::vector<Eigen::Vector3f> vertexNormals(const IndexedMesh& mesh) {
    std::vector<Eigen::Vector3f> normals(mesh.vertexCount(), Eigen::Vector3f::Zero());
    for (const Triangle& t : mesh.triangles) {
        const Eigen::Vector3f& a = mesh.positions_m[t[0]];
        const Eigen::Vector3f n = (mesh.positions_m[t[1]] - a).cross(mesh.positions_m[t[2]] - a);
        for (const uint32_t v : t) normals[v] += n;
    }
    for (Eigen::Vector3f& n : normals) {
        const float len = n.norm();
        if (len > 0.0f) n /= len;
    }
    return normals;
}

MeshDefects countDefects(const IndexedMesh& mesh) {
    MeshDefects d;
    const std::vector<uint32_t> canonical = canonicalByPosition(mesh);
    std::vector<char> used(mesh.vertexCount(), 0);
    TriangleSet seen(mesh.triangleCount());
    // The good triangles' edges as keys, sorted: a run of equal keys is one edge and its triangles (a sort of a
    // flat array, not a hash map: a watertight head's check holds 400,000 edges).
    std::vector<uint64_t> edge_keys;
    edge_keys.reserve(mesh.triangleCount() * 3);
    std::vector<Triangle> good;  // canonical, non-degenerate, first copies
    good.reserve(mesh.triangleCount());
    for (const Triangle& t : mesh.triangles) {
        for (const uint32_t v : t) used[v] = 1;
        const Triangle c = {canonical[t[0]], canonical[t[1]], canonical[t[2]]};
        if (zeroArea(mesh, c)) {
            ++d.zero_area_triangles;
            continue;
        }
        if (!seen.insert(c)) {
            ++d.duplicate_triangles;
            continue;
        }
        good.push_back(c);
        for (int i = 0; i < 3; ++i) edge_keys.push_back(edgeKey(c[i], c[(i + 1) % 3]));
    }
    d.unreferenced_vertices = static_cast<size_t>(std::count(used.begin(), used.end(), 0));
    std::sort(edge_keys.begin(), edge_keys.end());
    for (size_t i = 0; i < edge_keys.size();) {
        size_t j = i + 1;
        while (j < edge_keys.size() && edge_keys[j] == edge_keys[i]) ++j;
        if (j - i > 2) ++d.non_manifold_edges;
        if (j - i == 1) ++d.boundary_edges;
        i = j;
    }
    // Fans: around each vertex, its triangles joined through the edges they share there (vertex -> other end).
    std::vector<uint32_t> first(mesh.vertexCount() + 1, 0);
    for (const Triangle& t : good) {
        for (const uint32_t v : t) ++first[v + 1];
    }
    std::partial_sum(first.begin(), first.end(), first.begin());
    std::vector<uint32_t> fill(first.begin(), first.end() - 1);
    std::vector<uint32_t> incident(good.size() * 3);
    for (uint32_t f = 0; f < good.size(); ++f) {
        for (const uint32_t v : good[f]) incident[fill[v]++] = f;
    }
    std::vector<uint32_t> parent;
    // (other end, triangle of the fan) sorted by the other end: the triangles of a run share the edge v-other.
    std::vector<std::pair<uint32_t, uint32_t>> by_other;
    for (uint32_t v = 0; v < mesh.vertexCount(); ++v) {
        const uint32_t k = first[v + 1] - first[v];
        if (k < 2) continue;
        parent.resize(k);
        std::iota(parent.begin(), parent.end(), 0u);
        by_other.clear();
        for (uint32_t i = 0; i < k; ++i) {
            for (const uint32_t o : good[incident[first[v] + i]]) {
                if (o != v) by_other.emplace_back(o, i);
            }
        }
        std::sort(by_other.begin(), by_other.end());
        uint32_t pieces = k;
        for (size_t i = 1; i < by_other.size(); ++i) {
            if (by_other[i].first != by_other[i - 1].first) continue;
            const int ra = findRoot(parent, by_other[i - 1].second), rb = findRoot(parent, by_other[i].second);
            if (ra != rb) parent[rb] = static_cast<uint32_t>(ra), --pieces;
        }
        if (pieces > 1) ++d.non_manifold_vertices;
    }
    return d;
}

void removeDefects(IndexedMesh& mesh) {
    const std::vector<uint32_t> canonical = canonicalByPosition(mesh);
    TriangleSet seen(mesh.triangleCount());
    size_t kept = 0;
    for (const Triangle& t : mesh.triangles) {
        const Triangle c = {canonical[t[0]], canonical[t[1]], canonical[t[2]]};
        if (zeroArea(mesh, c) || !seen.insert(c)) continue;
        mesh.triangles[kept++] = c;
    }
    mesh.triangles.resize(kept);
    constexpr uint32_t kUnused = ~0u;
    std::vector<uint32_t> new_index(mesh.vertexCount(), kUnused);
    uint32_t next = 0;
    for (Triangle& t : mesh.triangles) {
        for (uint32_t& v : t) {
            if (new_index[v] == kUnused) new_index[v] = next++;
            v = new_index[v];
        }
    }
    auto compact = [&](auto& values) {
        if (values.size() != new_index.size()) return;
        std::remove_reference_t<decltype(values)> out(next);
        for (size_t i = 0; i < new_index.size(); ++i) {
            if (new_index[i] != kUnused) out[new_index[i]] = values[i];
        }
        values.swap(out);
    };
    compact(mesh.positions_m);
    compact(mesh.normals);
    compact(mesh.colours_rgb);
}

Mesh toOpenMesh(const IndexedMesh& in) {
    Mesh out;
    out.reserve(in.vertexCount(), in.triangleCount() * 3 / 2 + 3, in.triangleCount());
    const bool colours = in.hasColours();
    auto addVertex = [&](uint32_t i) {
        const Eigen::Vector3f& p = in.positions_m[i];
        const Mesh::VertexHandle vh = out.add_vertex(Mesh::Point(p.x(), p.y(), p.z()));
        if (colours) out.set_color(vh, Mesh::Color(in.colours_rgb[i][0], in.colours_rgb[i][1], in.colours_rgb[i][2]));
        return vh;
    };
    std::vector<Mesh::VertexHandle> handle(in.vertexCount());
    for (uint32_t i = 0; i < in.vertexCount(); ++i) handle[i] = addVertex(i);
    std::vector<uint32_t> source(in.vertexCount());  // the input vertex of each output vertex (for the normals)
    std::iota(source.begin(), source.end(), 0u);
    for (const Triangle& t : in.triangles) {
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
        if (out.add_face(handle[t[0]], handle[t[1]], handle[t[2]]).is_valid()) continue;
        Mesh::VertexHandle copy[3];
        for (int k = 0; k < 3; ++k) copy[k] = addVertex(t[k]), source.push_back(t[k]);
        out.add_face(copy[0], copy[1], copy[2]);
    }
    out.update_face_normals();
    if (in.hasNormals()) {
        for (const auto vh : out.vertices()) {
            const Eigen::Vector3f& n = in.normals[source[static_cast<size_t>(vh.idx())]];
            out.set_normal(vh, Mesh::Normal(n.x(), n.y(), n.z()));
        }
    } else {
        out.update_vertex_normals();
    }
    return out;
}

IndexedMesh fromOpenMesh(const Mesh& mesh) {
    IndexedMesh out;
    std::vector<uint32_t> index_of(mesh.n_vertices(), 0);
    out.positions_m.reserve(mesh.n_vertices());
    const bool normals = mesh.has_vertex_normals();
    const bool colours = mesh.has_vertex_colors();
    for (const auto vh : mesh.vertices()) {
        index_of[static_cast<size_t>(vh.idx())] = static_cast<uint32_t>(out.positions_m.size());
        const auto& p = mesh.point(vh);
        out.positions_m.emplace_back(p[0], p[1], p[2]);
        if (normals) {
            const auto& n = mesh.normal(vh);
            out.normals.emplace_back(n[0], n[1], n[2]);
        }
        if (colours) {
            const auto& c = mesh.color(vh);
            out.colours_rgb.push_back({c[0], c[1], c[2]});
        }
    }
    out.triangles.reserve(mesh.n_faces());
    std::vector<uint32_t> ring;
    for (const auto fh : mesh.faces()) {
        ring.clear();
        for (const auto vh : mesh.fv_range(fh)) ring.push_back(index_of[static_cast<size_t>(vh.idx())]);
        for (size_t i = 1; i + 1 < ring.size(); ++i) out.triangles.push_back({ring[0], ring[i], ring[i + 1]});
    }
    return out;
}

}  // namespace facescan::recon
