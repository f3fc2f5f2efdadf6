// The fast paths of the per-frame stages against plain, per-element statements of the thesis' equations:
// TsdfVolume::integrate (a row of voxels projected at once) against Algorithm 3 voxel by voxel, and the depth
// filter's fused level-0 vertex map and valid count against computeVertexMap / computeNormalMap.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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
    const float z = frame.depth_m.at<float>(v, u);
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
    const float d = z * ray.norm() - q.norm();  // eq. 4.24
    if (std::fabs(d + p.trunc_dist_m) < kDistEps || std::fabs(d - p.trunc_dist_m) < kDistEps) return Expect::kEitherWay;
    if (d < -p.trunc_dist_m) return Expect::kUnchanged;
    const float sdf = std::min(1.0f, d / p.trunc_dist_m);
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

}  // namespace
}  // namespace facescan::recon
