// Watertight closing (recon/finishing.hpp, ClosingMode::kWatertight) on a synthetic scan of the built-in head: the
// result is a closed manifold in one piece without self-intersections, and the seen surface stays where it was;
// from the volume (the server's finish) and from the mesh alone (`facescan mesh`); and a patch too small to be a
// head is said to be so and left open.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numeric>
#include <set>

#include "recon/finishing.hpp"
#include "recon/marching_cubes.hpp"
#include "recon/reconstructor.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::recon {
namespace {

struct Topology {
    size_t boundary_edges = 0, non_manifold_edges = 0, components = 0;
    long euler = 0;  // V - E + F
};

Topology topology(const IndexedMesh& m) {
    Topology t;
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    for (const Triangle& f : m.triangles) {
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = f[k], b = f[(k + 1) % 3];
            ++edges[{std::min(a, b), std::max(a, b)}];
        }
    }
    for (const auto& [e, n] : edges) {
        t.boundary_edges += n == 1;
        t.non_manifold_edges += n > 2;
    }
    std::vector<uint32_t> parent(m.vertexCount());
    std::iota(parent.begin(), parent.end(), 0u);
    auto root = [&parent](uint32_t i) {
        while (parent[i] != i) i = parent[i] = parent[parent[i]];
        return i;
    };
    for (const Triangle& f : m.triangles) parent[root(f[1])] = root(f[0]), parent[root(f[2])] = root(f[0]);
    for (uint32_t i = 0; i < parent.size(); ++i) t.components += root(i) == i;
    t.euler =
        static_cast<long>(m.vertexCount()) - static_cast<long>(edges.size()) + static_cast<long>(m.triangleCount());
    return t;
}

// Segment pq crosses triangle abc's interior (Moller-Trumbore; touching and coplanar cases do not count).
bool segmentCrossesTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d d = q - p, e1 = b - a, e2 = c - a;
    const Eigen::Vector3d s = d.cross(e2);
    const double det = e1.dot(s);
    if (std::abs(det) < 1e-18) return false;
    const Eigen::Vector3d r = p - a;
    const double u = r.dot(s) / det;
    const Eigen::Vector3d qv = r.cross(e1);
    const double v = d.dot(qv) / det, t = e2.dot(qv) / det;
    constexpr double eps = 1e-9;
    return u > eps && v > eps && u + v < 1 - eps && t > eps && t < 1 - eps;
}

// Pairs of triangles without a shared vertex whose edges cross the other's interior, found through a uniform grid
// of 4 mm cells over the triangles' bounding boxes.
size_t selfIntersections(const IndexedMesh& m) {
    constexpr double kCellM = 0.004;
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9);
    for (const auto& p : m.positions_m) lo = lo.cwiseMin(p.cast<double>());
    std::map<std::tuple<int, int, int>, std::vector<uint32_t>> cells;
    for (uint32_t f = 0; f < m.triangleCount(); ++f) {
        Eigen::Vector3d b0 = Eigen::Vector3d::Constant(1e9), b1 = -b0;
        for (int k = 0; k < 3; ++k) {
            b0 = b0.cwiseMin(m.positions_m[m.triangles[f][k]].cast<double>());
            b1 = b1.cwiseMax(m.positions_m[m.triangles[f][k]].cast<double>());
        }
        const Eigen::Vector3i c0 = ((b0 - lo) / kCellM).array().floor().cast<int>();
        const Eigen::Vector3i c1 = ((b1 - lo) / kCellM).array().floor().cast<int>();
        for (int z = c0.z(); z <= c1.z(); ++z)
            for (int y = c0.y(); y <= c1.y(); ++y)
                for (int x = c0.x(); x <= c1.x(); ++x) cells[{x, y, z}].push_back(f);
    }
    std::set<std::pair<uint32_t, uint32_t>> found;
    for (const auto& [key, list] : cells) {
        for (size_t i = 0; i < list.size(); ++i) {
            for (size_t j = i + 1; j < list.size(); ++j) {
                const Triangle &s = m.triangles[list[i]], &t = m.triangles[list[j]];
                bool shared = false;
                for (int a = 0; a < 3; ++a)
                    for (int b = 0; b < 3; ++b) shared |= s[a] == t[b];
                if (shared) continue;
                auto P = [&m](uint32_t v) { return m.positions_m[v].cast<double>().eval(); };
                bool cross = false;
                for (int k = 0; k < 3 && !cross; ++k) {
                    cross = segmentCrossesTriangle(P(s[k]), P(s[(k + 1) % 3]), P(t[0]), P(t[1]), P(t[2])) ||
                            segmentCrossesTriangle(P(t[k]), P(t[(k + 1) % 3]), P(s[0]), P(s[1]), P(s[2]));
                }
                if (cross) found.insert({std::min(list[i], list[j]), std::max(list[i], list[j])});
            }
        }
    }
    return found.size();
}

