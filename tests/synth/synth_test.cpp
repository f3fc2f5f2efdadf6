// The synthetic Kinect: exact geometry without noise, smooth motion, determinism, the noise model's statistics,
// the subjects, the TUM writer, and whether OpenCV's stock face cascade believes the colour.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>
#include <thread>

#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"
#include "test_data.hpp"

namespace facescan::synth {
namespace {

// A square grid in the head frame: z = z0 + slope * x (metres), facing +z.
HeadModel planeHead(float z0, float slope, float half) {
    HeadModel h;
    h.name = "plane";
    constexpr int n = 40;
    for (int i = 0; i <= n; ++i) {
        for (int j = 0; j <= n; ++j) {
            const float x = -half + 2 * half * j / n, y = -half + 2 * half * i / n;
            h.mesh.add_vertex(recon::Mesh::Point(x, y, z0 + slope * x));
        }
    }
    auto vh = [](int i, int j) { return recon::Mesh::VertexHandle(i * (n + 1) + j); };
    for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
            h.mesh.add_face(vh(i, j), vh(i, j + 1), vh(i + 1, j + 1));
            h.mesh.add_face(vh(i, j), vh(i + 1, j + 1), vh(i + 1, j));
        }
    }
    h.neck_cut_y_m = -1.0f;
    return h;
}

SequenceParams still(bool noise) {
    SequenceParams p;
    p.yaw_amplitude_deg = p.pitch_amplitude_deg = 0;
    p.sway_amplitude_m = 0;
    p.noise = noise;
    p.torso = false;
    p.wall = false;
    return p;
}

TEST(KinectSimulator, NoiseFreePlaneMatchesRayIntersection) {
    SequenceParams p = still(false);
    p.distance_m = 0.8f;
    const KinectSimulator sim(planeHead(0.05f, 0.3f, 0.15f), p);
    recon::RgbdFrame f;
    FrameTruth t;
    sim.render(0, f, &t);
    // The plane in the camera frame: point P0 and normal n; depth along pixel ray r (z = 1) is n.P0 / n.r.
    const recon::Pose T = sim.poseAt(0);
    const Eigen::Vector3f p0 = T * Eigen::Vector3f(0, 0, 0.05f);
    const Eigen::Vector3f n = T.linear() * Eigen::Vector3f(-0.3f, 0, 1).normalized();
    int hits = 0;
    double max_err = 0;
    for (int v = 0; v < 480; ++v) {
        for (int u = 0; u < 640; ++u) {
            const float z = f.depth_m.at<float>(v, u);
            if (z == 0) continue;
            const Eigen::Vector3f r = sim.intrinsics().ray(static_cast<float>(u), static_cast<float>(v));
            max_err = std::max(max_err, static_cast<double>(std::abs(z - n.dot(p0) / n.dot(r))));
            ++hits;
        }
    }
    // The plane is 0.3 m wide at ~0.75 m: about 230 x 230 px.
    EXPECT_GT(hits, 200 * 200);
    EXPECT_LT(hits, 260 * 260);
    EXPECT_LT(max_err, 2e-5);
    EXPECT_EQ(cv::countNonZero(t.label == 1), hits);
}

