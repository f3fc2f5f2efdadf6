// Exact invariants of the reconstruction core on analytic scenes (a plane, a sphere), and bad input.
// Each scene is a tiny analytic depth image (ray-plane / ray-sphere intersection), not a renderer.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

#include "recon/depth_filter.hpp"
#include "recon/icp.hpp"
#include "recon/marching_cubes.hpp"
#include "recon/raycaster.hpp"
#include "recon/reconstructor.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {
namespace {

const Intrinsics kCam = Intrinsics::kinectV1();

// Depth of a sphere (centre c_world, radius r) seen from T_world_camera; 0 where the ray misses.
cv::Mat sphereDepth(const Pose& T_world_camera, const Eigen::Vector3f& c_world, float r) {
    cv::Mat depth(kCam.height_px, kCam.width_px, CV_32F, cv::Scalar(0));
    const Eigen::Vector3f c = T_world_camera.inverse() * c_world;
    for (int v = 0; v < depth.rows; ++v) {
        for (int u = 0; u < depth.cols; ++u) {
            const Eigen::Vector3f ray = kCam.ray(static_cast<float>(u), static_cast<float>(v));
            const float a = ray.squaredNorm(), b = ray.dot(c), disc = b * b - a * (c.squaredNorm() - r * r);
            if (disc > 0.0f) depth.at<float>(v, u) = (b - std::sqrt(disc)) / a;
        }
    }
    return depth;
}

// Camera on a sphere of radius `dist` around `target`, looking at it.
Pose lookAt(const Eigen::Vector3f& target, const Eigen::Vector3f& dir_from_target, float dist) {
    const Eigen::Vector3f z = -dir_from_target.normalized();
    Eigen::Vector3f up = std::fabs(z.y()) > 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
    const Eigen::Vector3f x = up.cross(z).normalized();
    const Eigen::Vector3f y = z.cross(x);
    Pose t = Pose::Identity();
    t.linear().col(0) = x;
    t.linear().col(1) = y;
    t.linear().col(2) = z;
    t.translation() = target - z * dist;
    return t;
}

TsdfParams smallVolume() {
    TsdfParams p;
    p.resolution_vox = 128;
    p.volume_size_m = 0.192f;  // 1.5 mm voxels
    p.centre_behind_surface_m = 0.0f;
    return p;
}

TEST(DepthFilter, InvalidStaysInvalidAndPlaneStaysPlane) {
    cv::Mat depth(kCam.height_px, kCam.width_px, CV_32F, cv::Scalar(0.8f));
    depth.at<float>(100, 100) = 0.0f;
    depth.at<float>(200, 200) = std::numeric_limits<float>::quiet_NaN();
    DepthFilter f(kCam, FilterParams{});
    SurfacePyramid pyr;
    pyr.allocate(kCam, 3);
    EXPECT_EQ(f.filter(depth, cv::Mat(), pyr), kCam.width_px * kCam.height_px - 2);
    EXPECT_EQ(pyr.levels[0].depth_m.at<float>(100, 100), 0.0f);
    EXPECT_EQ(pyr.levels[0].depth_m.at<float>(200, 200), 0.0f);
    EXPECT_FLOAT_EQ(pyr.levels[0].depth_m.at<float>(101, 100), 0.8f);  // eq. 4.4 of a constant is the constant
    const cv::Vec3f n = pyr.levels[0].normal.at<cv::Vec3f>(240, 320);
    EXPECT_NEAR(n[2], -1.0f, 1e-5f);  // eq. 4.10 of a fronto-parallel plane, facing the camera
    EXPECT_FLOAT_EQ(pyr.levels[2].depth_m.at<float>(60, 80), 0.8f);
}

// Every filtered pixel is eq. 4.4 over its window: Gaussian weights in pixel distance (eq. 4.5) and in depth
// difference (eq. 4.6, cut at 3 sigma as the filter documents), invalid neighbours left out, the window clipped to
// the head's box. Computed here in double with exact exponentials, on a noisy sphere with holes, so that both the
// filter's path for pixels whose window lies inside the box and its clipped path at the box's edges are checked.
TEST(DepthFilter, EveryPixelIsEquation4_4OverItsWindow) {
    const FilterParams params;
    cv::Mat depth = sphereDepth(Pose::Identity(), Eigen::Vector3f(0.02f, -0.01f, 0.75f), 0.09f);
    std::mt19937 rng(7);
    std::normal_distribution<float> noise(0.0f, 0.002f);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    for (int v = 0; v < depth.rows; ++v) {
        for (int u = 0; u < depth.cols; ++u) {
            float& z = depth.at<float>(v, u);
            if (z <= 0.0f) continue;
            z = unit(rng) < 0.1f ? 0.0f : z + noise(rng);    // dropouts and axial noise
            if (z > 0.0f && u > 330 && v > 250) z += 0.08f;  // a step within 3 sigma: the weights stay > 0
        }
    }
    DepthFilter f(kCam, params);
    SurfacePyramid pyr;
    pyr.allocate(kCam, 1);
    ASSERT_GT(f.filter(depth, cv::Mat(), pyr), 10000);
    const cv::Rect roi = pyr.levels[0].roi;
    const int r = params.radius_px;
    const double s2 = 2.0 * params.sigma_space_px * params.sigma_space_px;
    const double d2 = 2.0 * params.sigma_depth_m * params.sigma_depth_m;
    int checked = 0, interior = 0;
    double worst_m = 0.0;
    for (int v = roi.y; v < roi.y + roi.height; ++v) {
        for (int u = roi.x; u < roi.x + roi.width; ++u) {
            const double zc = depth.at<float>(v, u);
            const float out = pyr.levels[0].depth_m.at<float>(v, u);
            const cv::Vec3f vertex = pyr.levels[0].vertex.at<cv::Vec3f>(v, u);
            if (!(zc > 0.0)) {
                EXPECT_EQ(out, 0.0f) << u << "," << v;
                EXPECT_TRUE(std::isnan(vertex[0])) << u << "," << v;
                continue;
            }
            // Eq. 4.9 of the filtered depth: the vertex map comes out of the same pass, pixel by pixel.
            const Eigen::Vector3f p = kCam.backProject(static_cast<float>(u), static_cast<float>(v), out);
            EXPECT_EQ(vertex, cv::Vec3f(p.x(), p.y(), p.z())) << u << "," << v;
            double sum_w = 0.0, sum_wz = 0.0;
            for (int dv = -r; dv <= r; ++dv) {
                for (int du = -r; du <= r; ++du) {
                    if (!roi.contains(cv::Point(u + du, v + dv))) continue;
                    const double z = depth.at<float>(v + dv, u + du);
                    if (!(z > 0.0) || std::fabs(z - zc) > 3.0 * params.sigma_depth_m) continue;
                    const double w = std::exp(-(du * du + dv * dv) / s2) * std::exp(-(z - zc) * (z - zc) / d2);
                    sum_w += w;
                    sum_wz += w * z;
                }
            }
            worst_m = std::max(worst_m, std::fabs(out - sum_wz / sum_w));
            ++checked;
            interior += roi.contains(cv::Point(u - r, v - r)) && roi.contains(cv::Point(u + r, v + r));
        }
    }
    EXPECT_GT(interior, 10000);
    EXPECT_GT(checked - interior, 100);  // pixels at the box's edges, with clipped windows
    // The filter tabulates the range weight in steps of 0.3 mm of depth difference: across the 80 mm step that
    // moves a weight by up to 0.5 %, 0.02 mm of depth here. A wrong window or weight moves it by millimetres.
    EXPECT_LT(worst_m, 5e-5) << "worst difference from eq. 4.4 over " << checked << " pixels";
}

// A segmentation's box (HeadObservation::mask_box) is all the filter sweeps: with the mask 0 outside it, every
// level comes out bit for bit as from the whole-frame sweep, even after a frame that left other values in the
// filter's buffers; depth outside the box is never kept, whatever the mask says.
TEST(DepthFilter, TheMaskBoxIsAllThatIsSwept) {
    const cv::Mat depth = sphereDepth(Pose::Identity(), Eigen::Vector3f(0.02f, -0.01f, 0.75f), 0.12f);
    cv::Mat mask(depth.size(), CV_8U, cv::Scalar(0));
    cv::circle(mask, cv::Point(345, 225), 70, cv::Scalar(255), cv::FILLED);
    const cv::Rect box = cv::boundingRect(mask);
    DepthFilter whole(kCam, FilterParams{}), boxed(kCam, FilterParams{});
    SurfacePyramid expected, got;
    expected.allocate(kCam, 3);
    got.allocate(kCam, 3);
    ASSERT_GT(boxed.filter(depth, cv::Mat(), got), 10000);  // the whole sphere first: its values stay behind
    const int valid = whole.filter(depth, mask, expected);
    ASSERT_GT(valid, 5000);
    ASSERT_EQ(boxed.filter(depth, mask, got, box), valid);
    for (int l = 0; l < 3; ++l) {
        const SurfaceLevel &e = expected.levels[l], &g = got.levels[l];
        ASSERT_EQ(e.roi, g.roi) << "level " << l;
        // NaN marks invalid vertices and normals: compared bytewise.
        for (const auto& [me, mg] :
             {std::pair{&e.depth_m, &g.depth_m}, {&e.vertex, &g.vertex}, {&e.normal, &g.normal}}) {
            for (int v = e.roi.y; v < e.roi.br().y; ++v) {
                ASSERT_EQ(std::memcmp(me->ptr(v) + e.roi.x * me->elemSize(), mg->ptr(v) + e.roi.x * mg->elemSize(),
                                      static_cast<size_t>(e.roi.width) * me->elemSize()),
                          0)
                    << "level " << l << " row " << v;
            }
        }
    }
    // No mask at all: the box alone decides what is kept.
    const int in_box = cv::countNonZero(depth(box) > 0.0f);
    EXPECT_EQ(boxed.filter(depth, cv::Mat(), got, box), in_box);
    EXPECT_TRUE((box & got.levels[0].roi) == got.levels[0].roi) << got.levels[0].roi;
    EXPECT_LT(in_box, cv::countNonZero(depth > 0.0f));
}

TEST(Tsdf, PlaneGivesTruncatedDistanceAlongTheRay) {
    TsdfParams p = smallVolume();
    TsdfVolume vol(p);
    cv::Mat depth(kCam.height_px, kCam.width_px, CV_32F, cv::Scalar(0.7f));
    DepthFilter f(kCam, FilterParams{});
    SurfacePyramid pyr;
    pyr.allocate(kCam, 1);
    ASSERT_GT(f.filter(depth, cv::Mat(), pyr), 0);
    ASSERT_TRUE(vol.place(pyr.levels[0]));
    const IntegrateStats s = vol.integrate(pyr.levels[0], cv::Mat(), Pose::Identity());
    EXPECT_GT(s.blocks_touched, 0);
    EXPECT_FALSE(s.pool_exhausted);
    const VoxelBlockGrid& g = vol.grid();
    // Voxels on the optical axis: D = (0.7 - z) / mu, truncated to 1 in front, unobserved beyond -mu.
    const Eigen::Vector3f axis_vox = g.toVoxel(Eigen::Vector3f(0, 0, 0.7f));
    const int x = static_cast<int>(std::lround(axis_vox.x())), y = static_cast<int>(std::lround(axis_vox.y()));
    int checked = 0;
    for (int z = 0; z < g.resolution_vox; ++z) {
        const Voxel* vx = g.voxel(x, y, z);
        if (vx == nullptr || vx->weight <= 0.0f) continue;
        const Eigen::Vector3f pw = g.toWorld(Eigen::Vector3f(x, y, z));
        const float d = (0.7f * kCam.ray(kCam.project(pw).x(), kCam.project(pw).y()).norm() - pw.norm());
        EXPECT_GE(d, -p.trunc_dist_m - 1e-6f);
        EXPECT_NEAR(vx->tsdf, std::min(1.0f, d / p.trunc_dist_m), 0.05f) << "z " << z;
        ++checked;
    }
    EXPECT_GE(checked, 6);  // the band +-mu is 6-7 voxels thick
}

// A sphere seen from 14 directions: ray-cast normals equal the radial direction, ray-cast points lie on the
// sphere, and marching cubes gives a closed surface of genus 0 whose vertices are within half a voxel of it.
class SphereTest : public ::testing::Test {
 protected:
    void SetUp() override {
        const TsdfParams p = smallVolume();
        volume_ = std::make_unique<TsdfVolume>(p);
        DepthFilter f(kCam, FilterParams{});
        SurfacePyramid pyr;
        pyr.allocate(kCam, 1);
        std::vector<Eigen::Vector3f> dirs;
        for (int a = 0; a < 3; ++a)
            for (float s : {-1.0f, 1.0f}) dirs.push_back(Eigen::Vector3f::Unit(a) * s);
        for (float sx : {-1.0f, 1.0f})
            for (float sy : {-1.0f, 1.0f})
                for (float sz : {-1.0f, 1.0f}) dirs.emplace_back(sx, sy, sz);
        bool placed = false;
        for (const auto& d : dirs) {
            const Pose T = lookAt(centre_, d, 0.6f);
            const cv::Mat depth = sphereDepth(T, centre_, radius_);
            ASSERT_GT(f.filter(depth, cv::Mat(), pyr), 1000);
            if (!placed) {
                // Place the cube around the sphere: the first view's camera is the world here, so place with a
                // level whose vertices are the sphere in world coordinates.
                SurfaceLevel world = pyr.levels[0];
                world.vertex = pyr.levels[0].vertex.clone();
                world.vertex.forEach<cv::Vec3f>([&](cv::Vec3f& px, const int*) {
                    if (std::isnan(px[0])) return;
                    const Eigen::Vector3f w = T * Eigen::Vector3f(px[0], px[1], px[2]);
                    px = cv::Vec3f(w.x(), w.y(), w.z());
                });
                volume_->place(world);
                placed = true;
            }
            volume_->integrate(pyr.levels[0], cv::Mat(), T);
        }
    }
    const Eigen::Vector3f centre_{0.01f, -0.02f, 0.0f};
    const float radius_ = 0.05f;
    std::unique_ptr<TsdfVolume> volume_;
};

TEST_F(SphereTest, RaycastNormalsAreRadial) {
    Raycaster rc(RaycastParams{});
    SurfacePyramid model;
    model.allocate(kCam, 1);
    const Pose T = lookAt(centre_, Eigen::Vector3f(0.3f, 0.2f, 1.0f), 0.5f);
    rc.cast(volume_->grid(), kCam, T, cv::Rect(0, 0, kCam.width_px, kCam.height_px), cv::Mat(), model.levels[0]);
    int hits = 0;
    double max_radial = 0, sum_angle = 0;
    std::vector<double> angles;
    for (int v = 0; v < kCam.height_px; ++v) {
        for (int u = 0; u < kCam.width_px; ++u) {
            const cv::Vec3f p = model.levels[0].vertex.at<cv::Vec3f>(v, u);
            const cv::Vec3f n = model.levels[0].normal.at<cv::Vec3f>(v, u);
            if (std::isnan(p[0])) continue;
            const Eigen::Vector3f pw(p[0], p[1], p[2]), nw(n[0], n[1], n[2]);
            const Eigen::Vector3f radial = (pw - centre_).normalized();
            // Skip the silhouette rim, where the gradient mixes in unobserved space.
            if (radial.dot((T.translation() - pw).normalized()) < 0.3f) continue;
            angles.push_back(std::acos(std::min(1.0f, nw.dot(radial))) * 57.29578);
            sum_angle += angles.back();
            max_radial = std::max(max_radial, std::fabs((pw - centre_).norm() - radius_) * 1.0);
            ++hits;
        }
    }
    EXPECT_GT(hits, 5000);
    // Eq. 4.30: normal = gradient of D. D is the projective distance along each view's rays (eq. 4.24), not
    // the Euclidean one, so where oblique views overlap the gradient bends by a few degrees (measured: mean
    // 2.1, p99 6.0 deg); a wrong sign, axis or scale would give tens of degrees.
    std::sort(angles.begin(), angles.end());
    EXPECT_LT(sum_angle / hits, 3.0);
    EXPECT_LT(angles[angles.size() * 99 / 100], 8.0);
    EXPECT_LT(max_radial, 0.5 * volume_->params().voxelSizeM());  // eq. 4.28 interpolated crossing
}

// gradient() gathers the 32 voxels of p's cell and the cross around it once and interpolates the grid's central
// differences; that must be exactly the central differences of six trilinear samples one voxel apart (eq. 4.30,
// the formula it replaced), with the same validity, near the surface (block edges included) and at the cube's
// border.
TEST_F(SphereTest, GradientEqualsCentralDifferencesOfSixTrilinearSamples) {
    const VoxelBlockGrid& g = volume_->grid();
    const auto six_samples = [&](const Eigen::Vector3f& p, Eigen::Vector3f& grad) {
        for (int a = 0; a < 3; ++a) {
            Eigen::Vector3f lo = p, hi = p;
            lo[a] -= 1.0f;
            hi[a] += 1.0f;
            float f_lo, f_hi;
            if (g.sample(lo, f_lo) != VoxelBlockGrid::Cell::kOk || g.sample(hi, f_hi) != VoxelBlockGrid::Cell::kOk)
                return false;
            grad[a] = f_hi - f_lo;
        }
        return true;
    };
    std::mt19937 rng(16);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    const float mu = volume_->params().trunc_dist_m;
    const float n = static_cast<float>(g.resolution_vox);
    int valid = 0, compared = 0;
    double max_diff = 0.0;
    for (int i = 0; i < 200000; ++i) {
        Eigen::Vector3f p_vox;
        if (i % 4 != 3) {
            // Within 1.5 mu of the sphere, where the ray caster takes its normals.
            const Eigen::Vector3f dir = Eigen::Vector3f(unit(rng), unit(rng), unit(rng)).normalized();
            p_vox = g.toVoxel(centre_ + dir * (radius_ + 1.5f * mu * unit(rng)));
        } else {
            // Anywhere in and just around the cube: empty blocks and the border.
            p_vox =
                Eigen::Vector3f(unit(rng), unit(rng), unit(rng)).cwiseProduct(Eigen::Vector3f::Constant(0.52f * n)) +
                Eigen::Vector3f::Constant(0.5f * n);
        }
        Eigen::Vector3f want = Eigen::Vector3f::Zero(), got = Eigen::Vector3f::Zero();
        const bool want_ok = six_samples(p_vox, want), got_ok = g.gradient(p_vox, got);
        ASSERT_EQ(want_ok, got_ok) << "at voxel " << p_vox.transpose();
        ++compared;
        if (!want_ok) continue;
        ++valid;
        max_diff = std::max(max_diff, static_cast<double>((want - got).cwiseAbs().maxCoeff()));
    }
    EXPECT_GT(valid, 50000) << "of " << compared;
    // Float rounding only: p -+ 1 is rounded before its fraction is taken (D is in units of mu, |D| <= 1).
    EXPECT_LT(max_diff, 1e-5);
    // The cube's border: a gradient needs voxels c0 - 1 .. c0 + 2 inside it.
    Eigen::Vector3f unused;
    EXPECT_FALSE(g.gradient(Eigen::Vector3f(0.5f, 64.0f, 64.0f), unused));
    EXPECT_FALSE(g.gradient(Eigen::Vector3f(64.0f, n - 2.5f, 64.0f), unused));
    EXPECT_FALSE(g.gradient(Eigen::Vector3f(64.0f, 64.0f, std::numeric_limits<float>::quiet_NaN()), unused));
}

// The ray caster refines a crossing and takes its normal from one gather of a cell and its cross (gatherCross): D
// there must be sample()'s, bit for bit and with the same validity, and so must the gradient at any point of the
// same cell, where the cell was gathered from another point of it.
TEST_F(SphereTest, OneGatheredCrossGivesTheSampleAndTheGradientOfItsWholeCell) {
    const VoxelBlockGrid& g = volume_->grid();
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f), frac(0.0f, 0.999f);
    const float mu = volume_->params().trunc_dist_m;
    int cells = 0, sampled = 0, with_gradient = 0;
    for (int i = 0; i < 100000; ++i) {
        const Eigen::Vector3f dir = Eigen::Vector3f(unit(rng), unit(rng), unit(rng)).normalized();
        const Eigen::Vector3f p_vox = g.toVoxel(centre_ + dir * (radius_ + 1.5f * mu * unit(rng)));
        VoxelBlockGrid::CrossCell cross;
        if (!g.gatherCross(p_vox, cross)) {
            Eigen::Vector3f unused;
            ASSERT_FALSE(g.gradient(p_vox, unused));
            continue;
        }
        ++cells;
        ASSERT_TRUE(cross.contains(p_vox));
        float d = 0.0f;
        ASSERT_EQ(cross.cell_observed, g.sample(p_vox, d) == VoxelBlockGrid::Cell::kOk) << p_vox.transpose();
        if (cross.cell_observed) {
            ++sampled;
            ASSERT_EQ(cross.tsdfAt(p_vox), d) << p_vox.transpose();
        }
        // Another point of the same cell.
        const Eigen::Vector3f q_vox(static_cast<float>(cross.x0) + frac(rng), static_cast<float>(cross.y0) + frac(rng),
                                    static_cast<float>(cross.z0) + frac(rng));
        ASSERT_TRUE(cross.contains(q_vox));
        Eigen::Vector3f want;
        ASSERT_EQ(cross.cross_observed, g.gradient(q_vox, want)) << q_vox.transpose();
        if (!cross.cross_observed) continue;
        ++with_gradient;
        const Eigen::Vector3f got = cross.gradientAt(q_vox);
        ASSERT_EQ(got, want) << q_vox.transpose();
    }
    EXPECT_GT(sampled, 30000) << "of " << cells;
    EXPECT_GT(with_gradient, 30000) << "of " << cells;
    EXPECT_GT(cells - with_gradient, 1000) << "cells at the band's edge, where the cross is not all observed";
    EXPECT_FALSE(VoxelBlockGrid::CrossCell{}.contains(Eigen::Vector3f(0.5f, -0.5f, 0.5f)));
}