void expectSolid(const IndexedMesh& m, const char* what) {
    const Topology t = topology(m);
    const MeshDefects d = countDefects(m);
    std::printf("%s: %zu triangles, %zu components, Euler characteristic %ld\n", what, m.triangleCount(), t.components,
                t.euler);
    EXPECT_GT(m.triangleCount(), 10000u) << what;
    EXPECT_EQ(t.boundary_edges, 0u) << what;  // closed
    EXPECT_EQ(t.non_manifold_edges, 0u) << what;
    EXPECT_EQ(d.non_manifold_vertices, 0u) << what;
    EXPECT_TRUE(d.clean()) << what;
    EXPECT_EQ(t.components, 1u) << what;
    // A closed orientable surface: V - E + F = 2 - 2 genus (2 for a sphere-like head; a handle, an ear closed
    // into a ring, lowers it by 2).
    EXPECT_EQ(t.euler % 2, 0) << what;
    EXPECT_LE(t.euler, 2) << what;
    EXPECT_EQ(selfIntersections(m), 0u) << what;
}

class WatertightScan : public ::testing::Test {
 protected:
    static void SetUpTestSuite() {
        synth::SequenceParams sp;
        ASSERT_TRUE(synth::applyScenario("wide", sp).isOk());
        sp.frames = 60;
        const synth::KinectSimulator sim(synth::builtinHead(), sp);
        Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
        RgbdFrame frame;
        synth::FrameTruth truth;
        for (int i = 0; i < sp.frames; ++i) {
            sim.render(i, frame, &truth);
            rec.processFrame(frame, truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead));
        }
        ASSERT_TRUE(rec.headRegion().valid);
        grid_ = new TsdfSnapshot;
        rec.copyVolume(*grid_);
        region_ = new HeadRegion(rec.headRegion());
        open_ = new IndexedMesh(extractTriangles(*grid_, ReconParams::faceDefaults().mesh));
    }
    static void TearDownTestSuite() {
        delete grid_;
        delete region_;
        delete open_;
    }
    static TsdfSnapshot* grid_;
    static HeadRegion* region_;
    static IndexedMesh* open_;
};
TsdfSnapshot* WatertightScan::grid_ = nullptr;
HeadRegion* WatertightScan::region_ = nullptr;
IndexedMesh* WatertightScan::open_ = nullptr;

TEST_F(WatertightScan, FromTheVolumeIsASolidAndKeepsTheSeenSurface) {
    IndexedMesh m = *open_;
    FinishParams p;
    p.close = ClosingMode::kWatertight;
    auto report = finishMesh(m, p, region_, grid_);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    std::printf("volume: %s (%.0f ms closing)\n", report->summary().c_str(), report->ms_close);
    ASSERT_TRUE(report->watertight) << report->summary();
    expectSolid(m, "from the volume");
    // The distance from the open model's vertices (the head alone) to the solid: the seen surface stays.
    EXPECT_LT(report->distance.mean_mm, 0.01);
    for (const Eigen::Vector3f& v : m.positions_m) ASSERT_TRUE(region_->contains(v) || !region_->valid);
    // What the server sends and writes: the mesh cleaned on Draco's grid (aligned with the voxels), still a solid.
    wire::MeshCodecParams codec;
    codec.lattice_step_m = grid_->voxel_size_m;
    codec.lattice_origin_m = grid_->origin_world;
    std::vector<uint8_t> bytes;
    IndexedMesh encoded;
    ASSERT_TRUE(wire::encodeMeshDraco(m, codec, bytes, &encoded).isOk());
    const Topology t = topology(encoded);
    EXPECT_EQ(t.boundary_edges, 0u);
    EXPECT_EQ(t.non_manifold_edges, 0u);
    EXPECT_EQ(countDefects(encoded).non_manifold_vertices, 0u);
    EXPECT_EQ(t.components, 1u);
}

