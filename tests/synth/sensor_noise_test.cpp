// The synthetic active stereo (D415-like) and time-of-flight (Azure-Kinect-like) sensors: each noise model has the
// statistics its source states (sigma at two depths), and each principle fails where it should: stereo holes on
// a textureless surface beyond the pattern's reach and in the second imager's shadow, flying pixels at
// silhouettes and a multipath bias in a concavity. And the orbit: the camera moves around a still head.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <opencv2/imgproc.hpp>

#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::synth {
namespace {

// A square grid in the head frame, z = height(x, y) metres, facing +z.
HeadModel gridHead(float half, int n, const std::function<float(float, float)>& height) {
    HeadModel h;
    h.name = "grid";
    for (int i = 0; i <= n; ++i) {
        for (int j = 0; j <= n; ++j) {
            const float x = -half + 2 * half * j / n, y = -half + 2 * half * i / n;
            h.mesh.add_vertex(recon::Mesh::Point(x, y, height(x, y)));
        }
    }
    auto vh = [n](int i, int j) { return recon::Mesh::VertexHandle(i * (n + 1) + j); };
    for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
            h.mesh.add_face(vh(i, j), vh(i, j + 1), vh(i + 1, j + 1));
            h.mesh.add_face(vh(i, j), vh(i + 1, j + 1), vh(i + 1, j));
        }
    }
    h.neck_cut_y_m = -1.0f;
    return h;
}

SequenceParams stillWith(const NoiseParams& noise) {
    SequenceParams p;
    p.yaw_amplitude_deg = p.pitch_amplitude_deg = 0;
    p.sway_amplitude_m = 0;
    p.torso = false;
    p.wall = false;
    p.noise_model = noise;
    return p;
}

recon::Intrinsics preset(const std::string& name) {
    SyntheticSpec spec;
    EXPECT_TRUE(applySyntheticSensor(name, spec).isOk());
    return spec.intrinsics;
}

struct WallStats {
    double sd_m = 0, mean_m = 0, invalid = 0;  // invalid: share of the window's pixels without depth
};

// Only a frontal wall at wall_m is in view (the "head" is a small plane behind the camera); statistics over a
// 200 x 200 window around the image centre, over a few frames.
WallStats wallStats(const NoiseParams& noise, const recon::Intrinsics& k, float wall_m) {
    SequenceParams p = stillWith(noise);
    p.distance_m = 0.3f;
    p.wall = true;
    p.wall_distance_m = wall_m;
    p.frames = 3;
    const KinectSimulator sim(gridHead(0.01f, 4, [](float, float) { return 0.8f; }), p, k);
    double sum = 0, ss = 0;
    int n = 0, invalid = 0;
    recon::RgbdFrame f;
    for (int i = 0; i < p.frames; ++i) {
        sim.render(i, f);
        const int u0 = k.width_px / 2 - 100, v0 = k.height_px / 2 - 100;
        for (int v = v0; v < v0 + 200; ++v) {
            for (int u = u0; u < u0 + 200; ++u) {
                const double z = f.depth_m.at<float>(v, u);
                if (z == 0) {
                    ++invalid;
                    continue;
                }
                sum += z - wall_m;
                ss += (z - wall_m) * (z - wall_m);
                ++n;
            }
        }
    }
    WallStats s;
    s.mean_m = n > 0 ? sum / n : 0;
    s.sd_m = n > 0 ? std::sqrt(ss / n - s.mean_m * s.mean_m) : 0;
    s.invalid = static_cast<double>(invalid) / (p.frames * 200 * 200);
    return s;
}

TEST(StereoSensor, DepthErrorGrowsWithTheSquareOfTheDistanceAsIntelStates) {
    const recon::Intrinsics k = preset("d415");
    ASSERT_EQ(k.width_px, 848);
    const NoiseParams noise = NoiseParams::activeStereo(k.fx_px);
    // Intel: RMS = z^2 * 0.08 px / (f * 55 mm): 0.79 mm at 0.6 m, 2.66 mm at 1.1 m.
    for (const float z : {0.6f, 1.1f}) {
        const double expected = z * z * 0.08 / (k.fx_px * 0.055);
        const WallStats s = wallStats(noise, k, z);
        EXPECT_NEAR(s.sd_m, expected, 0.15 * expected) << "wall at " << z << " m";
        EXPECT_LT(std::abs(s.mean_m), 0.1 * expected) << "wall at " << z << " m";
        EXPECT_LT(s.invalid, 0.02) << "the pattern reaches a frontal wall at " << z << " m";
    }
}

