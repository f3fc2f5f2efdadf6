// The accuracy ruler against cases with known answers, and the renderer's depth against the ruler's surface.
#include "eval/accuracy.hpp"

#include <gtest/gtest.h>

#include "eval/depth_mesh.hpp"
#include "eval/mesh_io.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::eval {
namespace {

const synth::HeadModel& head() {
    static const synth::HeadModel h = synth::builtinHead();
    return h;
}

recon::Mesh transformed(const recon::Mesh& m, const recon::Pose& T) {
    recon::Mesh out = m;
    for (const auto vh : out.vertices()) {
        const auto& p = out.point(vh);
        const Eigen::Vector3f q = T * Eigen::Vector3f(p[0], p[1], p[2]);
        out.point(vh) = recon::Mesh::Point(q.x(), q.y(), q.z());
    }
    out.update_face_normals();
    out.update_vertex_normals();
    return out;
}

TEST(Accuracy, MeshAgainstItselfIsZero) {
    const auto r = measureAccuracy(head().mesh, head().mesh, head().nose_tip_head);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    EXPECT_LT(r->mean_mm, 1e-3);
    EXPECT_LT(r->p90_mm, 1e-3);
    EXPECT_DOUBLE_EQ(r->completeness, 1.0);
    EXPECT_EQ(r->outliers, 0.0);
    EXPECT_GT(r->gt_face_vertices, 1000);
}

TEST(Accuracy, OneMillimetreNormalOffsetMeasuresOneMillimetre) {
    recon::Mesh m = head().mesh;
    for (const auto vh : m.vertices()) m.point(vh) += 0.001f * m.normal(vh);
    AccuracyParams p;
    p.align = false;  // ICP would slide a curved offset surface partly back onto the truth
    const auto r = measureAccuracy(m, head().mesh, head().nose_tip_head, p);
    ASSERT_TRUE(r.isOk());
    EXPECT_NEAR(r->mean_mm, 1.0, 0.05);
    EXPECT_NEAR(r->median_mm, 1.0, 0.05);
    EXPECT_NEAR(r->rms_mm, 1.0, 0.05);
    EXPECT_DOUBLE_EQ(r->completeness, 1.0);  // 1 mm < 2 mm
}

TEST(Accuracy, HoleLowersCompletenessByItsShare) {
    // Cut a 25 mm hole in the left cheek of M.
    const recon::Mesh& gt = head().mesh;
    const Eigen::Vector3f centre = head().nose_tip_head + Eigen::Vector3f(0.045f, 0.0f, -0.03f);
    auto dist = [&](const recon::Mesh::Point& p) { return (Eigen::Vector3f(p[0], p[1], p[2]) - centre).norm(); };
    recon::Mesh m;
    for (const auto vh : gt.vertices()) m.add_vertex(gt.point(vh));
    for (const auto fh : gt.faces()) {
        std::vector<recon::Mesh::VertexHandle> c;
        bool inside = false;
        for (const auto vh : gt.fv_range(fh)) c.push_back(vh), inside |= dist(gt.point(vh)) < 0.025f;
        if (!inside) m.add_face(c);
    }
    m.update_face_normals();
    m.update_vertex_normals();
    const auto full = measureAccuracy(gt, gt, head().nose_tip_head);
    const auto holed = measureAccuracy(m, gt, head().nose_tip_head);
    ASSERT_TRUE(full.isOk() && holed.isOk());
    // The hole's share of the face region; vertices within 2 mm of the rim still count as covered.
    AccuracyParams p;
    int in_region = 0, in_hole = 0, in_core = 0;
    for (const auto vh : gt.vertices()) {
        const auto& q = gt.point(vh);
        const bool face = (Eigen::Vector3f(q[0], q[1], q[2]) - head().nose_tip_head).norm() <= p.face_radius_m &&
                          gt.normal(vh)[2] >= p.min_facing_cos;
        in_region += face;
        in_hole += face && dist(q) < 0.025f;
        in_core += face && dist(q) < 0.025f - 0.002f - 0.003f;  // minus 2 mm reach, minus one edge of ragged rim
    }
    const double drop = full->completeness - holed->completeness;
    EXPECT_GT(in_hole, 100);
    EXPECT_LE(drop, static_cast<double>(in_hole) / in_region + 1e-9);
    EXPECT_GE(drop, static_cast<double>(in_core) / in_region);
    EXPECT_LT(holed->mean_mm, 1e-3);  // what is there is exact
}

TEST(Accuracy, RecoversAKnownRigidMisalignment) {
    recon::Pose T = recon::Pose::Identity();
    T.linear() = (Eigen::AngleAxisf(0.2f, Eigen::Vector3f(0.3f, 1, 0.2f).normalized())).toRotationMatrix();
    T.translation() = Eigen::Vector3f(0.02f, -0.015f, 0.03f);
    const auto r = measureAccuracy(transformed(head().mesh, T), head().mesh, head().nose_tip_head);
    ASSERT_TRUE(r.isOk());
    const recon::Pose err = r->T_gt_mesh * T;
    EXPECT_LT(Eigen::AngleAxisf(err.linear()).angle(), 0.002f);
    EXPECT_LT(err.translation().norm(), 0.0003f);
    EXPECT_LT(r->mean_mm, 0.05);
    EXPECT_GT(r->completeness, 0.99);
}

TEST(Accuracy, FirstCameraFrameMeshWithInitialGuess) {
    synth::SequenceParams p;
    p.frames = 1;
    const synth::KinectSimulator sim(head(), p);
    const auto r =
        measureAccuracy(sim.headInFirstCamera(), head().mesh, head().nose_tip_head, {}, sim.poseAt(0).inverse());
    ASSERT_TRUE(r.isOk());
    EXPECT_LT(r->mean_mm, 0.01);
}

TEST(Accuracy, NoiseFreeRenderLiesOnTheSurfaceAndNoisyFrameDoesNot) {
    synth::SequenceParams p;
    p.frames = 1;
    p.noise = false;
    const synth::KinectSimulator exact(head(), p);
    recon::RgbdFrame f;
    synth::FrameTruth t;
    exact.render(0, f, &t);
    const cv::Mat mask = t.label == 1;
    AccuracyParams ap;
    ap.align = false;
    const auto r0 = measureAccuracy(meshFromDepth(f.depth_m, exact.intrinsics(), mask), head().mesh,
                                    head().nose_tip_head, ap, t.T_camera_head.inverse());
    ASSERT_TRUE(r0.isOk());
    EXPECT_LT(r0->p90_mm, 0.02);  // the z-buffer hits the triangles exactly
    EXPECT_GT(r0->mesh_vertices_used, 5000);
    p.noise = true;
    const synth::KinectSimulator noisy(head(), p);
    noisy.render(0, f, &t);
    const auto r1 = measureAccuracy(meshFromDepth(f.depth_m, noisy.intrinsics(), t.label == 1), head().mesh,
                                    head().nose_tip_head, {}, t.T_camera_head.inverse());
    ASSERT_TRUE(r1.isOk());
    // Axial sigma at ~0.6 m is ~1.3 mm: mean |d| of a raw frame is about 1 mm.
    EXPECT_GT(r1->mean_mm, 0.5);
    EXPECT_LT(r1->mean_mm, 2.0);
}

TEST(Accuracy, RejectsBadInput) {
    EXPECT_FALSE(measureAccuracy(recon::Mesh(), head().mesh, head().nose_tip_head).isOk());
    AccuracyParams p;
    p.face_radius_m = -1;
    EXPECT_FALSE(measureAccuracy(head().mesh, head().mesh, head().nose_tip_head, p).isOk());
    EXPECT_FALSE(readMesh("/nonexistent/mesh.ply").isOk());
}

TEST(MeshIo, PlyRoundTripKeepsGeometry) {
    const auto path = std::filesystem::temp_directory_path() / ("facescan_mesh_" + std::to_string(::getpid()) + ".ply");
    ASSERT_TRUE(writeMesh(head().mesh, path).isOk());
    const auto m = readMesh(path);
    std::filesystem::remove(path);
    ASSERT_TRUE(m.isOk());
    EXPECT_EQ(m->n_vertices(), head().mesh.n_vertices());
    EXPECT_EQ(m->n_faces(), head().mesh.n_faces());
    EXPECT_NEAR((findNoseTip(*m) - head().nose_tip_head).norm(), 0.0f, 1e-6f);
}

}  // namespace
}  // namespace facescan::eval
