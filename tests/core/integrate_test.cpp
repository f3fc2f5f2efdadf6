// The fast paths of the per-frame stages against plain, per-element statements of the thesis' equations:
// TsdfVolume::integrate (a row of voxels projected at once) against Algorithm 3 voxel by voxel, and the depth
// filter's fused level-0 vertex map and valid count against computeVertexMap / computeNormalMap.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include "recon/depth_filter.hpp"
#include "recon/tsdf_volume.hpp"

namespace facescan::recon {
namespace {

const Intrinsics kCam = Intrinsics::kinectV1();

// Depth of a sphere (centre c_world, radius r) seen from T_world_camera, with a few holes; 0 where the ray misses.
cv::Mat sphereDepth(const Pose& T_world_camera, const Eigen::Vector3f& c_world, float r) {
    cv::Mat depth(kCam.height_px, kCam.width_px, CV_32F, cv::Scalar(0));
    const Eigen::Vector3f c = T_world_camera.inverse() * c_world;
    for (int v = 0; v < depth.rows; ++v) {
        for (int u = 0; u < depth.cols; ++u) {
            const Eigen::Vector3f ray = kCam.ray(static_cast<float>(u), static_cast<float>(v));
            const float a = ray.squaredNorm(), b = ray.dot(c), disc = b * b - a * (c.squaredNorm() - r * r);
            if (disc > 0.0f && (u * 7 + v * 13) % 97 != 0) depth.at<float>(v, u) = (b - std::sqrt(disc)) / a;
        }
    }
    return depth;
}

cv::Mat gradientColour() {
    cv::Mat bgr(kCam.height_px, kCam.width_px, CV_8UC3);
    for (int v = 0; v < bgr.rows; ++v)
        for (int u = 0; u < bgr.cols; ++u)
            bgr.at<cv::Vec3b>(v, u) = cv::Vec3b(static_cast<uint8_t>(u % 256), static_cast<uint8_t>(v % 256),
                                                static_cast<uint8_t>((u + v) % 256));
    return bgr;
}

Pose turned(float yaw_rad, float pitch_rad, const Eigen::Vector3f& t) {
    Pose p = Pose::Identity();
    p.linear() =
        (Eigen::AngleAxisf(yaw_rad, Eigen::Vector3f::UnitY()) * Eigen::AngleAxisf(pitch_rad, Eigen::Vector3f::UnitX()))
            .toRotationMatrix();
    p.translation() = t;
    return p;
}

enum class Expect { kUnchanged, kUpdated, kEitherWay };

// Algorithm 3 (eq. 4.22-4.26) for one voxel, written out as the thesis states it: project the voxel, look up the
// pixel's measurement, weight it by viewing angle (the normal around the pixel) and depth, and average. kEitherWay
// where the voxel sits within rounding of a decision (a pixel border, the -mu cut-off, the colour's +mu): the
// integrator reaches the voxel's position by sums along the grid (1e-7 m off the direct transform), so such a voxel may
// fall on either side.
Expect referenceUpdate(const TsdfParams& p, const SurfaceLevel& frame, const cv::Mat& bgr, const Pose& T_world_camera,
                       const Eigen::Vector3f& voxel_world, Voxel& vx) {
    constexpr float kPxEps = 1e-3f, kDistEps = 1e-6f;  // pixels, metres
    const Eigen::Vector3f q = T_world_camera.inverse() * voxel_world;
    if (q.z() <= 0.0f) return Expect::kUnchanged;
    const Eigen::Vector2f px = kCam.project(q) + Eigen::Vector2f::Constant(0.5f);
    if (std::fabs(px.x() - std::round(px.x())) < kPxEps || std::fabs(px.y() - std::round(px.y())) < kPxEps)
        return Expect::kEitherWay;
    const int u = static_cast<int>(std::floor(px.x())), v = static_cast<int>(std::floor(px.y()));
    if (!frame.roi.contains({u, v})) return Expect::kUnchanged;
    const float z = frame.depthToIntegrate().at<float>(v, u);  // the lightly filtered depth, where given
    if (!(z > 0.0f) || u == frame.roi.x || v == frame.roi.y) return Expect::kUnchanged;
    // The angle's normal: the mean of eq. 4.10's normals of the four pixel squares around the pixel; where one is
    // missing (a depth edge), the pixel's own alone, and the weight scaled by edge_weight. None without its own.
    Eigen::Vector3f n = Eigen::Vector3f::Zero();
    bool edge = false;
    for (const auto& [du, dv] : {std::pair{0, 0}, std::pair{-1, 0}, std::pair{0, -1}, std::pair{-1, -1}}) {
        const cv::Vec3f m = frame.normal.at<cv::Vec3f>(v + dv, u + du);
        if (std::isnan(m[0])) {
            if (du == 0 && dv == 0) return Expect::kUnchanged;
            edge = true;
            continue;
        }
        n += Eigen::Vector3f(m[0], m[1], m[2]);
    }
    if (edge) {
        const cv::Vec3f own = frame.normal.at<cv::Vec3f>(v, u);
        n = Eigen::Vector3f(own[0], own[1], own[2]);
    }
    const Eigen::Vector3f ray = kCam.ray(static_cast<float>(u), static_cast<float>(v));
    const float cos_angle = -n.normalized().dot(ray) / ray.norm();
    if (cos_angle < p.min_cos_angle) return Expect::kUnchanged;
    const float w =
        (edge ? p.edge_weight : 1.0f) * std::exp(-(1.0f - cos_angle) / p.weight_angle_sigma -
                                                 z * z / (2.0f * p.weight_depth_sigma_m * p.weight_depth_sigma_m));
    const float range = z * ray.norm();
    const float d = range - q.norm();  // eq. 4.24
    // Measurements reach mu plus behind_band_px footprints (range / f) behind the surface, clamped to -mu there.
    const float behind = p.trunc_dist_m + p.behind_band_px * range * 2.0f / (kCam.fx_px + kCam.fy_px);
    if (std::fabs(d + behind) < kDistEps || std::fabs(d - p.trunc_dist_m) < kDistEps) return Expect::kEitherWay;
    if (d < -behind) return Expect::kUnchanged;
    const float sdf = std::clamp(d / p.trunc_dist_m, -1.0f, 1.0f);
    const float w_sum = vx.weight + w;
    vx.tsdf = (vx.weight * vx.tsdf + w * sdf) / w_sum;  // eq. 4.22
    if (sdf < 1.0f) {
        const cv::Vec3b c = bgr.at<cv::Vec3b>(v, u);
        const float a = w / w_sum;
        vx.b = static_cast<uint8_t>(vx.b + a * (c[0] - vx.b) + 0.5f);
        vx.g = static_cast<uint8_t>(vx.g + a * (c[1] - vx.g) + 0.5f);
        vx.r = static_cast<uint8_t>(vx.r + a * (c[2] - vx.r) + 0.5f);
    }
    vx.weight = std::min(w_sum, p.max_weight);  // eq. 4.23
    return Expect::kUpdated;
}

// Integration into a 128^3 cube of 1.5 mm voxels around a sphere seen from two views, the second turned and shifted
// so that the grid's axes are oblique to the camera's.
class Tsdf : public ::testing::Test {
 protected:
    static TsdfParams cubeParams() {
        TsdfParams p;
        p.resolution_vox = 128;
        p.volume_size_m = 0.192f;
        p.centre_behind_surface_m = 0.0f;
        return p;
    }
    void SetUp() override { pyr.allocate(kCam, 1); }