TEST_F(SphereTest, MarchingCubesIsClosedGenusZeroAndOnTheSphere) {
    const Mesh mesh = extractMesh(volume_->grid(), MeshParams{});
    ASSERT_GT(mesh.n_faces(), 1000u);
    for (auto eh : mesh.edges()) ASSERT_FALSE(mesh.is_boundary(eh)) << "hole in the surface";
    const long euler =
        static_cast<long>(mesh.n_vertices()) - static_cast<long>(mesh.n_edges()) + static_cast<long>(mesh.n_faces());
    EXPECT_EQ(euler, 2);
    double max_err = 0;
    for (auto vh : mesh.vertices()) {
        const auto& p = mesh.point(vh);
        max_err = std::max(max_err, std::fabs((Eigen::Vector3f(p[0], p[1], p[2]) - centre_).norm() - radius_) * 1.0);
        const auto& n = mesh.normal(vh);
        EXPECT_GT(Eigen::Vector3f(n[0], n[1], n[2]).dot((Eigen::Vector3f(p[0], p[1], p[2]) - centre_).normalized()),
                  0.9f);
    }
    EXPECT_LT(max_err, 0.5 * volume_->params().voxelSizeM());
    // A coarse snapshot of the same volume is still one closed piece.
    MeshParams coarse;
    coarse.stride_vox = 2;
    const Mesh m2 = extractMesh(volume_->grid(), coarse);
    EXPECT_GT(m2.n_faces(), 200u);
    size_t boundary = 0;
    for (auto eh : m2.edges()) boundary += m2.is_boundary(eh) ? 1 : 0;
    // Cubes two voxels wide reach past the observed band in places, so small gaps are allowed there (measured:
    // 2.6 % of the edges); the full-resolution mesh above is exactly closed.
    EXPECT_LT(boundary, m2.n_edges() / 20);
}