TEST(StereoSensor, HolesWhereNeitherPatternNorTextureGivesAMatch) {
    const recon::Intrinsics k = preset("d415");
    // A plain wall at 1.6 m: beyond the pattern's 1.2 m reach and without texture of its own.
    EXPECT_GT(wallStats(NoiseParams::activeStereo(k.fx_px), k, 1.6f).invalid, 0.95);
    // A head in front of a wall at 1.1 m: the second imager's shadow is a band of wall left of the head.
    SequenceParams p = stillWith(NoiseParams::activeStereo(k.fx_px));
    p.distance_m = 0.55f;
    p.wall = true;
    p.wall_distance_m = 1.1f;
    const KinectSimulator sim(builtinHead(), p, k);
    recon::RgbdFrame f;
    FrameTruth t;
    sim.render(0, f, &t);
    const cv::Mat lost = (f.depth_m == 0) & (t.depth_true_m > 0) & (t.label == 0);
    EXPECT_GT(cv::countNonZero(lost), 3000);
    // The head itself, frontal at 0.45-0.6 m, is matched almost everywhere (holes only at grazing incidence).
    const int head = cv::countNonZero(t.label == 1);
    const int head_lost = cv::countNonZero((f.depth_m == 0) & (t.label == 1));
    EXPECT_LT(head_lost, head / 10);
}

// Beyond the pattern's reach a surface with its own texture is still matched, a plain one is not.
TEST(StereoSensor, TheSurfacesOwnTextureIsMatchedBeyondThePatternsReach) {
    const recon::Intrinsics k = preset("d415");
    auto invalidShare = [&](bool textured) {
        HeadModel h = gridHead(0.3f, 80, [](float, float) { return 0.0f; });
        h.mesh.request_vertex_colors();
        for (const auto vh : h.mesh.vertices()) {
            const int i = vh.idx() / 81, j = vh.idx() % 81;
            const uint8_t c = textured && (i + j) % 2 ? 60 : 200;
            h.mesh.set_color(vh, recon::Mesh::Color(c, c, c));
        }
        SequenceParams p = stillWith(NoiseParams::activeStereo(k.fx_px));
        p.distance_m = 1.5f;  // the plane faces the camera 1.5 m away, beyond the 1.2 m reach
        const KinectSimulator sim(std::move(h), p, k);
        recon::RgbdFrame f;
        FrameTruth t;
        sim.render(0, f, &t);
        const cv::Rect centre(k.width_px / 2 - 60, k.height_px / 2 - 60, 120, 120);
        return static_cast<double>(cv::countNonZero(f.depth_m(centre) == 0)) / centre.area();
    };
    EXPECT_GT(invalidShare(false), 0.95);
    EXPECT_LT(invalidShare(true), 0.05);
}

TEST(TimeOfFlightSensor, RandomErrorAtTwoDistancesMatchesTheModel) {
    const recon::Intrinsics k = preset("azure-kinect");
    ASSERT_EQ(k.width_px, 640);
    ASSERT_EQ(k.height_px, 576);
    // 0.8 mm + 0.7 mm/m^2 z^2, with the 1 mm depth units' step^2 / 12.
    for (const float z : {0.6f, 1.5f}) {
        const double sigma = 0.0008 + 0.0007 * z * z;
        const double expected = std::sqrt(sigma * sigma + 0.001 * 0.001 / 12);
        const WallStats s = wallStats(NoiseParams::timeOfFlight(), k, z);
        EXPECT_NEAR(s.sd_m, expected, 0.15 * expected) << "wall at " << z << " m";
        EXPECT_LT(std::abs(s.mean_m), 0.1 * expected) << "a flat wall has no multipath bias";
        EXPECT_LT(s.invalid, 0.01);
    }
}

TEST(TimeOfFlightSensor, FlyingPixelsAtSilhouettesOnly) {
    const recon::Intrinsics k = preset("azure-kinect");
    SequenceParams p = stillWith(NoiseParams::timeOfFlight());
    p.distance_m = 0.75f;
    p.wall = true;
    const KinectSimulator sim(builtinHead(), p, k);
    recon::RgbdFrame f;
    FrameTruth t;
    sim.render(0, f, &t);
    // Silhouettes: the true depth's 3 x 3 neighbourhood spans more than 5 cm.
    cv::Mat filled = t.depth_true_m.clone(), lo, hi;
    filled.setTo(1e6f, t.depth_true_m == 0);
    cv::erode(filled, lo, cv::Mat::ones(3, 3, CV_8U));
    cv::dilate(t.depth_true_m, hi, cv::Mat::ones(3, 3, CV_8U));
    int edge = 0, between = 0, inside = 0, off = 0;
    for (int v = 0; v < k.height_px; ++v) {
        for (int u = 0; u < k.width_px; ++u) {
            const float z = f.depth_m.at<float>(v, u), l = lo.at<float>(v, u), h = hi.at<float>(v, u);
            if (l < 1e5f && h - l > 0.05f) {
                ++edge;
                between += z > l + 0.01f && z < h - 0.01f;  // on neither surface: a flying pixel
            } else if (z > 0 && t.depth_true_m.at<float>(v, u) > 0) {
                ++inside;
                // Off its own surface by more than 6 sigma of the noise plus the multipath cap.
                off += std::abs(z - t.depth_true_m.at<float>(v, u)) > 6 * (0.0008f + 0.0007f * 2.6f) + 0.003f;
            }
        }
    }
    ASSERT_GT(edge, 500);
    EXPECT_GT(between, edge / 4) << edge << " silhouette pixels";
    EXPECT_LT(off, inside / 10000 + 1) << inside << " pixels away from silhouettes";
}

