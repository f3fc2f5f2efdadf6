// The texture atlas (recon/texture_atlas.hpp) and its files (recon/mesh_writer.hpp) on a sphere whose colour is known
// everywhere: views are ray-cast analytically (not with the code under test), so the atlas can be compared with the
// truth at any surface point.
#include <gtest/gtest.h>
#include <unistd.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "recon/mesh_writer.hpp"
#include "recon/texture_atlas.hpp"

namespace facescan::recon {
namespace {

const Eigen::Vector3f kCentre(0.0f, 0.0f, 0.5f);  // metres, the first camera's frame (y down, z forward)
constexpr float kRadius = 0.1f;                   // metres
constexpr float kPi = 3.14159265f;

// The sphere's true colour at a surface point (BGR, 0-255): stripes about 4 cm apart, finer than the vertices'
// 1 cm spacing can hold, so vertex colours blur them and a texture does not.
Eigen::Vector3f trueBgr(const Eigen::Vector3f& p) {
    const Eigen::Vector3f d = p - kCentre;
    return {128 + 90 * std::sin(150 * d.x()), 128 + 90 * std::sin(150 * d.y()), 128 + 90 * std::sin(150 * d.z())};
}

// A latitude-longitude sphere: poles along y (the head's axis), vertex colours and normals exact.
IndexedMesh sphere(int n_lat, int n_lon) {
    IndexedMesh m;
    auto add = [&](const Eigen::Vector3f& dir) {
        m.positions_m.push_back(kCentre + kRadius * dir);
        m.normals.push_back(dir);
        const Eigen::Vector3f c = trueBgr(m.positions_m.back());
        m.colours_rgb.push_back({static_cast<uint8_t>(std::lround(c[2])), static_cast<uint8_t>(std::lround(c[1])),
                                 static_cast<uint8_t>(std::lround(c[0]))});
    };
    add(Eigen::Vector3f(0, -1, 0));
    for (int i = 1; i < n_lat; ++i) {
        const float lat = kPi * static_cast<float>(i) / static_cast<float>(n_lat);
        for (int j = 0; j < n_lon; ++j) {
            const float lon = 2 * kPi * static_cast<float>(j) / static_cast<float>(n_lon);
            add(Eigen::Vector3f(std::sin(lat) * std::cos(lon), -std::cos(lat), std::sin(lat) * std::sin(lon)));
        }
    }
    add(Eigen::Vector3f(0, 1, 0));
    const auto ring = [&](int i, int j) { return static_cast<uint32_t>(1 + (i - 1) * n_lon + (j % n_lon)); };
    const uint32_t last = static_cast<uint32_t>(m.positions_m.size() - 1);
    for (int j = 0; j < n_lon; ++j) {
        m.triangles.push_back({0, ring(1, j + 1), ring(1, j)});
        for (int i = 1; i < n_lat - 1; ++i) {
            m.triangles.push_back({ring(i, j), ring(i, j + 1), ring(i + 1, j)});
            m.triangles.push_back({ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)});
        }
        m.triangles.push_back({ring(n_lat - 1, j), ring(n_lat - 1, j + 1), last});
    }
    // Outward winding: flip any triangle whose normal points inwards.
    for (Triangle& t : m.triangles) {
        const Eigen::Vector3f& a = m.positions_m[t[0]];
        const Eigen::Vector3f n = (m.positions_m[t[1]] - a).cross(m.positions_m[t[2]] - a);
        if (n.dot(a - kCentre) < 0) std::swap(t[1], t[2]);
    }
    return m;
}

// A 640x480 camera 0.5 m from the sphere's centre, turned by yaw about the vertical and pitch, looking at it;
// the image ray-cast from the true sphere, its colours times `gain`.
TextureView view(float yaw_deg, float pitch_deg, float gain = 1.0f) {
    TextureView v;
    v.colour = Intrinsics::kinectV1();
    const Eigen::Matrix3f R_mesh_colour = (Eigen::AngleAxisf(yaw_deg * kPi / 180, Eigen::Vector3f::UnitY()) *
                                           Eigen::AngleAxisf(pitch_deg * kPi / 180, Eigen::Vector3f::UnitX()))
                                              .toRotationMatrix();
    Pose T_mesh_colour = Pose::Identity();
    T_mesh_colour.linear() = R_mesh_colour;
    T_mesh_colour.translation() = kCentre - R_mesh_colour * Eigen::Vector3f(0, 0, 0.5f);
    v.T_colour_mesh = T_mesh_colour.inverse();
    v.colour_bgr = cv::Mat(v.colour.height_px, v.colour.width_px, CV_8UC3, cv::Scalar(30, 60, 40) * gain);
    const Eigen::Vector3f o = T_mesh_colour.translation();
    for (int y = 0; y < v.colour.height_px; ++y) {
        for (int x = 0; x < v.colour.width_px; ++x) {
            const Eigen::Vector3f d = (R_mesh_colour * v.colour.ray(float(x), float(y))).normalized();
            const Eigen::Vector3f oc = o - kCentre;
            const float b = oc.dot(d), c = oc.squaredNorm() - kRadius * kRadius, disc = b * b - c;
            if (disc < 0) continue;
            const Eigen::Vector3f bgr = gain * trueBgr(o + (-b - std::sqrt(disc)) * d);
            v.colour_bgr.at<cv::Vec3b>(y, x) =
                cv::Vec3b(cv::saturate_cast<uint8_t>(bgr[0]), cv::saturate_cast<uint8_t>(bgr[1]),
                          cv::saturate_cast<uint8_t>(bgr[2]));
        }
    }
    return v;
}

std::vector<TextureView> ringOfViews(float gain_of_third = 1.0f) {
    return {view(0, 0), view(-35, 0), view(35, 0, gain_of_third), view(-70, 0), view(70, 0), view(0, 30), view(0, -30)};
}

Eigen::Vector3f atlasAt(const cv::Mat& atlas, const Eigen::Vector2f& uv) {
    cv::Mat px;
    const cv::Point2f at(uv.x() * float(atlas.cols) - 0.5f, uv.y() * float(atlas.rows) - 0.5f);
    cv::getRectSubPix(atlas, cv::Size(1, 1), at, px);
    const cv::Vec3b c = px.at<cv::Vec3b>(0, 0);
    return {float(c[0]), float(c[1]), float(c[2])};
}

// Mean absolute colour error (0-255, over channels) at the centroids of the triangles that face the cameras
// (within 60 degrees of -z), of the atlas and of the vertex colours interpolated.
struct Errors {
    double texture = 0, vertex = 0;
};
Errors frontErrors(const TexturedMesh& t) {
    Errors e;
    int n = 0;
    for (const Triangle& tri : t.mesh.triangles) {
        Eigen::Vector3f p = Eigen::Vector3f::Zero(), vertex_bgr = Eigen::Vector3f::Zero();
        Eigen::Vector2f uv = Eigen::Vector2f::Zero();
        for (const uint32_t v : tri) {
            p += t.mesh.positions_m[v] / 3;
            uv += t.uv[v] / 3;
            const Rgb8& c = t.mesh.colours_rgb[v];
            vertex_bgr += Eigen::Vector3f(c[2], c[1], c[0]) / 3;
        }
        const Eigen::Vector3f dir = (p - kCentre).normalized();
        if (dir.z() > -0.5f) continue;
        const Eigen::Vector3f truth = trueBgr(kCentre + kRadius * dir);
        e.texture += (atlasAt(t.atlas_bgr, uv) - truth).cwiseAbs().mean();
        e.vertex += (vertex_bgr - truth).cwiseAbs().mean();
        ++n;
    }
    e.texture /= std::max(1, n);
    e.vertex /= std::max(1, n);
    return e;
}

TEST(TextureCharts, FaceIsOneSeamlessPieceAndUvsLieInTheAtlas) {
    const IndexedMesh mesh = sphere(32, 64);
    TexturedMesh out;
    auto report = textureCharts(mesh, {}, TextureParams{}, out);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    ASSERT_EQ(out.mesh.triangleCount(), mesh.triangleCount());
    ASSERT_EQ(out.uv.size(), out.mesh.vertexCount());
    ASSERT_EQ(out.source_vertex.size(), out.mesh.vertexCount());
    for (const Eigen::Vector2f& uv : out.uv) {
        EXPECT_GT(uv.x(), 0.0f);
        EXPECT_LT(uv.x(), 1.0f);
        EXPECT_GT(uv.y(), 0.0f);
        EXPECT_LT(uv.y(), 1.0f);
    }
    // Every vertex of the front half away from the poles (the face) has exactly one copy: no cut runs through it.
    std::map<uint32_t, int> copies;
    for (const uint32_t s : out.source_vertex) ++copies[s];
    int front = 0;
    for (const auto& [v, n] : copies) {
        const Eigen::Vector3f dir = (mesh.positions_m[v] - kCentre) / kRadius;
        if (dir.z() < -0.2f && std::abs(dir.y()) < 0.5f) {
            EXPECT_EQ(n, 1) << "vertex " << v << " at " << dir.transpose() << " lies on a cut";
            ++front;
        }
    }
    EXPECT_GT(front, 100);
    // The back has the cut: some vertices there have two copies; caps are charts of their own.
    EXPECT_GT(out.mesh.vertexCount(), mesh.vertexCount());
    EXPECT_GE(report->charts, 3);
    // Without views the texel is a millimetre: the atlas holds the sphere's 0.126 m^2 at about that density.
    EXPECT_NEAR(report->texel_mm, 1.0f, 1e-3f);
    const double texels = double(report->atlas_width_px) * report->atlas_height_px;
    EXPECT_GT(texels, 0.126 / 1e-6);
    EXPECT_LT(texels, 3 * 0.126 / 1e-6);
}

// A surface inside the head (as the carving leaves in a solid closed behind the face) unwraps onto the same place
// of the cylinder as the head around it: it must get texels of its own, or the bake paints one with the other's
// colours. Two concentric spheres: no texel centre lies inside two triangles' UVs.
TEST(TextureCharts, ALayerInsideTheHeadGetsTexelsOfItsOwn) {
    IndexedMesh mesh = sphere(32, 64);
    const IndexedMesh inner = sphere(24, 48);
    const uint32_t base = static_cast<uint32_t>(mesh.vertexCount());
    for (size_t i = 0; i < inner.vertexCount(); ++i) {
        mesh.positions_m.push_back(kCentre + 0.5f * (inner.positions_m[i] - kCentre));
        mesh.normals.push_back(inner.normals[i]);
        mesh.colours_rgb.push_back(inner.colours_rgb[i]);
    }
    for (const Triangle& t : inner.triangles) mesh.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
    TexturedMesh out;
    auto report = textureCharts(mesh, {}, TextureParams{}, out);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    ASSERT_EQ(out.mesh.triangleCount(), mesh.triangleCount());
    const int width = out.atlas_bgr.cols, height = out.atlas_bgr.rows;
    cv::Mat covered(height, width, CV_8U, cv::Scalar(0));
    int shared = 0, texels = 0;
    for (const Triangle& t : out.mesh.triangles) {
        Eigen::Vector2f c[3];
        for (int k = 0; k < 3; ++k) c[k] = out.uv[t[k]].cwiseProduct(Eigen::Vector2f(width, height));
        const float area = (c[1] - c[0]).x() * (c[2] - c[0]).y() - (c[1] - c[0]).y() * (c[2] - c[0]).x();
        ASSERT_GT(std::abs(area), 0.0f);
        const int x0 = std::max(0, int(std::floor(std::min({c[0].x(), c[1].x(), c[2].x()}))));
        const int x1 = std::min(width - 1, int(std::ceil(std::max({c[0].x(), c[1].x(), c[2].x()}))));
        const int y0 = std::max(0, int(std::floor(std::min({c[0].y(), c[1].y(), c[2].y()}))));
        const int y1 = std::min(height - 1, int(std::ceil(std::max({c[0].y(), c[1].y(), c[2].y()}))));
        for (int y = y0; y <= y1; ++y) {
            for (int x = x0; x <= x1; ++x) {
                const Eigen::Vector2f p(float(x) + 0.5f, float(y) + 0.5f);
                bool inside = true;
                for (int k = 0; k < 3; ++k) {
                    const Eigen::Vector2f& a = c[k];
                    const Eigen::Vector2f& b = c[(k + 1) % 3];
                    inside = inside &&
                             ((b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x())) / area > 1e-3f;
                }
                if (!inside) continue;
                ++texels;
                if (covered.at<uint8_t>(y, x)++ == 1) ++shared;
            }
        }
    }
    EXPECT_GT(texels, 0.126 * 1.25 / 1e-6 * 0.7);  // both spheres' area at a millimetre a texel, most of it
    EXPECT_EQ(shared, 0) << "of " << texels << " texels";
}

TEST(TextureBake, ResolvesWhatVertexColoursBlur) {
    const IndexedMesh mesh = sphere(32, 64);
    TexturedMesh out;
    auto report = bakeTexture(mesh, ringOfViews(), TextureParams{}, out);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    ASSERT_TRUE(out.valid());
    std::printf("%s\n", report->summary().c_str());
    // From the colour camera's resolution: the median view distance to the centre (0.5 m) over fx (575.8 px) is
    // 0.87 mm a pixel, two texels a pixel by default.
    EXPECT_NEAR(report->texel_mm, 0.5f / 575.8f * 1000 / 2, 0.01f);
    EXPECT_EQ(report->views_used, 7);
    const Errors e = frontErrors(out);
    std::printf("front mean abs error: texture %.2f, vertex colours %.2f (of 255)\n", e.texture, e.vertex);
    EXPECT_LT(e.texture, 6.0);
    EXPECT_LT(e.texture, e.vertex / 2);
    // The vertex colours stay as they were.
    for (size_t i = 0; i < out.mesh.vertexCount(); ++i) {
        ASSERT_EQ(out.mesh.colours_rgb[i], mesh.colours_rgb[out.source_vertex[i]]);
    }
}

TEST(TextureBake, EvensOutAViewsExposure) {
    const IndexedMesh mesh = sphere(32, 64);
    TexturedMesh even, raw;
    TextureParams params;
    ASSERT_TRUE(bakeTexture(mesh, ringOfViews(0.6f), params, even).isOk());
    params.even_exposure = false;
    ASSERT_TRUE(bakeTexture(mesh, ringOfViews(0.6f), params, raw).isOk());
    const Errors e_even = frontErrors(even), e_raw = frontErrors(raw);
    std::printf("one view at 0.6 exposure: error evened %.2f, as captured %.2f\n", e_even.texture, e_raw.texture);
    EXPECT_LT(e_even.texture, e_raw.texture - 1.0);
    EXPECT_LT(e_even.texture, 8.0);
}

TEST(TextureBake, HiddenSurfaceIsNotPaintedFromAViewThatCannotSeeIt) {
    // Only the frontal view: the back of the sphere is hidden from it by the front. Its texels must come from the
    // vertex colours, not from the front's pixels that lie on the same rays.
    const IndexedMesh mesh = sphere(32, 64);
    TexturedMesh out;
    auto report = bakeTexture(mesh, {view(0, 0)}, TextureParams{}, out);
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    EXPECT_GT(report->texels_unseen, report->texels_surface / 3);
    double back_error = 0;
    int n = 0;
    for (const Triangle& tri : out.mesh.triangles) {
        Eigen::Vector3f p = Eigen::Vector3f::Zero(), vertex_bgr = Eigen::Vector3f::Zero();
        Eigen::Vector2f uv = Eigen::Vector2f::Zero();
        for (const uint32_t v : tri) {
            p += out.mesh.positions_m[v] / 3;
            uv += out.uv[v] / 3;
            const Rgb8& c = out.mesh.colours_rgb[v];
            vertex_bgr += Eigen::Vector3f(c[2], c[1], c[0]) / 3;
        }
        if ((p - kCentre).normalized().z() < 0.5f) continue;  // the back, facing away from the camera
        back_error += (atlasAt(out.atlas_bgr, uv) - vertex_bgr).cwiseAbs().mean();
        ++n;
    }
    ASSERT_GT(n, 100);
    EXPECT_LT(back_error / n, 3.0);
}

TEST(TextureBake, BadInputGetsAClearMessage) {
    const IndexedMesh mesh = sphere(16, 32);
    TexturedMesh out;
    auto none = bakeTexture(mesh, {}, TextureParams{}, out);
    ASSERT_FALSE(none.isOk());
    EXPECT_NE(none.status().message().find("no colour"), std::string::npos) << none.status().message();
    EXPECT_FALSE(out.valid());

    std::vector<TextureView> dark = {view(0, 0, 0.02f), view(30, 0, 0.02f)};
    auto darkened = bakeTexture(mesh, dark, TextureParams{}, out);
    ASSERT_FALSE(darkened.isOk());
    EXPECT_NE(darkened.status().message().find("dark"), std::string::npos) << darkened.status().message();

    // One dark view among good ones is left out with a note.
    std::vector<TextureView> mixed = {view(0, 0), view(30, 0, 0.02f)};
    auto some = bakeTexture(mesh, mixed, TextureParams{}, out);
    ASSERT_TRUE(some.isOk()) << some.status().toString();
    EXPECT_EQ(some->views_dark, 1);

    std::vector<TextureView> wrong = {view(0, 0)};
    wrong[0].colour.width_px = 1280;
    auto mismatched = bakeTexture(mesh, wrong, TextureParams{}, out);
    ASSERT_FALSE(mismatched.isOk());
    EXPECT_NE(mismatched.status().message().find("matches its camera"), std::string::npos);

    TextureParams huge;
    huge.texel_m = 1e-5f;  // 10 um per texel: the sphere would need an atlas 30,000 texels wide
    huge.max_atlas_px = 4096;
    auto too_large = bakeTexture(mesh, {view(0, 0)}, huge, out);
    ASSERT_FALSE(too_large.isOk());
    EXPECT_EQ(too_large.status().code(), StatusCode::kResourceExhausted);
    EXPECT_NE(too_large.status().message().find("exceeds"), std::string::npos) << too_large.status().message();
    EXPECT_FALSE(out.valid());

    TextureParams tight;
    tight.max_memory_bytes = size_t{1} << 20;  // the sphere's atlas needs tens of MiB to bake
    auto no_memory = bakeTexture(mesh, {view(0, 0)}, tight, out);
    ASSERT_FALSE(no_memory.isOk());
    EXPECT_EQ(no_memory.status().code(), StatusCode::kResourceExhausted);
    EXPECT_NE(no_memory.status().message().find("MiB"), std::string::npos) << no_memory.status().message();
    EXPECT_FALSE(out.valid());

    TextureParams bad;
    bad.weight_power = 0;
    EXPECT_FALSE(bakeTexture(mesh, {view(0, 0)}, bad, out).isOk());
}

}  // namespace
}  // namespace facescan::recon