TEST(Reconstructor, BadInputIsAValueNeverACrash) {
    Reconstructor rec(kCam, ReconParams::faceDefaults());
    ASSERT_TRUE(rec.initStatus().isOk());
    RgbdFrame f;
    EXPECT_EQ(rec.processFrame(f, cv::Mat()).tracking.status, TrackingStatus::kInvalidInput);  // empty
    f.depth_m = cv::Mat(100, 100, CV_32F, cv::Scalar(0.7f));
    EXPECT_EQ(rec.processFrame(f, cv::Mat()).tracking.status, TrackingStatus::kInvalidInput);  // wrong size
    f.depth_m = cv::Mat(kCam.height_px, kCam.width_px, CV_16U, cv::Scalar(700));
    EXPECT_EQ(rec.processFrame(f, cv::Mat()).tracking.status, TrackingStatus::kInvalidInput);  // wrong type
    f.depth_m = cv::Mat(kCam.height_px, kCam.width_px, CV_32F, cv::Scalar(0));
    FrameResult r = rec.processFrame(f, cv::Mat());  // all invalid
    EXPECT_EQ(r.tracking.status, TrackingStatus::kNoHead);
    EXPECT_FALSE(r.integrated);
    f.depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
    EXPECT_EQ(rec.processFrame(f, cv::Mat()).tracking.status, TrackingStatus::kNoHead);  // all NaN
    f.depth_m = sphereDepth(Pose::Identity(), Eigen::Vector3f(0, 0, 0.7f), 0.08f);
    cv::Mat empty_mask(kCam.height_px, kCam.width_px, CV_8U, cv::Scalar(0));
    EXPECT_EQ(rec.processFrame(f, empty_mask).tracking.status, TrackingStatus::kNoHead);  // no head in the mask
    cv::Mat bad_mask(10, 10, CV_8U, cv::Scalar(1));
    EXPECT_EQ(rec.processFrame(f, bad_mask).tracking.status, TrackingStatus::kInvalidInput);
    f.colour_bgr = cv::Mat(10, 10, CV_8UC3);
    EXPECT_EQ(rec.processFrame(f, cv::Mat()).tracking.status, TrackingStatus::kInvalidInput);
    f.colour_bgr.release();
    r = rec.processFrame(f, cv::Mat());
    EXPECT_EQ(r.tracking.status, TrackingStatus::kFirstFrame);
    EXPECT_TRUE(r.integrated);
    EXPECT_EQ(rec.framesIntegrated(), 1);
    ReconParams bad = ReconParams::faceDefaults();
    bad.tsdf.trunc_dist_m = 0.0f;
    Reconstructor broken(kCam, bad);
    EXPECT_FALSE(broken.initStatus().isOk());
    EXPECT_EQ(broken.processFrame(f, cv::Mat()).tracking.status, TrackingStatus::kInvalidInput);
}