TEST_F(WatertightScan, FromTheMeshAloneIsASolid) {
    IndexedMesh m = *open_;
    FinishParams head_only;
    ASSERT_TRUE(finishMesh(m, head_only, region_).isOk());
    FinishParams p;
    p.close = ClosingMode::kWatertight;
    auto report = finishMesh(m, p);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    std::printf("mesh alone: %s (%.0f ms closing)\n", report->summary().c_str(), report->ms_close);
    ASSERT_TRUE(report->watertight) << report->summary();
    expectSolid(m, "from the mesh");
    // Re-meshed on a 1.5 mm lattice: the seen surface moves by a fraction of a voxel.
    EXPECT_LT(report->distance.mean_mm, 0.2);
}

// A crop box through the middle of the head: the solid is cut flat there too, and stays closed.
TEST_F(WatertightScan, ACropBoxCutsTheSolidFlat) {
    IndexedMesh m = *open_;
    Eigen::AlignedBox3f box;
    for (const Eigen::Vector3f& p : m.positions_m) box.extend(p);
    Eigen::AlignedBox3f crop = box;
    crop.max().z() = box.center().z();  // the front half (z away from the camera)
    FinishParams p;
    p.close = ClosingMode::kWatertight;
    p.crop_m = crop;
    auto report = finishMesh(m, p, region_, grid_);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    std::printf("cropped: %s\n", report->summary().c_str());
    ASSERT_TRUE(report->watertight) << report->summary();
    expectSolid(m, "cropped");
    size_t on_cut = 0;
    for (const Eigen::Vector3f& v : m.positions_m) {
        ASSERT_LE(v.z(), crop.max().z() + 1e-6f);
        on_cut += v.z() > crop.max().z() - grid_->voxel_size_m;
    }
    EXPECT_GT(on_cut, 100u) << "the cut is a flat face of the solid";
}

TEST(Watertight, TooLittleOfAHeadStaysOpenWithANote) {
    // A 4 x 4 cm bumpy patch: no head.
    IndexedMesh m;
    const int n = 41;
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            const float fx = static_cast<float>(x) * 1e-3f, fy = static_cast<float>(y) * 1e-3f;
            m.positions_m.emplace_back(fx, fy, 0.003f * std::sin(fx * 100.0f));
        }
    }
    for (uint32_t y = 0; y + 1 < n; ++y) {
        for (uint32_t x = 0; x + 1 < n; ++x) {
            m.triangles.push_back({y * n + x, y * n + x + 1, (y + 1) * n + x + 1});
            m.triangles.push_back({y * n + x, (y + 1) * n + x + 1, (y + 1) * n + x});
        }
    }
    const IndexedMesh before = m;
    FinishParams p;
    p.close = ClosingMode::kWatertight;
    auto report = finishMesh(m, p);
    ASSERT_TRUE(report.isOk());
    EXPECT_FALSE(report->watertight);
    EXPECT_EQ(m.triangleCount(), before.triangleCount());
    ASSERT_FALSE(report->notes.empty());
    EXPECT_NE(report->summary().find("too little"), std::string::npos) << report->summary();
    EXPECT_TRUE(parseClosingMode("watertight").isOk());
    EXPECT_STREQ(closingModeName(ClosingMode::kWatertight), "watertight");
}

}  // namespace
}  // namespace facescan::recon