namespace facescan::recon {
namespace {

TEST(TextureFiles, ObjMtlPngAndPlyCarryTheTexture) {
    const IndexedMesh mesh = sphere(16, 32);
    TexturedMesh t;
    ASSERT_TRUE(bakeTexture(mesh, {view(0, 0), view(40, 0)}, TextureParams{}, t).isOk());

    auto obj = texturedObjFiles(t, "model");
    ASSERT_TRUE(obj.isOk()) << obj.status().toString();
    EXPECT_NE(obj->obj.find("mtllib model.mtl\nusemtl facescan\n"), std::string::npos);
    EXPECT_NE(obj->mtl.find("map_Kd model.png"), std::string::npos);
    size_t vt = 0, faces = 0;
    std::istringstream lines(obj->obj);
    for (std::string line; std::getline(lines, line);) {
        if (line.rfind("vt ", 0) == 0) {
            float u = -1, v = -1;
            ASSERT_EQ(std::sscanf(line.c_str(), "vt %f %f", &u, &v), 2);
            // v up: the first uv's v is 1 - its glTF v.
            if (vt == 0) {
                EXPECT_NEAR(v, 1.0f - t.uv[0].y(), 1e-5f);
            }
            ++vt;
        }
        if (line.rfind("f ", 0) == 0) {
            unsigned a[3][3];
            ASSERT_EQ(std::sscanf(line.c_str(), "f %u/%u/%u %u/%u/%u %u/%u/%u", &a[0][0], &a[0][1], &a[0][2], &a[1][0],
                                  &a[1][1], &a[1][2], &a[2][0], &a[2][1], &a[2][2]),
                      9)
                << line;
            ++faces;
        }
    }
    EXPECT_EQ(vt, t.mesh.vertexCount());
    EXPECT_EQ(faces, t.mesh.triangleCount());
    const std::vector<uint8_t> png(obj->png.begin(), obj->png.end());
    const cv::Mat decoded = cv::imdecode(png, cv::IMREAD_COLOR);
    ASSERT_EQ(decoded.size(), t.atlas_bgr.size());
    EXPECT_EQ(cv::norm(decoded, t.atlas_bgr, cv::NORM_INF), 0.0);  // PNG is lossless
    EXPECT_FALSE(texturedObjFiles(t, "a/b").isOk());

    auto ply = texturedPlyBytes(t, "model.png");
    ASSERT_TRUE(ply.isOk()) << ply.status().toString();
    EXPECT_NE(ply->find("comment TextureFile model.png\n"), std::string::npos);
    const std::filesystem::path path =
        std::filesystem::temp_directory_path() / ("facescan_texture_test_" + std::to_string(::getpid()) + ".ply");
    {
        std::ofstream f(path, std::ios::binary);
        f << *ply;
    }
    OpenMesh::TriMesh_ArrayKernelT<> back;
    back.request_vertex_texcoords2D();
    OpenMesh::IO::Options opt = OpenMesh::IO::Options::VertexTexCoord;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(back, path.string(), opt));
    std::filesystem::remove(path);
    ASSERT_TRUE(opt.vertex_has_texcoord());
    ASSERT_EQ(back.n_vertices(), t.mesh.vertexCount());
    for (const auto vh : back.vertices()) {
        const auto uv = back.texcoord2D(vh);
        const Eigen::Vector2f& want = t.uv[static_cast<size_t>(vh.idx())];
        ASSERT_NEAR(uv[0], want.x(), 1e-6f);
        ASSERT_NEAR(uv[1], 1.0f - want.y(), 1e-6f);
    }

    TexturedMesh untextured;
    untextured.mesh = mesh;
    EXPECT_FALSE(texturedPlyBytes(untextured, "x.png").isOk());
}

}  // namespace
}  // namespace facescan::recon
