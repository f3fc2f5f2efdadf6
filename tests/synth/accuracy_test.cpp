// The accuracy ruler against cases with known answers, and the renderer's depth against the ruler's surface; the
// observable region (eval/observed_region.hpp) on a scene with a known answer and against the renderer.
#include "eval/accuracy.hpp"

#include <gtest/gtest.h>

#include "eval/depth_mesh.hpp"
#include "eval/mesh_io.hpp"
#include "eval/observed_region.hpp"
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

// The known answer the ruler must not hide: the whole head moved 1 mm along its normals (inflated, or shrunk for
// -1 mm), measured with DEFAULT settings, reads 1.00 +/- 0.05 mm aligned and unaligned, and the alignment finds
// the offset. A face-only alignment without the offset term read 0.33 mm on the Lee Perry-Smith head.
void expectUniformOffsetReadsItself(const synth::HeadModel& h) {
    for (const float offset_mm : {1.0f, -1.0f}) {
        SCOPED_TRACE(h.name + ", offset " + std::to_string(offset_mm) + " mm");
        const recon::Mesh m = offsetAlongNormals(h.mesh, offset_mm * 1e-3f);
        const auto r = measureAccuracy(m, h.mesh, h.nose_tip_head);
        ASSERT_TRUE(r.isOk()) << r.status().toString();
        EXPECT_NEAR(r->mean_mm, 1.0, 0.05);
        EXPECT_NEAR(r->median_mm, 1.0, 0.05);
        EXPECT_NEAR(r->unaligned.mean_mm, 1.0, 0.05);
        EXPECT_NEAR(r->offset_mm, offset_mm, 0.1);
        EXPECT_LT(r->T_gt_mesh.translation().norm(), 0.1e-3f) << "the alignment moved the offset surface";
        EXPECT_DOUBLE_EQ(r->completeness, 1.0);  // 1 mm < 2 mm
    }
}

TEST(Accuracy, WholeHeadOneMillimetreOffsetReadsOneMillimetre) { expectUniformOffsetReadsItself(head()); }

TEST(Accuracy, WholeLeePerrySmithHeadOneMillimetreOffsetReadsOneMillimetre) {
    const auto dir = synth::findLeePerrySmith();
    if (!dir) GTEST_SKIP() << "the Lee Perry-Smith scan is not in ../shared/data (set FACESCAN_DATA_DIR)";
    const auto scan = synth::loadHeadScan(*dir);
    ASSERT_TRUE(scan.isOk()) << scan.status().toString();
    expectUniformOffsetReadsItself(*scan);
}