TEST(KinectSimulator, DefaultMotionIsSmoothAndReachesItsAmplitudes) {
    const KinectSimulator sim(builtinHead(), SequenceParams{});
    float max_deg = 0, max_mm = 0, max_yaw = 0, max_pitch = 0;
    for (int i = 1; i < sim.frameCount(); ++i) {
        const recon::Pose a = sim.poseAt(i - 1), b = sim.poseAt(i);
        const Eigen::AngleAxisf d(a.linear().transpose() * b.linear());
        max_deg = std::max(max_deg, std::abs(d.angle()) * 180.0f / static_cast<float>(M_PI));
        // Motion of the points of the head that move most: nose tip and the top of the head.
        for (const Eigen::Vector3f& q : {Eigen::Vector3f(0, 0, 0.1f), Eigen::Vector3f(0, 0.14f, 0)}) {
            max_mm = std::max(max_mm, 1000.0f * (a * q - b * q).norm());
        }
        const Eigen::Vector3f fwd = Eigen::Vector3f(1, -1, -1).asDiagonal() * (b.linear() * Eigen::Vector3f::UnitZ());
        max_yaw = std::max(max_yaw, std::abs(std::atan2(fwd.x(), fwd.z())) * 180.0f / static_cast<float>(M_PI));
        max_pitch = std::max(max_pitch, std::abs(std::asin(fwd.y())) * 180.0f / static_cast<float>(M_PI));
    }
    EXPECT_LT(max_deg, 1.5f);
    EXPECT_LT(max_mm, 8.0f);
    EXPECT_NEAR(max_yaw, 35.0f, 1.0f);
    EXPECT_NEAR(max_pitch, 12.0f, 1.0f);
    EXPECT_NEAR(sim.poseAt(0).translation().z(), 0.7f, 1e-5f);
}