TEST(Tum, LineHasTimestampTranslationAndUnitQuaternion) {
    Pose p = Pose::Identity();
    p.translation() = Eigen::Vector3f(0.1f, -0.2f, 0.3f);
    EXPECT_EQ(toTumLine(1'500'000'000, p),
              "1.500000000 0.1000000 -0.2000000 0.3000000 0.0000000 0.0000000 0.0000000 1.0000000");
}

// Live snapshots re-mesh only the blocks whose voxels changed, and the result is the full re-mesh.
TEST_F(SphereTest, IncrementalMesherEqualsAFullRemeshAndSkipsUnchangedBlocks) {
    MeshParams coarse;
    coarse.stride_vox = 2;
    IncrementalMesher mesher(coarse);
    auto expectSame = [](const IndexedMesh& a, const IndexedMesh& b) {
        ASSERT_EQ(a.triangleCount(), b.triangleCount());
        ASSERT_EQ(a.vertexCount(), b.vertexCount());
        EXPECT_TRUE(a.triangles == b.triangles);
        EXPECT_TRUE(a.positions_m == b.positions_m);
        EXPECT_TRUE(a.colours_rgb == b.colours_rgb);
    };
    TsdfSnapshot grid;
    volume_->grid().copyTo(grid);
    const IndexedMesh first = mesher.update(grid);
    expectSame(first, extractTriangles(volume_->grid(), coarse));
    EXPECT_EQ(mesher.lastStats().blocks_remeshed, volume_->grid().allocated_blocks);

    volume_->grid().copyTo(grid);  // nothing changed
    expectSame(mesher.update(grid), first);
    EXPECT_EQ(mesher.lastStats().blocks_changed, 0);
    EXPECT_EQ(mesher.lastStats().blocks_remeshed, 0);

    // One more view changes the blocks it sees (and so the blocks whose cubes read them); the rest are reused.
    DepthFilter f(kCam, FilterParams{});
    SurfacePyramid pyr;
    pyr.allocate(kCam, 1);
    const Pose T = lookAt(centre_, Eigen::Vector3f(0.2f, 0.1f, 1.0f).normalized(), 0.6f);
    ASSERT_GT(f.filter(sphereDepth(T, centre_, radius_), cv::Mat(), pyr), 1000);
    volume_->integrate(pyr.levels[0], cv::Mat(), T);
    volume_->grid().copyTo(grid);
    expectSame(mesher.update(grid), extractTriangles(volume_->grid(), coarse));
    EXPECT_GT(mesher.lastStats().blocks_changed, 0);
    EXPECT_LT(mesher.lastStats().blocks_remeshed, mesher.lastStats().blocks);

    // A reset volume starts over.
    volume_->reset();
    volume_->grid().copyTo(grid);
    EXPECT_EQ(mesher.update(grid).triangleCount(), 0u);
}

// The live snapshot's copy of a growing model keeps its buffers (no fresh pages every second) and equals the model.
TEST_F(SphereTest, ACopyOfAGrowingGridKeepsItsBuffers) {
    TsdfSnapshot grid;
    volume_->grid().copyTo(grid);
    const Voxel* voxels_before = grid.voxels.data();
    const int blocks_before = grid.allocated_blocks;
    DepthFilter f(kCam, FilterParams{});
    SurfacePyramid pyr;
    pyr.allocate(kCam, 1);
    const Pose T = lookAt(centre_, Eigen::Vector3f(-0.5f, 0.3f, 0.8f).normalized(), 0.6f);
    ASSERT_GT(f.filter(sphereDepth(T, centre_, radius_), cv::Mat(), pyr), 1000);
    volume_->integrate(pyr.levels[0], cv::Mat(), T);
    ASSERT_GT(volume_->grid().allocated_blocks, blocks_before) << "the view should add blocks";
    volume_->grid().copyTo(grid);
    EXPECT_EQ(grid.voxels.data(), voxels_before);
    ASSERT_EQ(grid.allocated_blocks, volume_->grid().allocated_blocks);
    ASSERT_EQ(grid.voxels.size(), static_cast<size_t>(grid.allocated_blocks) * kBlockVoxels);
    EXPECT_EQ(0, std::memcmp(grid.voxels.data(), volume_->grid().voxels.data(), grid.voxels.size() * sizeof(Voxel)));
    EXPECT_TRUE(std::equal(grid.block_coords.begin(), grid.block_coords.end(), volume_->grid().block_coords.begin()));
}

// Defects are found by position, and removeDefects leaves none of the kinds the service promises to avoid.
TEST(IndexedMesh, CountsAndRemovesDefects) {
    IndexedMesh m;
    m.positions_m = {{0, 0, 0},          {0.01f, 0, 0}, {0, 0.01f, 0},
                     {0.01f, 0.01f, 0},  {0.02f, 0, 0}, {0, 0, 0},  // a copy of vertex 0's position
                     {0.5f, 0.5f, 0.5f},                            // unreferenced
                     {0, 0, 0.01f},      {0, 0, -0.01f}};
    m.triangles = {{0, 1, 2}, {1, 3, 2}, {5, 2, 1},  // duplicate of the first by position (other orientation)
                   {0, 1, 4},                        // collinear: zero area
                   {1, 1, 3},                        // repeated vertex
                   {0, 1, 7}, {0, 8, 1}};            // edge 0-1 now has four triangles: non-manifold
    const MeshDefects d = countDefects(m);
    EXPECT_EQ(d.zero_area_triangles, 2u);
    EXPECT_EQ(d.duplicate_triangles, 1u);
    EXPECT_EQ(d.unreferenced_vertices, 1u);
    EXPECT_EQ(d.non_manifold_edges, 1u);
    EXPECT_FALSE(d.clean());
    removeDefects(m);
    const MeshDefects after = countDefects(m);
    EXPECT_TRUE(after.clean());
    EXPECT_EQ(m.triangleCount(), 4u);
    EXPECT_EQ(m.vertexCount(), 6u);
    // Two fans meeting at one vertex (a bow tie) make it non-manifold.
    IndexedMesh bow;
    bow.positions_m = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
    bow.triangles = {{0, 1, 2}, {0, 3, 4}};
    EXPECT_EQ(countDefects(bow).non_manifold_vertices, 1u);
    EXPECT_EQ(countDefects(bow).boundary_edges, 6u);
    computeVertexNormals(bow);
    EXPECT_NEAR(bow.normals[1].z(), 1.0f, 1e-6f);
}

}  // namespace
}  // namespace facescan::recon
