// A procedural head of our own, so that the synthetic Kinect works on a machine without the real scan.
// An ellipsoidal skull displaced by smooth bumps (nose, brows, eye sockets, cheeks, lips, chin, ears) plus a
// neck tube, painted with skin, hair, brows, eyes and lips so that a frontal-face detector has the dark-eye /
// bright-nose-bridge pattern it looks for. Head frame of head_model.hpp: nose tip at (0, 0, 0.10) m.
#include <algorithm>
#include <cmath>
#include <vector>

#include "synth/head_model.hpp"

namespace facescan::synth {
namespace {

float gauss2(float x, float y, float cx, float cy, float sx, float sy) {
    const float dx = (x - cx) / sx, dy = (y - cy) / sy;
    return std::exp(-0.5f * (dx * dx + dy * dy));
}

// Skull: centre and semi-axes (metres); the face is flatter than the back of the head.
constexpr float kCentreY = 0.02f, kCentreZ = 0.0f;
constexpr float kSemiX = 0.076f, kSemiYUp = 0.118f, kSemiYDown = 0.105f, kSemiZFront = 0.082f, kSemiZBack = 0.105f;

// Forward displacement (metres, along +z) of the face at head-frame (x, y): the facial relief.
float faceRelief(float x, float y) {
    const float ax = std::abs(x);
    float d = 0;
    d += 0.019f * gauss2(x, y, 0, 0.004f, 0.010f, 0.011f);         // nose tip
    d += 0.013f * gauss2(x, y, 0, 0.022f, 0.0065f, 0.016f);        // nose bridge
    d -= 0.004f * gauss2(ax, y, 0.011f, -0.004f, 0.004f, 0.004f);  // alae crease
    d -= 0.011f * gauss2(ax, y, 0.031f, 0.029f, 0.014f, 0.010f);   // eye sockets
    d += 0.0045f * gauss2(ax, y, 0.030f, 0.047f, 0.022f, 0.006f);  // brow ridge
    d += 0.004f * gauss2(ax, y, 0.045f, 0.0f, 0.014f, 0.014f);     // cheekbones
    d += 0.0045f * gauss2(x, y, 0, -0.031f, 0.020f, 0.0045f);      // upper lip
    d += 0.0040f * gauss2(x, y, 0, -0.043f, 0.018f, 0.005f);       // lower lip
    d -= 0.0025f * gauss2(x, y, 0, -0.037f, 0.022f, 0.0015f);      // mouth line
    d += 0.0060f * gauss2(x, y, 0, -0.070f, 0.017f, 0.010f);       // chin
    return d;
}

// Outward displacement (metres, along +-x) of the sides of the head at (y, z): the ears.
float earRelief(float y, float z) {
    return 0.013f * gauss2(z, y, -0.012f, 0.012f, 0.011f, 0.024f) -
           0.004f * gauss2(z, y, -0.010f, 0.010f, 0.005f, 0.010f);
}

// Paint (BGR) of a skull point at (x, y, z) with outward direction n.
recon::Mesh::Color paint(float x, float y, float z) {
    const recon::Mesh::Color skin(135, 160, 205), hair(30, 40, 55), brow(35, 45, 60), lips(95, 95, 175);
    const float ax = std::abs(x);
    // Hair: above the hairline at the front, everywhere above the ears at the back.
    const float hairline_y = z > 0.04f ? 0.078f : (z > -0.02f ? 0.05f : -0.04f);
    if (y > hairline_y) return hair;
    if (z > 0.04f) {
        // Eyebrows.
        if (std::abs(y - 0.046f) < 0.0035f && ax > 0.012f && ax < 0.050f) return brow;
        // Eyes: sclera ellipse, dark iris/pupil.
        const float ex = (ax - 0.031f) / 0.013f, ey = (y - 0.028f) / 0.006f;
        if (ex * ex + ey * ey < 1.0f) {
            const float ir = std::hypot(ax - 0.031f, y - 0.028f);
            if (ir < 0.0055f) return recon::Mesh::Color(40, 35, 30);
            return recon::Mesh::Color(215, 220, 225);
        }
        // Shade of the eye sockets and the nostrils.
        const float socket = gauss2(ax, y, 0.031f, 0.028f, 0.016f, 0.010f);
        if (std::abs(y + 0.037f) < 0.011f && ax < 0.022f - 0.004f * std::abs(y + 0.037f) / 0.011f) return lips;
        if (std::abs(y + 0.003f) < 0.003f && ax > 0.004f && ax < 0.011f) return recon::Mesh::Color(50, 60, 90);
        const float k = 1.0f - 0.35f * socket;
        return recon::Mesh::Color(static_cast<unsigned char>(skin[0] * k), static_cast<unsigned char>(skin[1] * k),
                                  static_cast<unsigned char>(skin[2] * k));
    }
    return skin;
}

}  // namespace

HeadModel builtinHead() {
    constexpr int kRings = 180;    // polar steps (top to bottom)
    constexpr int kSectors = 240;  // azimuth steps
    constexpr float kPi = 3.14159265358979f;
    HeadModel head;
    head.name = "builtin";
    recon::Mesh& mesh = head.mesh;

    auto skull_point = [&](float theta, float phi) {
        const Eigen::Vector3f d(std::sin(theta) * std::sin(phi), std::cos(theta), std::sin(theta) * std::cos(phi));
        const float ay = d.y() > 0 ? kSemiYUp : kSemiYDown, az = d.z() > 0 ? kSemiZFront : kSemiZBack;
        const float r =
            1.0f / std::sqrt(std::pow(d.x() / kSemiX, 2.f) + std::pow(d.y() / ay, 2.f) + std::pow(d.z() / az, 2.f));
        Eigen::Vector3f p = Eigen::Vector3f(0, kCentreY, kCentreZ) + r * d;
        // The relief fades in over the front and the ears over the sides, so the surface stays smooth.
        const float front = std::clamp(d.z() * 2.5f - 0.5f, 0.0f, 1.0f);
        p.z() += front * faceRelief(p.x(), p.y());
        const float side = std::clamp(std::abs(d.x()) * 3.0f - 2.0f, 0.0f, 1.0f);
        p.x() += (p.x() > 0 ? 1.f : -1.f) * side * earRelief(p.y(), p.z());
        return p;
    };
    std::vector<recon::Mesh::VertexHandle> grid;
    auto add = [&](const Eigen::Vector3f& p) {
        const auto vh = mesh.add_vertex(recon::Mesh::Point(p.x(), p.y(), p.z()));
        mesh.set_color(vh, paint(p.x(), p.y(), p.z()));
        return vh;
    };
    const auto top = add(skull_point(0, 0));
    for (int i = 1; i < kRings; ++i) {
        for (int j = 0; j < kSectors; ++j) {
            grid.push_back(add(skull_point(kPi * i / kRings, 2 * kPi * j / kSectors)));
        }
    }
    const auto bottom = add(skull_point(kPi, 0));
    auto at = [&](int ring, int sector) { return grid[(ring - 1) * kSectors + (sector % kSectors)]; };
    // Winding: outward normals (counter-clockwise seen from outside).
    for (int j = 0; j < kSectors; ++j) mesh.add_face(top, at(1, j), at(1, j + 1));
    for (int i = 1; i + 1 < kRings; ++i) {
        for (int j = 0; j < kSectors; ++j) {
            mesh.add_face(at(i, j), at(i + 1, j), at(i + 1, j + 1));
            mesh.add_face(at(i, j), at(i + 1, j + 1), at(i, j + 1));
        }
    }
    for (int j = 0; j < kSectors; ++j) mesh.add_face(at(kRings - 1, j), bottom, at(kRings - 1, j + 1));

    // Neck: an open tube from inside the jaw down to the shoulders (the simulator's torso continues it).
    constexpr int kNeckRings = 16, kNeckSectors = 64;
    constexpr float kNeckTopY = -0.05f, kNeckBottomY = -0.22f, kNeckZ = -0.025f, kNeckRx = 0.055f, kNeckRz = 0.06f;
    std::vector<recon::Mesh::VertexHandle> neck;
    for (int i = 0; i <= kNeckRings; ++i) {
        const float y = kNeckTopY + (kNeckBottomY - kNeckTopY) * i / kNeckRings;
        for (int j = 0; j < kNeckSectors; ++j) {
            const float phi = 2 * kPi * j / kNeckSectors;
            const auto vh =
                mesh.add_vertex(recon::Mesh::Point(kNeckRx * std::sin(phi), y, kNeckZ + kNeckRz * std::cos(phi)));
            mesh.set_color(vh, recon::Mesh::Color(125, 150, 195));
            neck.push_back(vh);
        }
    }
    auto nk = [&](int i, int j) { return neck[i * kNeckSectors + (j % kNeckSectors)]; };
    for (int i = 0; i < kNeckRings; ++i) {
        for (int j = 0; j < kNeckSectors; ++j) {
            mesh.add_face(nk(i, j), nk(i + 1, j), nk(i + 1, j + 1));
            mesh.add_face(nk(i, j), nk(i + 1, j + 1), nk(i, j + 1));
        }
    }
    mesh.update_face_normals();
    mesh.update_vertex_normals();
    // The nose tip is the most forward point; translate so it sits at (0, 0, 0.10) as the head frame demands.
    float best_z = -1;
    OpenMesh::Vec3f nose(0, 0, 0);
    for (const auto vh : mesh.vertices()) {
        if (mesh.point(vh)[2] > best_z) best_z = mesh.point(vh)[2], nose = mesh.point(vh);
    }
    const OpenMesh::Vec3f shift(-nose[0], -nose[1], 0.1f - nose[2]);
    for (const auto vh : mesh.vertices()) mesh.point(vh) += shift;
    head.nose_tip_head = Eigen::Vector3f(0, 0, 0.1f);
    head.neck_cut_y_m = -0.09f;  // the chin ends ~0.08 m below the nose tip
    return head;
}

}  // namespace facescan::synth