TEST(TimeOfFlightSensor, MultipathReadsAConcavityTooFar) {
    const recon::Intrinsics k = preset("azure-kinect");
    // A plane at 0.6 m with a spherical dent 8 cm across and 15 mm deep in its middle.
    const float dent_r = 0.04f, dent_depth = 0.015f;
    const float R = (dent_r * dent_r + dent_depth * dent_depth) / (2 * dent_depth);
    const HeadModel dented = gridHead(0.12f, 160, [&](float x, float y) {
        const float r2 = x * x + y * y;
        return r2 < dent_r * dent_r ? -(dent_depth - (R - std::sqrt(R * R - r2))) : 0.0f;
    });
    auto centreAndFlatBias = [&](const NoiseParams& noise) {
        SequenceParams p = stillWith(noise);
        p.distance_m = 0.6f;
        p.frames = 8;
        const KinectSimulator sim(dented, p, k);
        double centre = 0, flat = 0;
        int nc = 0, nf = 0;
        recon::RgbdFrame f;
        FrameTruth t;
        for (int i = 0; i < p.frames; ++i) {
            sim.render(i, f, &t);
            for (int v = 0; v < k.height_px; ++v) {
                for (int u = 0; u < k.width_px; ++u) {
                    const float z = f.depth_m.at<float>(v, u), zt = t.depth_true_m.at<float>(v, u);
                    if (z == 0 || zt == 0) continue;
                    const float du = u - k.cx_px, dv = v - k.cy_px;
                    const float r_m = std::sqrt(du * du + dv * dv) * 0.6f / k.fx_px;
                    if (r_m < 0.008f) centre += z - zt, ++nc;
                    if (r_m > 0.07f && r_m < 0.09f) flat += z - zt, ++nf;
                }
            }
        }
        return std::pair{centre / std::max(nc, 1), flat / std::max(nf, 1)};
    };
    const auto [centre, flat] = centreAndFlatBias(NoiseParams::timeOfFlight());
    EXPECT_GT(centre, 0.0004) << "the bottom of the dent reads too far";
    EXPECT_LT(std::abs(flat), 0.0001) << "the flat part does not";
    NoiseParams no_multipath = NoiseParams::timeOfFlight();
    no_multipath.multipath_gain = 0;
    EXPECT_LT(std::abs(centreAndFlatBias(no_multipath).first), 0.0001);
}

TEST(Orbit, TheCameraMovesAroundAStillHead) {
    const StatusOr<SyntheticSpec> spec = parseSyntheticOptions("scenario=orbit,noise=0");
    ASSERT_TRUE(spec.isOk()) << spec.status().toString();
    const KinectSimulator sim(builtinHead(), spec->sequence, spec->intrinsics);
    float max_deg = 0, max_step_deg = 0;
    for (int i = 0; i < sim.frameCount(); ++i) {
        const recon::Pose T = sim.poseAt(i);
        // The head stays rigid with the body (it does not turn) and at its distance from the camera.
        EXPECT_TRUE((sim.bodyPoseAt(i).inverse() * T).isApprox(recon::Pose::Identity(), 1e-4f)) << i;
        EXPECT_NEAR(T.translation().norm(), spec->sequence.distance_m, 1e-4f) << i;
        EXPECT_EQ(sim.yawDegAt(i), 0.0f);
        const Eigen::AngleAxisf from_first(sim.poseAt(0).linear().transpose() * T.linear());
        max_deg = std::max(max_deg, from_first.angle() * 180.0f / static_cast<float>(M_PI));
        if (i > 0) {
            const Eigen::AngleAxisf step(sim.poseAt(i - 1).linear().transpose() * T.linear());
            max_step_deg = std::max(max_step_deg, step.angle() * 180.0f / static_cast<float>(M_PI));
        }
    }
    EXPECT_GT(max_deg, 38.0f);
    EXPECT_LT(max_step_deg, 1.0f);
    // The background moves in the image: the wall seen at the same pixel is at another depth once the camera
    // has moved round by a quarter of its period.
    recon::RgbdFrame a, b;
    FrameTruth ta, tb;
    sim.render(0, a, &ta);
    sim.render(75, b, &tb);
    const int u = 40, v = 240;  // left edge: wall in both frames
    ASSERT_EQ(ta.label.at<uint8_t>(v, u), 0);
    ASSERT_EQ(tb.label.at<uint8_t>(v, u), 0);
    ASSERT_GT(a.depth_m.at<float>(v, u), 0.0f);
    ASSERT_GT(b.depth_m.at<float>(v, u), 0.0f);
    EXPECT_GT(std::abs(a.depth_m.at<float>(v, u) - b.depth_m.at<float>(v, u)), 0.1f);
    // Without orbit the same options keep the camera still.
    const StatusOr<SyntheticSpec> still = parseSyntheticOptions("scenario=orbit,orbit=0,noise=0");
    ASSERT_TRUE(still.isOk());
    const KinectSimulator fixed(builtinHead(), still->sequence, still->intrinsics);
    EXPECT_TRUE(fixed.cameraFromWorldAt(75).isApprox(recon::Pose::Identity()));
}

}  // namespace
}  // namespace facescan::synth