TEST(KinectSimulator, DeterministicPerSeedInAnyOrderAndThread) {
    SequenceParams p;
    p.frames = 20;
    const KinectSimulator sim(builtinHead(), p);
    recon::RgbdFrame a, b, c;
    sim.render(7, a);
    std::thread th([&] { sim.render(7, b); });
    sim.render(3, c);
    th.join();
    EXPECT_EQ(cv::norm(a.depth_m, b.depth_m, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(a.colour_bgr, b.colour_bgr, cv::NORM_INF), 0.0);
    p.seed = 2;
    const KinectSimulator other(builtinHead(), p);
    other.render(7, b);
    EXPECT_GT(cv::countNonZero(a.depth_m != b.depth_m), 1000);
}

TEST(KinectSimulator, AxialNoiseOnFlatWallMatchesTheModel) {
    // Only the wall at 1 m is in view (the "head" is a small plane behind the camera).
    SequenceParams p = still(true);
    p.distance_m = 0.5f;
    p.wall = true;
    p.wall_distance_m = 1.0f;
    const KinectSimulator sim(planeHead(1.0f, 0, 0.01f), p);
    recon::RgbdFrame f;
    sim.render(0, f);
    double sum = 0, ss = 0;
    int n = 0, dropped = 0;
    for (int v = 140; v < 340; ++v) {
        for (int u = 220; u < 420; ++u) {
            const double z = f.depth_m.at<float>(v, u);
            if (z == 0) {
                ++dropped;
                continue;
            }
            sum += z - 1.0;
            ss += (z - 1.0) * (z - 1.0);
            ++n;
        }
    }
    const double mean = sum / n, sd = std::sqrt(ss / n - mean * mean);
    // Nguyen et al. at 1 m, near-frontal: 1.2 + 1.9 * 0.36 mm; disparity steps of 1/8 px add step^2 / 12.
    const double sigma = 0.0012 + 0.0019 * 0.36, step = 1.0 * 1.0 * 0.125 / (575.8 * 0.075);
    const double expected = std::sqrt(sigma * sigma + step * step / 12);
    EXPECT_NEAR(sd, expected, 0.2 * expected);
    EXPECT_LT(std::abs(mean), 0.0005);
    EXPECT_NEAR(static_cast<double>(dropped) / (200 * 200), 0.005, 0.003);
}

TEST(KinectSimulator, ShadowBandAndTorsoAndLabels) {
    SequenceParams p;
    p.frames = 1;
    const KinectSimulator sim(builtinHead(), p);
    recon::RgbdFrame f;
    FrameTruth t;
    sim.render(0, f, &t);
    const int head_px = cv::countNonZero(t.label == 1), body_px = cv::countNonZero(t.label == 2);
    EXPECT_GT(head_px, 15000);  // a ~0.15 x 0.23 m head at 0.6-0.7 m
    EXPECT_LT(head_px, 60000);
    EXPECT_GT(body_px, 20000);
    // Shadow: pixels of the wall just left of the head are invalid although the truth has depth there.
    const cv::Mat lost = (f.depth_m == 0) & (t.depth_true_m > 0) & (t.label == 0);
    EXPECT_GT(cv::countNonZero(lost), 3000);
    ASSERT_FALSE(t.face_box_px.empty());
    const cv::Rect box = t.face_box_px;
    EXPECT_GT(box.width, 80);
    EXPECT_LT(box.width, 200);
    EXPECT_GT(cv::countNonZero(t.label(box) == 1), 0.8 * box.area());
}

TEST(HeadModel, BuiltinHeadIsClosedAndHumanSized) {
    const HeadModel h = builtinHead();
    Eigen::AlignedBox3f box;
    double volume = 0;
    for (const auto vh : h.mesh.vertices()) {
        const auto& p = h.mesh.point(vh);
        if (p[1] > h.neck_cut_y_m + 0.01f) box.extend(Eigen::Vector3f(p[0], p[1], p[2]));
    }
    int boundary = 0;
    for (const auto eh : h.mesh.edges()) boundary += h.mesh.is_boundary(eh);
    for (const auto fh : h.mesh.faces()) {
        auto it = h.mesh.cfv_iter(fh);
        const auto a = h.mesh.point(*it++), b = h.mesh.point(*it++), c = h.mesh.point(*it);
        volume += OpenMesh::dot(a, OpenMesh::cross(b, c)) / 6.0;
    }
    EXPECT_EQ(boundary, 2 * 64);  // only the two rims of the open neck tube
    EXPECT_GT(volume, 0.0025);    // outward normals; a head is about 3-4 litres
    EXPECT_LT(volume, 0.006);
    EXPECT_NEAR(headBreadthM(h, 0.03f, 0.08f), 0.152f, 0.012f);
    EXPECT_GT(box.sizes().y(), 0.19f);
    EXPECT_LT(box.sizes().y(), 0.26f);
    EXPECT_GT(box.sizes().z(), 0.17f);
    EXPECT_LT(box.sizes().z(), 0.22f);
    EXPECT_TRUE((h.nose_tip_head - Eigen::Vector3f(0, 0, 0.1f)).norm() < 1e-5f);
}

TEST(HeadModel, LeePerrySmithScaledToHeadBreadth) {
    FACESCAN_REQUIRE_DATA(dir, "leeperrysmith");
    const auto h = loadHeadScan(dir);
    ASSERT_TRUE(h.isOk()) << h.status().toString();
    EXPECT_EQ(h->name, "leeperrysmith");
    EXPECT_FALSE(h->texture_bgr.empty());
    EXPECT_TRUE(h->mesh.has_vertex_texcoords2D());
    EXPECT_EQ(h->mesh.n_faces(), 17684u);
    // Breadth above the ears (README: 3.1 units, 0.152 m); the ears sit 0 to 0.06 m above the nose tip.
    EXPECT_NEAR(headBreadthM(*h, 0.075f, 0.095f), 0.152f, 0.008f);
    EXPECT_FALSE(loadHeadScan(dir / "missing.ply").isOk());
}

TEST(TumWriter, RoundTrip) {
    SequenceParams p;
    p.frames = 3;
    p.yaw_period_frames = 20;  // move visibly within three frames
    const KinectSimulator sim(builtinHead(), p);
    const auto dir = std::filesystem::temp_directory_path() / ("facescan_tum_" + std::to_string(::getpid()));
    ASSERT_TRUE(writeTumSequence(sim, dir).isOk());
    std::ifstream intr(dir / "intrinsics.txt");
    float fx, fy, cx, cy;
    ASSERT_TRUE(intr >> fx >> fy >> cx >> cy);
    EXPECT_FLOAT_EQ(fx, 575.8f);
    EXPECT_FLOAT_EQ(cy, 239.5f);
    std::ifstream depth_txt(dir / "depth.txt"), gt_txt(dir / "groundtruth.txt");
    std::string line;
    std::vector<std::string> depth_files;
    while (std::getline(depth_txt, line)) {
        if (line.empty() || line[0] == '#') continue;
        depth_files.push_back(line.substr(line.find(' ') + 1));
    }
    ASSERT_EQ(depth_files.size(), 3u);
    recon::RgbdFrame f;
    sim.render(2, f);
    const cv::Mat raw = cv::imread((dir / depth_files[2]).string(), cv::IMREAD_ANYDEPTH);
    ASSERT_EQ(raw.type(), CV_16UC1);
    cv::Mat back;
    recon::depthRawToMetres(raw, 1.0f / 5000, back);
    EXPECT_LE(cv::norm(back, f.depth_m, cv::NORM_INF), 0.5 / 5000 + 1e-6);
    std::vector<recon::Pose> poses;
    while (std::getline(gt_txt, line)) {
        if (line.empty() || line[0] == '#') continue;
        std::istringstream ls(line);
        double t, tx, ty, tz, qx, qy, qz, qw;
        ASSERT_TRUE(ls >> t >> tx >> ty >> tz >> qx >> qy >> qz >> qw);
        recon::Pose T = recon::Pose::Identity();
        T.linear() = Eigen::Quaternionf(qw, qx, qy, qz).normalized().toRotationMatrix();
        T.translation() = Eigen::Vector3f(tx, ty, tz);
        poses.push_back(T);
    }
    ASSERT_EQ(poses.size(), 3u);
    EXPECT_LT((poses[0].matrix() - Eigen::Matrix4f::Identity()).norm(), 1e-5f);
    // Camera 2 in the first camera frame: a head point seen by camera 2 maps to where camera 0 saw it.
    const Eigen::Vector3f nose = sim.head().nose_tip_head;
    EXPECT_LT((poses[2] * (sim.poseAt(2) * nose) - sim.poseAt(0) * nose).norm(), 1e-5f);
    EXPECT_TRUE(std::filesystem::exists(dir / "head_gt.ply"));
    EXPECT_TRUE(std::filesystem::exists(dir / "T_camera0_head.txt"));
    std::filesystem::remove_all(dir);
}

// A rolled camera sees the upright camera's image turned about the principal point: roll 180 is cv::rotate's
// ROTATE_180 of the upright frame, roll 90 its ROTATE_90_CLOCKWISE where both frames see the scene (the central
// 480 x 480 pixels of a 640 x 480 camera whose principal point is the image centre). Noise-free, torso and wall in.
double rolledAgreement(float roll_deg, cv::RotateFlags flag) {
    SequenceParams p;
    p.frames = 1;
    p.noise = false;
    p.sway_amplitude_m = 0;
    const KinectSimulator upright(builtinHead(), p);
    p.roll_deg = roll_deg;
    const KinectSimulator rolled(builtinHead(), p);
    recon::RgbdFrame a, b;
    FrameTruth ta, tb;
    upright.render(0, a, &ta);
    rolled.render(0, b, &tb);
    cv::Mat turned, turned_label;
    cv::rotate(a.depth_m, turned, flag);
    cv::rotate(ta.label, turned_label, flag);
    // The common region, centred on both principal points.
    const int side_w = std::min(turned.cols, b.depth_m.cols), side_h = std::min(turned.rows, b.depth_m.rows);
    const cv::Rect in_turned((turned.cols - side_w) / 2, (turned.rows - side_h) / 2, side_w, side_h);
    const cv::Rect in_rolled((b.depth_m.cols - side_w) / 2, (b.depth_m.rows - side_h) / 2, side_w, side_h);
    const cv::Mat za = turned(in_turned), zb = b.depth_m(in_rolled);
    const cv::Mat la = turned_label(in_turned), lb = tb.label(in_rolled);
    int same = 0, head = 0;
    for (int v = 0; v < side_h; ++v) {
        for (int u = 0; u < side_w; ++u) {
            same += std::abs(za.at<float>(v, u) - zb.at<float>(v, u)) < 1e-4f &&
                    la.at<uint8_t>(v, u) == lb.at<uint8_t>(v, u);
            head += lb.at<uint8_t>(v, u) == static_cast<uint8_t>(PixelLabel::kHead);
        }
    }
    EXPECT_GT(head, 15000) << "the head is in the common region";
    return static_cast<double>(same) / (side_w * side_h);
}

TEST(KinectSimulator, RolledCameraRendersTheTurnedImage) {
    EXPECT_GT(rolledAgreement(180.0f, cv::ROTATE_180), 0.995);
    EXPECT_GT(rolledAgreement(90.0f, cv::ROTATE_90_CLOCKWISE), 0.995);
    EXPECT_GT(rolledAgreement(-90.0f, cv::ROTATE_90_COUNTERCLOCKWISE), 0.995);
    EXPECT_GT(rolledAgreement(270.0f, cv::ROTATE_90_COUNTERCLOCKWISE), 0.995);
    // Not the same image turned the other way: the test can tell the direction.
    EXPECT_LT(rolledAgreement(90.0f, cv::ROTATE_90_COUNTERCLOCKWISE), 0.9);
}

TEST(SyntheticOptions, RollIsParsedAndChecked) {
    StatusOr<SyntheticSpec> spec = parseSyntheticOptions("roll=90,sensor=truedepth");
    ASSERT_TRUE(spec.isOk()) << spec.status().toString();
    EXPECT_EQ(spec->sequence.roll_deg, 90.0f);
    EXPECT_FALSE(parseSyntheticOptions("roll=400").isOk());
    EXPECT_FALSE(parseSyntheticOptions("roll=portrait").isOk());
    // A camera turned during the scan: the roll goes from roll to roll + roll_turn over the frames.
    spec = parseSyntheticOptions("roll=90,roll_turn=-90,frames=11");
    ASSERT_TRUE(spec.isOk()) << spec.status().toString();
    const KinectSimulator sim(builtinHead(), spec->sequence);
    EXPECT_FLOAT_EQ(sim.rollDegAt(0), 90.0f);
    EXPECT_FLOAT_EQ(sim.rollDegAt(5), 45.0f);
    EXPECT_FLOAT_EQ(sim.rollDegAt(10), 0.0f);
}

TEST(SequenceParams, RejectsNonsense) {
    SequenceParams p;
    EXPECT_TRUE(p.validate().isOk());
    p.frames = 0;
    EXPECT_FALSE(p.validate().isOk());
    p = {};
    p.wall_distance_m = p.distance_m;
    EXPECT_FALSE(p.validate().isOk());
    p = {};
    p.noise_model.dropout_rate = 1.5f;
    EXPECT_FALSE(p.validate().isOk());
}

// Share of frontal frames (|yaw| < 10 deg) on which the stock cascade finds the true face box (IoU >= 0.3).
double frontalDetectionRate(HeadModel head) {
    cv::CascadeClassifier cascade(FACESCAN_HAAR_FRONTAL_DEFAULT);
    EXPECT_FALSE(cascade.empty());
    const KinectSimulator sim(std::move(head), SequenceParams{});
    int tried = 0, found = 0;
    recon::RgbdFrame f;
    FrameTruth t;
    cv::Mat grey;
    for (const int i : {0, 4, 8, 146, 150, 154, 296}) {
        sim.render(i, f, &t);
        cv::cvtColor(f.colour_bgr, grey, cv::COLOR_BGR2GRAY);
        std::vector<cv::Rect> faces;
        cascade.detectMultiScale(grey, faces, 1.1, 3, 0, cv::Size(60, 60));
        ++tried;
        for (const auto& r : faces) {
            const double inter = (r & t.face_box_px).area();
            if (inter / (r.area() + t.face_box_px.area() - inter) >= 0.3) {
                ++found;
                break;
            }
        }
    }
    return static_cast<double>(found) / tried;
}

TEST(KinectSimulator, StockCascadeFindsTheScannedFace) {
    FACESCAN_REQUIRE_DATA(dir, "leeperrysmith");
    auto h = loadHeadScan(dir);
    ASSERT_TRUE(h.isOk());
    EXPECT_GE(frontalDetectionRate(std::move(h).value()), 6.0 / 7);
}

TEST(KinectSimulator, StockCascadeFindsTheBuiltinFace) { EXPECT_GE(frontalDetectionRate(builtinHead()), 6.0 / 7); }

}  // namespace
}  // namespace facescan::synth