TEST(Accuracy, RigidAlignmentWithoutTheOffsetTermAbsorbsAnInflation) {
    // Why the defaults are what they are: the old ruler (rigid least-squares ICP over the face) slides the inflated
    // face back onto the truth and reads far less than the 1 mm that is there.
    AccuracyParams old;
    old.fit_offset = false;
    old.robust_scale_m = 0;
    const auto r = measureAccuracy(offsetAlongNormals(head().mesh, 1e-3f), head().mesh, head().nose_tip_head, old);
    ASSERT_TRUE(r.isOk());
    EXPECT_LT(r->mean_mm, 0.8);
    EXPECT_NEAR(r->unaligned.mean_mm, 1.0, 0.05);  // the alignment-free figure tells the truth all the same
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

// Face-region flags of the ruler's default params, computed here independently of the ruler.
std::vector<uint8_t> faceRegionOf(const recon::Mesh& gt, const Eigen::Vector3f& nose) {
    const AccuracyParams p;
    std::vector<uint8_t> in(gt.n_vertices(), 0);
    for (const auto vh : gt.vertices()) {
        const auto& q = gt.point(vh);
        in[vh.idx()] = (Eigen::Vector3f(q[0], q[1], q[2]) - nose).norm() <= p.face_radius_m &&
                       gt.normal(vh)[2] >= p.min_facing_cos;
    }
    return in;
}

TEST(Accuracy, ObservedMaskRestrictsCompletenessToTheObservedPart) {
    // M = the triangles of G whose corners all lie at x <= 0 (the person's right half). Known answers: every
    // corner of M is covered (distance 0); every G vertex at x >= 3 mm is not (M lies in x <= 0, 3 mm > 2 mm).
    const recon::Mesh& gt = head().mesh;
    const std::vector<uint8_t> face = faceRegionOf(gt, head().nose_tip_head);
    recon::Mesh m;
    for (const auto vh : gt.vertices()) m.add_vertex(gt.point(vh));
    std::vector<uint8_t> in_m(gt.n_vertices(), 0);
    for (const auto fh : gt.faces()) {
        std::vector<recon::Mesh::VertexHandle> c;
        bool right = true;
        for (const auto vh : gt.fv_range(fh)) c.push_back(vh), right &= gt.point(vh)[0] <= 0.0f;
        if (!right) continue;
        m.add_face(c);
        for (const auto vh : c) in_m[vh.idx()] = 1;
    }
    m.update_face_normals();
    m.update_vertex_normals();
    std::vector<uint8_t> left(gt.n_vertices(), 0);
    int n_face = 0, n_right = 0, n_left = 0;
    for (size_t i = 0; i < gt.n_vertices(); ++i) {
        left[i] = gt.point(recon::Mesh::VertexHandle(static_cast<int>(i)))[0] >= 0.003f;
        n_face += face[i];
        n_right += face[i] && in_m[i];
        n_left += face[i] && left[i];
    }
    ASSERT_GT(n_right, 300);
    ASSERT_GT(n_left, 300);

    AccuracyParams p;
    p.align = false;  // M is G's own geometry: measured as given, so the answers are exact
    const auto plain = measureAccuracy(m, gt, head().nose_tip_head, p);
    ASSERT_TRUE(plain.isOk()) << plain.status().toString();
    EXPECT_LT(plain->completeness, 1.0 - static_cast<double>(n_left) / n_face + 1e-9);  // the left half is missing
    // Without a mask the observed figures are the plain ones.
    EXPECT_DOUBLE_EQ(plain->completeness_observed, plain->completeness);
    EXPECT_EQ(plain->gt_observed_vertices, plain->gt_face_vertices);
    EXPECT_EQ(plain->gt_face_vertices, n_face);

    // Observed = exactly the part M covers: complete over what was observed, the plain figure unchanged.
    p.observed = in_m;
    const auto part = measureAccuracy(m, gt, head().nose_tip_head, p);
    ASSERT_TRUE(part.isOk()) << part.status().toString();
    EXPECT_DOUBLE_EQ(part->completeness_observed, 1.0);
    EXPECT_EQ(part->gt_observed_vertices, n_right);
    EXPECT_DOUBLE_EQ(part->completeness, plain->completeness);
    EXPECT_EQ(part->gt_face_vertices, n_face);

    // Observed = that part and the far left half: exactly n_right / (n_right + n_left).
    for (size_t i = 0; i < p.observed.size(); ++i) p.observed[i] = in_m[i] || left[i];
    const auto more = measureAccuracy(m, gt, head().nose_tip_head, p);
    ASSERT_TRUE(more.isOk());
    EXPECT_EQ(more->gt_observed_vertices, n_right + n_left);
    EXPECT_NEAR(more->completeness_observed, static_cast<double>(n_right) / (n_right + n_left), 1e-12);
}

TEST(Accuracy, RejectsABadObservedMask) {
    AccuracyParams p;
    p.observed.assign(head().mesh.n_vertices() - 1, 1);  // one entry short
    EXPECT_EQ(measureAccuracy(head().mesh, head().mesh, head().nose_tip_head, p).status().code(),
              StatusCode::kInvalidArgument);
    // Marks only vertices outside the face region (the back of the head): nothing to measure over.
    const std::vector<uint8_t> face = faceRegionOf(head().mesh, head().nose_tip_head);
    p.observed.assign(head().mesh.n_vertices(), 0);
    for (size_t i = 0; i < face.size(); ++i) p.observed[i] = !face[i];
    EXPECT_EQ(measureAccuracy(head().mesh, head().mesh, head().nose_tip_head, p).status().code(),
              StatusCode::kInvalidArgument);
}

// A quad (two triangles) with corners at z, normals toward -z (the camera) unless `away`.
void addQuad(recon::Mesh& m, float x0, float y0, float x1, float y1, float z, bool away = false) {
    const auto a = m.add_vertex({x0, y0, z}), b = m.add_vertex({x1, y0, z}), c = m.add_vertex({x1, y1, z}),
               d = m.add_vertex({x0, y1, z});
    if (away) {
        m.add_face(a, b, c), m.add_face(a, c, d);
    } else {
        m.add_face(a, c, b), m.add_face(a, d, c);
    }
}

TEST(ObservedRegion, KnownSceneOccludersDropoutsMaskAndBackFaces) {
    // Camera = G's frame. A wall of 21 x 21 vertices at z = 0.6 m (1 cm apart), a 6 cm square plate at z = 0.5 m
    // hiding the wall's vertices with |x|, |y| <= 3 cm (their rays cross z = 0.5 at 5/6 of that), a 1 cm film
    // 1 mm in front of the wall vertex (5, 5) cm, and a back-facing quad off to the side.
    recon::Mesh g;
    constexpr int kN = 21;
    for (int r = 0; r < kN; ++r)
        for (int c = 0; c < kN; ++c) g.add_vertex({-0.1f + 0.01f * c, -0.1f + 0.01f * r, 0.6f});
    auto wall = [](int r, int c) { return recon::Mesh::VertexHandle(r * kN + c); };
    for (int r = 0; r + 1 < kN; ++r)
        for (int c = 0; c + 1 < kN; ++c)
            g.add_face(wall(r, c), wall(r + 1, c + 1), wall(r, c + 1)),
                g.add_face(wall(r, c), wall(r + 1, c), wall(r + 1, c + 1));
    const int plate = static_cast<int>(g.n_vertices());
    addQuad(g, -0.03f, -0.03f, 0.03f, 0.03f, 0.5f);
    const int film = static_cast<int>(g.n_vertices());
    addQuad(g, 0.045f, 0.045f, 0.055f, 0.055f, 0.599f);
    const int back = static_cast<int>(g.n_vertices());
    addQuad(g, -0.2f, -0.05f, -0.15f, 0.0f, 0.55f, true);
    g.update_face_normals();
    g.update_vertex_normals();
    ASSERT_LT(g.normal(wall(10, 10))[2], -0.99f);  // faces the camera
    ASSERT_GT(g.normal(recon::Mesh::VertexHandle(back))[2], 0.99f);

    const recon::Intrinsics k = recon::Intrinsics::kinectV1();
    SensorView view;
    view.depth_m = cv::Mat(k.height_px, k.width_px, CV_32F, cv::Scalar(0.6f));
    view.depth_m.colRange(392, k.width_px).setTo(0.0f);  // no return for x >= 8 cm (u = 396 and beyond)
    view.mask = cv::Mat(k.height_px, k.width_px, CV_8U, cv::Scalar(255));
    view.mask.rowRange(0, 200).setTo(0);  // outside the mask: y <= -5 cm (v <= 191.5)
    ObservedRegionParams p;
    const auto s = countSightings(g, k, {view, view}, p);
    ASSERT_TRUE(s.isOk()) << s.status().toString();
    ASSERT_EQ(s->size(), g.n_vertices());
    for (int r = 0; r < kN; ++r) {
        for (int c = 0; c < kN; ++c) {
            const float x = -0.1f + 0.01f * c, y = -0.1f + 0.01f * r;
            const bool hidden = std::fabs(x) < 0.035f && std::fabs(y) < 0.035f;
            const bool measured = !hidden && x < 0.075f;
            const VertexSightings& v = (*s)[static_cast<size_t>(r * kN + c)];
            EXPECT_EQ(v.measured, measured ? 2 : 0) << "wall vertex x " << x << " y " << y;
            EXPECT_EQ(v.in_mask, measured && y > -0.045f ? 2 : 0) << "wall vertex x " << x << " y " << y;
        }
    }
    for (int i = plate; i < film; ++i) EXPECT_EQ((*s)[static_cast<size_t>(i)].measured, 2) << "plate corner";
    for (int i = back; i < back + 4; ++i) EXPECT_EQ((*s)[static_cast<size_t>(i)].measured, 0) << "back face";
    EXPECT_EQ((*s)[15 * kN + 15].measured, 2);  // (5, 5) cm: the film is 1 mm in front, within 1.5 mm
    p.surface_tolerance_m = 0.0005f;
    const auto strict = countSightings(g, k, {view}, p);
    ASSERT_TRUE(strict.isOk());
    EXPECT_EQ((*strict)[15 * kN + 15].measured, 0);  // ... but not within 0.5 mm
    EXPECT_EQ((*strict)[15 * kN + 16].measured, 1);  // its neighbour is not behind the film
    const std::vector<uint8_t> mask = observedMask(*s);
    EXPECT_EQ(mask[10 * kN + 10], 0);
    EXPECT_EQ(mask[10 * kN + 5], 1);
}

TEST(ObservedRegion, AgreesWithTheNoiseFreeRender) {
    // Two independent answers to "is this vertex visible": ray casting against G, and the renderer's z-buffer at
    // the vertex's pixel. They differ only where the pixel centre, up to half a pixel off, falls on another
    // surface: near occlusion edges and in creases.
    synth::SequenceParams sp;
    sp.noise = false;
    sp.torso = false;
    sp.wall = false;
    const synth::KinectSimulator sim(head(), sp);
    const recon::Intrinsics& k = sim.intrinsics();
    for (const int frame : {0, 40, 110}) {
        recon::RgbdFrame f;
        synth::FrameTruth t;
        sim.render(frame, f, &t);
        const auto s = countSightings(head().mesh, k, {{t.T_camera_head, f.depth_m, cv::Mat()}});
        ASSERT_TRUE(s.isOk());
        int seen = 0, seen_agree = 0, hidden = 0, hidden_agree = 0;
        for (const auto vh : head().mesh.vertices()) {
            const auto& q = head().mesh.point(vh);
            const Eigen::Vector3f c = t.T_camera_head * Eigen::Vector3f(q[0], q[1], q[2]);
            const Eigen::Vector3f n = t.T_camera_head.linear() * Eigen::Vector3f(head().mesh.normal(vh).data());
            const Eigen::Vector2f px = k.project(c);
            const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
            // Below y = -0.12 m the renderer blends the neck towards the body pose (skinning): not rigid with G.
            if (q[1] < -0.11f) continue;
            if (!k.contains(u, v) || n.dot(c.normalized()) > -0.5f || !(f.depth_m.at<float>(v, u) > 0)) continue;
            const float gap_m = c.z() - t.depth_true_m.at<float>(v, u);  // > 0: the render shows something in front
            if ((*s)[vh.idx()].measured) {
                ++seen;
                seen_agree += std::fabs(gap_m) < 0.003f;
            } else {
                ++hidden;
                hidden_agree += gap_m > 0.0015f;
            }
        }
        EXPECT_GT(seen, 1000) << "frame " << frame;
        EXPECT_GT(hidden, 20) << "frame " << frame;  // eyes, nostrils, mouth of the built-in head
        EXPECT_GE(seen_agree, 0.995 * seen) << "frame " << frame;
        EXPECT_GE(hidden_agree, 0.95 * hidden) << "frame " << frame << ", " << hidden << " hidden";
    }
}

TEST(ObservedRegion, RejectsBadInput) {
    const recon::Intrinsics k = recon::Intrinsics::kinectV1();
    SensorView ok{recon::Pose::Identity(), cv::Mat(k.height_px, k.width_px, CV_32F, cv::Scalar(0.6f)), cv::Mat()};
    EXPECT_TRUE(countSightings(head().mesh, k, {ok}).isOk());
    EXPECT_TRUE(countSightings(head().mesh, k, {}).isOk());  // no views: nothing observed
    SensorView small = ok;
    small.depth_m = cv::Mat(240, 320, CV_32F, cv::Scalar(0.6f));
    EXPECT_EQ(countSightings(head().mesh, k, {ok, small}).status().code(), StatusCode::kInvalidArgument);
    SensorView raw = ok;
    raw.depth_m = cv::Mat(k.height_px, k.width_px, CV_16U, cv::Scalar(600));
    EXPECT_EQ(countSightings(head().mesh, k, {raw}).status().code(), StatusCode::kInvalidArgument);
    SensorView bad_mask = ok;
    bad_mask.mask = cv::Mat(k.height_px, k.width_px, CV_32F, cv::Scalar(1));
    EXPECT_EQ(countSightings(head().mesh, k, {bad_mask}).status().code(), StatusCode::kInvalidArgument);
    ObservedRegionParams p;
    p.surface_tolerance_m = 0;
    EXPECT_EQ(countSightings(head().mesh, k, {ok}, p).status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(countSightings(recon::Mesh(), k, {ok}).status().code(), StatusCode::kInvalidArgument);
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