    const TsdfParams p = cubeParams();
    TsdfVolume vol{p};
    DepthFilter filter{kCam, FilterParams{}};
    SurfacePyramid pyr;
    const Eigen::Vector3f centre{0.01f, -0.02f, 0.7f};
    const Pose poses[2] = {Pose::Identity(), turned(-0.35f, 0.2f, Eigen::Vector3f(0.2f, 0.1f, 0.05f))};
};

TEST_F(Tsdf, IntegrationMatchesAlgorithm3VoxelByVoxel) {
    const cv::Mat bgr = gradientColour();
    int updated = 0, either_way = 0, frames = 0;
    for (const Pose& T_world_camera : poses) {
        ASSERT_GT(filter.filter(sphereDepth(T_world_camera, centre, 0.09f), cv::Mat(), pyr), 1000);
        if (!vol.placed()) {
            ASSERT_TRUE(vol.place(pyr.levels[0]));
        }
        const VoxelBlockGrid before = vol.grid();
        const uint64_t generation = vol.generation();
        const IntegrateStats stats = vol.integrate(pyr.levels[0], bgr, T_world_camera);
        ASSERT_GT(stats.blocks_touched, 0);
        ASSERT_FALSE(stats.pool_exhausted);
        std::vector<Eigen::Vector3i> touched;
        std::vector<Voxel> voxels;
        vol.copyBlocks(generation, touched, voxels);
        ASSERT_EQ(static_cast<int>(touched.size()), stats.blocks_touched);
        const VoxelBlockGrid& after = vol.grid();
        for (size_t b = 0; b < touched.size(); ++b) {
            for (int i = 0; i < kBlockVoxels; ++i) {
                const Eigen::Vector3i c = touched[b] * kBlockSide + Eigen::Vector3i(i & 7, (i >> 3) & 7, i >> 6);
                const Voxel* old = before.block_index.empty() ? nullptr : before.voxel(c.x(), c.y(), c.z());
                Voxel expected = old != nullptr ? *old : Voxel{};
                const Expect e =
                    referenceUpdate(p, pyr.levels[0], bgr, T_world_camera, after.toWorld(c.cast<float>()), expected);
                if (e == Expect::kEitherWay) {
                    ++either_way;
                    continue;
                }
                updated += e == Expect::kUpdated ? 1 : 0;
                const Voxel& got = *after.voxel(c.x(), c.y(), c.z());
                // 1e-4 mu = 0.5 um: the position's rounding; a wrong pixel or weight is off by far more.
                ASSERT_NEAR(got.tsdf, expected.tsdf, 1e-4f) << "voxel " << c.transpose() << " frame " << frames;
                ASSERT_NEAR(got.weight, expected.weight, 1e-6f * std::max(1.0f, expected.weight));
                ASSERT_NEAR(got.b, expected.b, 1);
                ASSERT_NEAR(got.g, expected.g, 1);
                ASSERT_NEAR(got.r, expected.r, 1);
            }
        }
        ++frames;
    }
    EXPECT_GT(updated, 20000);            // the comparison covered the band around two views of the sphere
    EXPECT_LT(either_way, updated / 50);  // about 2 x 2e-3 of the voxels sit within 1e-3 px of a pixel border
}

// The blocks a frame touches are those within -mu, 0, +mu of every second pixel's measurement along its ray (found
// in parallel, allocated serially): new blocks are allocated in the order a row-major scan first names them, on any
// core count, so two runs build the same pool.
TEST_F(Tsdf, AllocatesTheBlocksAlongEverySecondPixelsRayInScanOrder) {
    std::vector<Eigen::Vector3i> expected_pool;
    for (const Pose& T_world_camera : poses) {
        ASSERT_GT(filter.filter(sphereDepth(T_world_camera, centre, 0.09f), cv::Mat(), pyr), 1000);
        if (!vol.placed()) {
            ASSERT_TRUE(vol.place(pyr.levels[0]));
        }
        const SurfaceLevel& lv = pyr.levels[0];
        const VoxelBlockGrid& g = vol.grid();
        const int bps = g.blocks_per_side;
        const float inv_block_m = 1.0f / (g.voxel_size_m * kBlockSide);
        const Eigen::Vector3f half_voxel = Eigen::Vector3f::Constant(0.5f * g.voxel_size_m);
        std::vector<Eigen::Vector3i> named;  // this frame's blocks, first naming order
        for (int v = lv.roi.y; v < lv.roi.br().y; v += 2) {
            for (int u = lv.roi.x; u < lv.roi.br().x; u += 2) {
                const float z = lv.depth_m.at<float>(v, u);
                if (!(z > 0.0f)) continue;
                const Eigen::Vector3f ray = kCam.ray(static_cast<float>(u), static_cast<float>(v));
                const float step = p.trunc_dist_m / ray.norm();
                for (int s = -1; s <= 1; ++s) {
                    const Eigen::Vector3f p_world = T_world_camera * (ray * (z + static_cast<float>(s) * step));
                    const Eigen::Vector3f b = (p_world - g.origin_world + half_voxel) * inv_block_m;
                    const Eigen::Vector3i bc(static_cast<int>(std::floor(b.x())), static_cast<int>(std::floor(b.y())),
                                             static_cast<int>(std::floor(b.z())));
                    if (bc.minCoeff() < 0 || bc.maxCoeff() >= bps) continue;
                    if (std::find(named.begin(), named.end(), bc) == named.end()) named.push_back(bc);
                }
            }
        }
        for (const Eigen::Vector3i& bc : named) {
            if (std::find(expected_pool.begin(), expected_pool.end(), bc) == expected_pool.end())
                expected_pool.push_back(bc);
        }
        const uint64_t generation = vol.generation();
        const IntegrateStats stats = vol.integrate(lv, gradientColour(), T_world_camera);
        EXPECT_EQ(stats.blocks_touched, static_cast<int>(named.size()));
        std::vector<Eigen::Vector3i> touched;
        std::vector<Voxel> voxels;
        vol.copyBlocks(generation, touched, voxels);
        ASSERT_EQ(touched.size(), named.size());
        for (const Eigen::Vector3i& bc : touched)
            EXPECT_NE(std::find(named.begin(), named.end(), bc), named.end()) << bc.transpose();
    }
    ASSERT_EQ(static_cast<int>(expected_pool.size()), vol.grid().allocated_blocks);
    EXPECT_GT(expected_pool.size(), 100u);
    for (size_t i = 0; i < expected_pool.size(); ++i)
        ASSERT_EQ(vol.grid().block_coords[i], expected_pool[i]) << "pool slot " << i;
}

TEST(DepthFilter, FusedLevelZeroVerticesCountAndRoiEqualThePerMapFunctions) {
    const cv::Mat depth = sphereDepth(Pose::Identity(), Eigen::Vector3f(0.0f, 0.0f, 0.8f), 0.1f);
    DepthFilter filter(kCam, FilterParams{});
    SurfacePyramid pyr;
    pyr.allocate(kCam, 3);
    // A mask that keeps the sphere's upper left quarter: the ROI (from the mask pass, over stripes of rows) is the
    // box of the pixels kept.
    cv::Mat mask(depth.size(), CV_8UC1, cv::Scalar(0));
    mask(cv::Rect(0, 0, 331, 247)).setTo(255);
    const int valid = filter.filter(depth, mask, pyr);
    EXPECT_EQ(valid, cv::countNonZero(pyr.levels[0].depth_m > 0.0f));
    EXPECT_GT(valid, 5000);
    int u0 = depth.cols, v0 = depth.rows, u1 = -1, v1 = -1;
    for (int v = 0; v < depth.rows; ++v) {
        for (int u = 0; u < depth.cols; ++u) {
            if (!(mask.at<uint8_t>(v, u) && depth.at<float>(v, u) > 0.0f)) continue;
            u0 = std::min(u0, u), v0 = std::min(v0, v), u1 = std::max(u1, u), v1 = std::max(v1, v);
        }
    }
    EXPECT_EQ(pyr.levels[0].roi, cv::Rect(cv::Point(u0, v0), cv::Point(u1 + 1, v1 + 1)));
    for (int l = 0; l < pyr.count; ++l) {
        const SurfaceLevel& lv = pyr.levels[l];
        cv::Mat vertex(lv.vertex.size(), CV_32FC3, cv::Scalar::all(0)), normal = vertex.clone();
        computeVertexMap(lv.k, lv.depth_m, lv.roi, vertex);
        computeNormalMap(vertex, lv.roi, filter.params().pyramid_max_step_m, normal);
        int compared = 0;
        for (int v = lv.roi.y; v < lv.roi.br().y; ++v) {
            for (int u = lv.roi.x; u < lv.roi.br().x; ++u) {
                for (int a = 0; a < 3; ++a) {
                    const float got_v = lv.vertex.at<cv::Vec3f>(v, u)[a], want_v = vertex.at<cv::Vec3f>(v, u)[a];
                    const float got_n = lv.normal.at<cv::Vec3f>(v, u)[a], want_n = normal.at<cv::Vec3f>(v, u)[a];
                    ASSERT_TRUE(got_v == want_v || (std::isnan(got_v) && std::isnan(want_v)))
                        << l << " " << u << "," << v;
                    ASSERT_TRUE(got_n == want_n || (std::isnan(got_n) && std::isnan(want_n)))
                        << l << " " << u << "," << v;
                }
                ++compared;
            }
        }
        EXPECT_GT(compared, 100) << "level " << l;
    }
}

// The depth the model integrates (FilterParams::integration_sigma_space_px): eq. 4.4 with its own spatial sigma over
// the inner 3x3 and the registration filter's range kernel, at every pixel (the four-wide path and the ROI's edges
// alike); and what it is for: a groove 2 px wide and 3 mm deep in a wall keeps most of its depth, where the
// registration's depth (1 px sigma over 5x5) bridges it.
TEST(DepthFilter, IntegrationDepthIsEq44OverTheInner3x3AndKeepsANarrowGroove) {
    cv::Mat depth(kCam.height_px, kCam.width_px, CV_32F, cv::Scalar(0.7f));
    for (int v = 0; v < depth.rows; ++v) {
        for (int u = 0; u < depth.cols; ++u) {
            if (u == 320 || u == 321) depth.at<float>(v, u) = 0.703f;  // the groove
            // A ripple left of the groove (so the range kernel's weights differ), and a few holes.
            depth.at<float>(v, u) += (u < 320 ? 0.002f : 0.0f) * static_cast<float>((u * 31 + v * 17) % 7 - 3) / 3.0f;
            if ((u * 7 + v * 13) % 97 == 0) depth.at<float>(v, u) = 0.0f;
        }
    }
    cv::Mat mask(depth.size(), CV_8UC1, cv::Scalar(0));
    mask(cv::Rect(250, 100, 141, 200)).setTo(255);
    const FilterParams params;
    ASSERT_GT(params.integration_sigma_space_px, 0.0f);
    DepthFilter filter(kCam, params);
    SurfacePyramid pyr;
    pyr.allocate(kCam, 1);
    ASSERT_GT(filter.filter(depth, mask, pyr), 20000);
    const SurfaceLevel& lv = pyr.levels[0];
    ASSERT_FALSE(lv.integration_depth_m.empty());
    ASSERT_EQ(&lv.depthToIntegrate(), &lv.integration_depth_m);
    const double s2 = 2.0 * params.integration_sigma_space_px * params.integration_sigma_space_px;
    const double r2 = 2.0 * params.sigma_depth_m * params.sigma_depth_m;
    int compared = 0;
    for (int v = lv.roi.y; v < lv.roi.br().y; ++v) {
        for (int u = lv.roi.x; u < lv.roi.br().x; ++u) {
            const float zc = mask.at<uint8_t>(v, u) ? depth.at<float>(v, u) : 0.0f;
            const float got = lv.integration_depth_m.at<float>(v, u);
            if (!(zc > 0.0f)) {
                ASSERT_EQ(got, 0.0f) << u << "," << v;
                continue;
            }
            double sum_w = 0.0, sum_wz = 0.0;
            for (int dv = -1; dv <= 1; ++dv) {
                for (int du = -1; du <= 1; ++du) {
                    if (!lv.roi.contains({u + du, v + dv}) || !mask.at<uint8_t>(v + dv, u + du)) continue;
                    const double z = depth.at<float>(v + dv, u + du);
                    if (!(z > 0.0)) continue;
                    const double w = std::exp(-(du * du + dv * dv) / s2) * std::exp(-(z - zc) * (z - zc) / r2);
                    sum_w += w, sum_wz += w * z;
                }
            }
            // The filter's range kernel is a 512-step table: 1e-6 m is well above its rounding, far below a wrong tap.
            ASSERT_NEAR(got, sum_wz / sum_w, 1e-6) << u << "," << v;
            ++compared;
        }
    }
    EXPECT_GT(compared, 20000);
    // Rows away from the holes' influence: the groove's depth below its right-hand wall (no added ripple there).
    double kept_int = 0.0, kept_reg = 0.0;
    int rows = 0;
    for (int v = 120; v < 280; ++v) {
        bool clean = true;
        for (int u = 316; u <= 326 && clean; ++u)
            for (int dv = -2; dv <= 2; ++dv) clean = clean && depth.at<float>(v + dv, u) > 0.0f;
        if (!clean) continue;
        kept_int += lv.integration_depth_m.at<float>(v, 321) - lv.integration_depth_m.at<float>(v, 325);
        kept_reg += lv.depth_m.at<float>(v, 321) - lv.depth_m.at<float>(v, 325);
        ++rows;
    }
    ASSERT_GT(rows, 50);
    kept_int /= rows, kept_reg /= rows;
    EXPECT_GT(kept_int, 0.85 * 0.003) << "the integration depth keeps most of the groove";
    EXPECT_LT(kept_reg, 0.7 * 0.003) << "the registration's depth bridges a third of it (why the two differ)";
}

// Algorithm 3 cuts a measurement off at mu behind the surface and clamps it at mu in front. Decided on a noisy
// depth, that cut drops the samples measured too near and keeps those measured too far, and the fused surface
// lies behind the true one (the model comes out thin). The band behind (behind_band_px) moves the cut out of most
// of the noise: a wall at 0.7 m measured with Gaussian noise of half mu, 120 times, fused with and without it (the
// same samples), the zero crossing of every voxel column near the optical axis against the wall.
double fusedWallOffsetMu(float behind_band_px) {
    TsdfParams p;
    p.resolution_vox = 64;
    p.volume_size_m = 0.096f;  // 1.5 mm voxels, mu = 5 mm
    p.centre_behind_surface_m = 0.0f;
    p.behind_band_px = behind_band_px;
    TsdfVolume vol(p);
    const float wall_m = 0.7f;
    SurfaceLevel lv;
    lv.k = kCam;
    lv.roi = cv::Rect(270, 190, 100, 100);
    lv.depth_m = cv::Mat(kCam.height_px, kCam.width_px, CV_32F, cv::Scalar(0.0f));
    lv.vertex = cv::Mat(kCam.height_px, kCam.width_px, CV_32FC3, cv::Scalar::all(std::nanf("")));
    lv.normal = lv.vertex.clone();
    lv.normal(lv.roi).setTo(cv::Scalar(0.0f, 0.0f, -1.0f));   // exact: only the depth is noisy
    lv.vertex(lv.roi).setTo(cv::Scalar(0.0f, 0.0f, wall_m));  // only place() reads it
    if (!vol.place(lv)) return NAN;
    std::mt19937 rng(7);
    std::normal_distribution<float> noise(0.0f, 0.5f * p.trunc_dist_m);
    for (int frame = 0; frame < 120; ++frame) {
        for (int v = lv.roi.y; v < lv.roi.br().y; ++v)
            for (int u = lv.roi.x; u < lv.roi.br().x; ++u) lv.depth_m.at<float>(v, u) = wall_m + noise(rng);
        vol.integrate(lv, cv::Mat(), Pose::Identity());
    }
    const VoxelBlockGrid& g = vol.grid();
    double sum_offset = 0.0;
    int columns = 0;
    for (int y = 24; y < 40; ++y) {
        for (int x = 24; x < 40; ++x) {
            for (int z = 0; z + 1 < g.resolution_vox; ++z) {
                const Voxel *a = g.voxel(x, y, z), *b = g.voxel(x, y, z + 1);
                if (a == nullptr || b == nullptr || !(a->weight > 0.0f) || !(b->weight > 0.0f)) continue;
                if (!(a->tsdf > 0.0f && b->tsdf <= 0.0f)) continue;
                const float cross_z =
                    g.toWorld(Eigen::Vector3f(x, y, z)).z() + g.voxel_size_m * a->tsdf / (a->tsdf - b->tsdf);
                sum_offset += (cross_z - wall_m) / p.trunc_dist_m;
                ++columns;
                break;
            }
        }
    }
    return columns > 200 ? sum_offset / columns : NAN;
}

TEST(TsdfNoise, TheBandBehindTheSurfaceKeepsANoisyWallFromComingOutThin) {
    const double without = fusedWallOffsetMu(0.0f), with = fusedWallOffsetMu(TsdfParams{}.behind_band_px);
    // Without the band the wall fuses about 0.03 mu behind itself (0.15 mm at mu = 5 mm; the truncated Gaussian's
    // expectation gives 0.027); the default band (half a footprint, 0.27 mu here) takes off 40 % of that.
    EXPECT_GT(without, 0.02) << "the cut-off's bias, in mu";
    EXPECT_LT(with, 0.7 * without) << "with the band, in mu";
    EXPECT_GT(with, -0.01) << "the band does not turn it into an inflation";
}

}  // namespace
}  // namespace facescan::recon
