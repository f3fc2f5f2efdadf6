// The synthetic Kinect v1: scene assembly (head, torso, wall), head trajectory, shading and ground truth.
// Rasterisation is in raster.cpp, the sensor noise in depth_noise.cpp.
#include "synth/kinect_simulator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>

#include "depth_noise.hpp"
#include "raster.hpp"

namespace facescan::synth {
namespace {

constexpr float kDegToRad = static_cast<float>(M_PI / 180.0);
// The head turns about the neck joint, below and behind the head-frame origin (metres, head frame).
const Eigen::Vector3f kPivotHead(0.0f, -0.07f, -0.03f);
// Linear-blend skinning of the neck: head-frame points above kSkinTopY move with the head, below kSkinBottomY
// with the body, so a bust's shoulders do not swing with the head (metres, head frame).
constexpr float kSkinTopY = -0.12f, kSkinBottomY = -0.18f;
// Periods (frames) of the slow body sway; the phases come from the seed.
constexpr float kSwayPeriodX = 230.0f, kSwayPeriodY = 170.0f;
// The occluder: ellipsoid semi-axes (a hand: 9 cm wide, 18 cm tall, 3 cm thick) and how far either side of the
// nose its centre starts and ends its crossing (metres).
constexpr float kOccluderRadiiM[3] = {0.045f, 0.09f, 0.015f};
constexpr float kOccluderSweepM = 0.17f;

using Vec3 = Eigen::Vector3f;

Vec3 toVec(const OpenMesh::Vec3f& v) { return {v[0], v[1], v[2]}; }

}  // namespace

NoiseParams NoiseParams::nearRangeStructuredLight() {
    NoiseParams p;
    p.axial_a_m = 0.0004f;
    p.axial_b_per_m = 0.01f;
    p.axial_z0_m = 0.2f;
    p.angle_coeff_m = 0.0001f / 3.0f;
    p.lateral_sigma_px = 0.5f;
    p.disparity_step_px = 1.0f / 64.0f;
    p.baseline_m = 0.025f;
    p.min_range_m = 0.2f;
    p.max_range_m = 0.5f;
    return p;
}

NoiseParams NoiseParams::activeStereo(float f_px) {
    NoiseParams p;
    p.principle = DepthPrinciple::kActiveStereo;
    // Intel's sigma = z^2 * subpixel / (f * baseline): the b of a + b (z - z0)^2 with a = 0, z0 = 0.
    constexpr float kSubpixel = 0.08f, kBaselineM = 0.055f;
    p.axial_a_m = 0.0f;
    p.axial_b_per_m = kSubpixel / (f_px * kBaselineM);
    p.axial_z0_m = 0.0f;
    p.baseline_m = kBaselineM;   // the right imager: its occlusion band is the stereo shadow
    p.disparity_step_px = 0.0f;  // sub-pixel disparity; its error is the subpixel RMS above
    p.lateral_sigma_px = 0.5f;
    p.min_range_m = 0.3f;
    p.max_range_m = 3.0f;
    p.pattern_range_m = 1.2f;
    return p;
}

NoiseParams NoiseParams::timeOfFlight() {
    NoiseParams p;
    p.principle = DepthPrinciple::kTimeOfFlight;
    p.axial_a_m = 0.0008f;
    p.axial_b_per_m = 0.0007f;
    p.axial_z0_m = 0.0f;
    p.lateral_sigma_px = 0.0f;  // each pixel measures its own footprint (its mixing is the flying pixels)
    p.disparity_step_px = 0.0f;
    p.depth_step_m = 0.001f;  // the depth image's 1 mm units
    p.shadow = false;         // the illuminator sits beside the lens: no shadow band worth modelling
    p.max_incidence_deg = 80.0f;
    p.min_range_m = 0.5f;
    p.max_range_m = 3.86f;
    p.dropout_rate = 0.002f;
    p.flying_pixel_rate = 0.5f;
    // Over about 4 cm of a face at 0.65 m (31 px at f = 504 px): an eye socket 5-8 mm behind its surroundings
    // reads 1.5-2.4 mm too far, at most 3 mm.
    p.multipath_window_px = 31;
    p.multipath_gain = 0.3f;
    p.multipath_max_m = 0.003f;
    return p;
}

Status NoiseParams::validate() const {
    if (!(axial_a_m >= 0 && axial_b_per_m >= 0 && angle_coeff_m >= 0 && lateral_sigma_px >= 0)) {
        return invalidArgument("noise: sigmas must be >= 0");
    }
    if (!(disparity_step_px >= 0 && disparity_step_px < 4))
        return invalidArgument("noise: disparity step in [0, 4) px");
    if (!(baseline_m > 0 && baseline_m < 1)) return invalidArgument("noise: baseline in (0, 1) m");
    if (!(max_incidence_deg > 0 && max_incidence_deg <= 90)) return invalidArgument("noise: max incidence in (0, 90]");
    if (!(min_range_m >= 0 && max_range_m > min_range_m)) return invalidArgument("noise: need 0 <= min < max range");
    if (!(dropout_rate >= 0 && dropout_rate < 1)) return invalidArgument("noise: dropout rate in [0, 1)");
    if (!(depth_step_m >= 0 && depth_step_m < 0.05f)) return invalidArgument("noise: depth step in [0, 0.05) m");
    if (!(pattern_range_m >= 0 && texture_min_grey >= 0)) {
        return invalidArgument("noise: pattern range and texture threshold must be >= 0");
    }
    if (texture_window_px < 3 || texture_window_px > 63 || texture_window_px % 2 == 0 || multipath_window_px < 3 ||
        multipath_window_px > 63 || multipath_window_px % 2 == 0) {
        return invalidArgument("noise: texture and multipath windows must be odd, 3-63 pixels");
    }
    if (!(flying_pixel_rate >= 0 && flying_pixel_rate <= 1 && flying_jump_m > 0 && multipath_gain >= 0 &&
          multipath_max_m >= 0)) {
        return invalidArgument("noise: flying-pixel rate in [0, 1], jump > 0, multipath gain and cap >= 0");
    }
    return Status::ok();
}

Status SequenceParams::validate() const {
    if (frames < 1 || frames > 1'000'000) return invalidArgument("synthetic: frames must be in [1, 1e6]");
    if (!(fps > 0 && fps <= 1000)) return invalidArgument("synthetic: fps must be in (0, 1000]");
    if (!(distance_m >= 0.3f && distance_m <= 5.0f)) return invalidArgument("synthetic: distance must be 0.3-5 m");
    if (!(std::abs(yaw_amplitude_deg) <= 80 && std::abs(pitch_amplitude_deg) <= 60)) {
        return invalidArgument("synthetic: yaw amplitude <= 80 deg, pitch amplitude <= 60 deg");
    }
    if (!(yaw_period_frames >= 2 && pitch_period_frames >= 2)) return invalidArgument("synthetic: periods >= 2 frames");
    if (!(sway_amplitude_m >= 0 && sway_amplitude_m <= 0.2f)) return invalidArgument("synthetic: sway in [0, 0.2] m");
    if (wall && !(wall_distance_m > distance_m + 0.25f && wall_distance_m < 10)) {
        return invalidArgument("synthetic: the wall must be at least 0.25 m behind the head and within 10 m");
    }
    if (!(std::isfinite(roll_deg) && std::abs(roll_deg) <= 360.0f && std::isfinite(roll_turn_deg) &&
          std::abs(roll_turn_deg) <= 360.0f))
        return invalidArgument("synthetic: |roll| and |roll_turn| <= 360 deg");
    if (gap_start_frame >= 0 && !(gap_frames >= 0 && gap_walk_frames >= 0 && std::abs(gap_turn_deg) <= 90 &&
                                  gap_side_m >= 0 && gap_side_m <= 5)) {
        return invalidArgument("synthetic: gap frames >= 0, walk frames >= 0, |turn| <= 90 deg, side 0-5 m");
    }
    if (occluder_start_frame >= 0 &&
        !(occluder_frames >= 1 && occluder_front_m >= 0.02f && occluder_front_m <= distance_m - 0.45f)) {
        return invalidArgument(
            "synthetic: occluder frames >= 1, 0.02 m <= occluder_front <= distance - 0.45 m (the sensor's range)");
    }
    return noise_model.validate();
}

struct KinectSimulator::Scene {
    // Vertices of head [0, head_end), torso [head_end, torso_end), wall [torso_end, wall_end), occluder
    // [wall_end, end).
    std::vector<Vec3> points, normals, colours;  // object frame; colours BGR 0-255
    std::vector<Eigen::Vector2f> uvs;            // head only, when textured
    std::vector<float> head_weight;              // skinning weight of head vertices (1 = rigid with the head)
    std::vector<Eigen::Vector3i> tris;
    std::vector<uint8_t> tri_label;  // PixelLabel
    int head_end = 0, torso_end = 0, wall_end = 0, head_tri_end = 0;
    std::vector<int> face_vertices;  // head vertices of the face box (brows to chin, cheek to cheek)
    float sway_phase_x = 0, sway_phase_y = 0;

    void addTorso(const recon::Mesh& head_mesh);
    void addWall(float distance_m, float half_m, int cells);
    void addOccluder();
};

// A torso continuing the head mesh downwards: an elliptic cylinder sized from the mesh's lowest band
// (at least shoulder-wide), capped by shoulders that slope up towards the neck. Body frame = head frame at rest.
void KinectSimulator::Scene::addTorso(const recon::Mesh& head_mesh) {
    float y_min = std::numeric_limits<float>::max();
    for (const auto vh : head_mesh.vertices()) y_min = std::min(y_min, head_mesh.point(vh)[1]);
    Eigen::AlignedBox3f band;
    for (const auto vh : head_mesh.vertices()) {
        if (head_mesh.point(vh)[1] < y_min + 0.02f) band.extend(toVec(head_mesh.point(vh)));
    }
    const float top_y = y_min + 0.02f, bottom_y = -0.9f;
    const float rx = std::max(0.19f, 0.5f * band.sizes().x()), rz = std::max(0.11f, 0.5f * band.sizes().z());
    const float cz = band.center().z();
    constexpr int kSectors = 72;
    constexpr int kCapRings = 6;
    const Vec3 shirt(110, 80, 60);
    const int base = static_cast<int>(points.size());
    // Rings from the bottom up: 0 bottom, 1 shoulder line, then the cap rings narrowing to the neck.
    std::vector<std::pair<float, Eigen::Vector2f>> rings = {{bottom_y, {rx, rz}}, {top_y, {rx, rz}}};
    for (int r = 1; r <= kCapRings; ++r) {
        const float t = static_cast<float>(r) / kCapRings;
        const float s = std::sqrt(1.0f - 0.8f * t * t);  // rounded shoulders
        rings.push_back({top_y + 0.05f * t, {std::max(0.06f, rx * s * (1 - 0.6f * t)), std::max(0.06f, rz * s)}});
    }
    for (const auto& [y, r] : rings) {
        for (int j = 0; j < kSectors; ++j) {
            const float phi = 2.0f * static_cast<float>(M_PI) * j / kSectors;
            const Vec3 n(std::sin(phi) / r.x(), 0.3f, std::cos(phi) / r.y());
            points.emplace_back(r.x() * std::sin(phi), y, cz + r.y() * std::cos(phi));
            normals.push_back(n.normalized());
            colours.push_back(shirt);
        }
    }
    for (int i = 0; i + 1 < static_cast<int>(rings.size()); ++i) {
        for (int j = 0; j < kSectors; ++j) {
            const int a = base + i * kSectors + j, b = base + i * kSectors + (j + 1) % kSectors;
            tris.emplace_back(a, b, b + kSectors);
            tris.emplace_back(a, b + kSectors, a + kSectors);
            tri_label.push_back(static_cast<uint8_t>(PixelLabel::kBody));
            tri_label.push_back(static_cast<uint8_t>(PixelLabel::kBody));
        }
    }
}

// The wall: a large square facing the camera (camera frame at rest), `half` metres each side of the optical axis,
// beyond the frustum on every side, as cells x cells quads (the rasteriser drops a triangle with a corner behind
// the camera, so a wall seen from the side needs small ones).
void KinectSimulator::Scene::addWall(float distance_m, float half, int cells) {
    const int base = static_cast<int>(points.size());
    for (int i = 0; i <= cells; ++i) {
        for (int j = 0; j <= cells; ++j) {
            points.emplace_back(half * (2.0f * j / cells - 1.0f), half * (2.0f * i / cells - 1.0f), distance_m);
            normals.emplace_back(0, 0, -1);
            colours.emplace_back(175, 190, 200);
        }
    }
    for (int i = 0; i < cells; ++i) {
        for (int j = 0; j < cells; ++j) {
            const int a = base + i * (cells + 1) + j, b = a + 1, c = a + cells + 2, d = a + cells + 1;
            tris.emplace_back(a, b, c);
            tris.emplace_back(a, c, d);
        }
    }
    tri_label.insert(tri_label.end(), 2 * cells * cells, static_cast<uint8_t>(PixelLabel::kNone));
}

// The occluder: a flattened ellipsoid about the size of a hand (9 x 18 x 3 cm), skin-coloured, in its own frame
// (axes of the camera), centred on the origin.
void KinectSimulator::Scene::addOccluder() {
    const Vec3 radii(kOccluderRadiiM[0], kOccluderRadiiM[1], kOccluderRadiiM[2]);
    constexpr int kSectors = 32, kRings = 16;
    const int base = static_cast<int>(points.size());
    for (int r = 0; r <= kRings; ++r) {
        const float theta = static_cast<float>(M_PI) * r / kRings;
        for (int j = 0; j < kSectors; ++j) {
            const float phi = 2.0f * static_cast<float>(M_PI) * j / kSectors;
            const Vec3 unit(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
            points.push_back(unit.cwiseProduct(radii));
            normals.push_back(unit.cwiseQuotient(radii).normalized());
            colours.emplace_back(120, 150, 205);
        }
    }
    for (int r = 0; r < kRings; ++r) {
        for (int j = 0; j < kSectors; ++j) {
            const int a = base + r * kSectors + j, b = base + r * kSectors + (j + 1) % kSectors;
            tris.emplace_back(a, b, b + kSectors);
            tris.emplace_back(a, b + kSectors, a + kSectors);
            tri_label.insert(tri_label.end(), 2, static_cast<uint8_t>(PixelLabel::kOccluder));
        }
    }
}

KinectSimulator::KinectSimulator(HeadModel head, SequenceParams params, recon::Intrinsics intrinsics)
    : head_(std::move(head)), params_(params), intrinsics_(intrinsics), scene_(std::make_unique<Scene>()) {
    Scene& s = *scene_;
    recon::Mesh& m = head_.mesh;
    if (!m.has_vertex_normals()) m.request_vertex_normals();
    if (!m.has_face_normals()) m.request_face_normals();
    m.update_face_normals();
    m.update_vertex_normals();
    const bool textured = !head_.texture_bgr.empty() && m.has_vertex_texcoords2D();
    for (const auto vh : m.vertices()) {
        const Vec3 p = toVec(m.point(vh));
        s.points.push_back(p);
        s.normals.push_back(toVec(m.normal(vh)));
        const auto c = m.has_vertex_colors() ? m.color(vh) : recon::Mesh::Color(200, 170, 150);
        s.colours.emplace_back(c[0], c[1], c[2]);
        if (textured) s.uvs.emplace_back(m.texcoord2D(vh)[0], m.texcoord2D(vh)[1]);
        s.head_weight.push_back(std::clamp((p.y() - kSkinBottomY) / (kSkinTopY - kSkinBottomY), 0.0f, 1.0f));
        const Vec3 d = p - head_.nose_tip_head;
        if (std::abs(d.x()) < 0.065f && d.y() > -0.08f && d.y() < 0.055f && d.z() > -0.08f && m.normal(vh)[2] > 0.25f) {
            s.face_vertices.push_back(vh.idx());
        }
    }
    for (const auto fh : m.faces()) {
        Eigen::Vector3i t;
        int k = 0;
        float y_sum = 0;
        for (const auto vh : m.fv_range(fh)) {
            if (k < 3) t[k] = vh.idx();
            y_sum += m.point(vh)[1];
            ++k;
        }
        if (k != 3) continue;
        s.tris.push_back(t);
        s.tri_label.push_back(
            static_cast<uint8_t>(y_sum / 3 > head_.neck_cut_y_m ? PixelLabel::kHead : PixelLabel::kBody));
    }
    s.head_end = static_cast<int>(s.points.size());
    s.head_tri_end = static_cast<int>(s.tris.size());
    if (params_.torso) s.addTorso(m);
    s.torso_end = static_cast<int>(s.points.size());
    // A camera orbiting the head sees the wall obliquely and from the side: a wider wall keeps it behind the head.
    if (params_.wall) {
        if (params_.orbit) {
            s.addWall(params_.wall_distance_m, 3.0f * params_.wall_distance_m, 24);
        } else {
            s.addWall(params_.wall_distance_m, 1.2f * params_.wall_distance_m, 1);
        }
    }
    s.wall_end = static_cast<int>(s.points.size());
    if (params_.occluder_start_frame >= 0) s.addOccluder();
    const uint64_t r = detail::mix64(params_.seed ^ 0x5157A7ull);
    s.sway_phase_x = static_cast<float>(r & 0xFFFF) / 65536.0f * 2.0f * static_cast<float>(M_PI);
    s.sway_phase_y = static_cast<float>((r >> 16) & 0xFFFF) / 65536.0f * 2.0f * static_cast<float>(M_PI);
}

KinectSimulator::~KinectSimulator() = default;
KinectSimulator::KinectSimulator(KinectSimulator&&) noexcept = default;
KinectSimulator& KinectSimulator::operator=(KinectSimulator&&) noexcept = default;

// Rotation by `deg` about the head-frame axis `axis` through the neck pivot (head frame at rest).
static recon::Pose aboutNeck(const Vec3& axis, float deg) {
    recon::Pose m = recon::Pose::Identity();
    m.linear() = Eigen::AngleAxisf(deg * kDegToRad, axis).toRotationMatrix();
    m.translation() = kPivotHead - m.linear() * kPivotHead;
    return m;
}

// The rolled camera from the upright one: a rotation about the optical axis (z). With y down in the image, a positive
// angle turns the scene clockwise on screen.
static recon::Pose rollOf(float roll_deg) {
    recon::Pose r = recon::Pose::Identity();
    r.linear() = Eigen::AngleAxisf(roll_deg * kDegToRad, Vec3::UnitZ()).toRotationMatrix();
    return r;
}

// 0 -> 1 smoothly (zero slope at both ends) as t goes 0 -> 1.
static float smoothStep(float t) {
    t = std::clamp(t, 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

recon::Pose KinectSimulator::bodyPoseAt(int index) const {
    const SequenceParams& p = params_;
    const float two_pi = 2.0f * static_cast<float>(M_PI);
    const float px = scene_->sway_phase_x, py = scene_->sway_phase_y;
    const Vec3 sway(p.sway_amplitude_m * (std::sin(two_pi * index / kSwayPeriodX + px) - std::sin(px)),
                    p.sway_amplitude_m * (std::sin(two_pi * index / kSwayPeriodY + py) - std::sin(py)), 0);
    // The gap: walk out over W frames, stay out G frames, walk back in over W frames; turned on the way back.
    float side = 0.0f, turn = 0.0f;
    if (p.gap_start_frame >= 0 && index >= p.gap_start_frame) {
        const int w = p.gap_walk_frames, g = p.gap_frames, t = index - p.gap_start_frame;
        const float walk = static_cast<float>(w + 1);
        if (p.gap_leave) {
            if (t < w) {
                side = static_cast<float>(t + 1) / walk;
            } else if (t < w + g) {
                side = 1.0f;
            } else if (t < 2 * w + g) {
                side = static_cast<float>(2 * w + g - t) / walk;
            }
            turn = t >= w + g ? 1.0f : 0.0f;
        } else {
            turn = smoothStep(static_cast<float>(t + 1) / static_cast<float>(2 * w + g + 1));
        }
    }
    recon::Pose T = recon::Pose::Identity();
    T.translation() = Vec3(side * p.gap_side_m, 0, p.distance_m) + sway;
    // Head frame (y up, face along +z) to camera (y down, looking along +z): 180 deg about x.
    T.linear() = Eigen::Vector3f(1, -1, -1).asDiagonal();
    if (turn != 0.0f) T = T * aboutNeck(Vec3::UnitY(), turn * p.gap_turn_deg);
    if (p.orbit) T = cameraFromWorldAt(index) * T;
    // The roll turns the camera about its own optical axis, after everything else.
    if (const float roll = rollDegAt(index); roll != 0.0f) T = rollOf(roll) * T;
    return T;
}

float KinectSimulator::rollDegAt(int index) const {
    if (params_.roll_turn_deg == 0.0f) return params_.roll_deg;
    const float t = params_.frames > 1 ? static_cast<float>(index) / static_cast<float>(params_.frames - 1) : 0.0f;
    return params_.roll_deg + params_.roll_turn_deg * t;
}

// The yaw and pitch sweeps (degrees) of frame `index`: the head's turn, or the camera's orbit.
float KinectSimulator::sweepYawDeg(int index) const {
    const float two_pi = 2.0f * static_cast<float>(M_PI);
    return params_.yaw_amplitude_deg * std::sin(two_pi * index / params_.yaw_period_frames);
}

float KinectSimulator::sweepPitchDeg(int index) const {
    const float phase = 2.0f * static_cast<float>(M_PI) * index / params_.pitch_period_frames;
    return params_.pitch_amplitude_deg * (params_.nod ? 0.5f * (1.0f - std::cos(phase)) : std::sin(phase));
}

float KinectSimulator::yawDegAt(int index) const { return params_.orbit ? 0.0f : sweepYawDeg(index); }

float KinectSimulator::pitchDegAt(int index) const { return params_.orbit ? 0.0f : sweepPitchDeg(index); }

recon::Pose KinectSimulator::cameraFromWorldAt(int index) const {
    if (!params_.orbit) return recon::Pose::Identity();
    // The camera turns about the head's middle (distance_m ahead of its rest pose): yaw about the vertical, then
    // pitch about the horizontal axis, keeping its distance to the head.
    const Vec3 centre(0, 0, params_.distance_m);
    recon::Pose T_world_camera = recon::Pose::Identity();
    T_world_camera.linear() = (Eigen::AngleAxisf(sweepYawDeg(index) * kDegToRad, Vec3::UnitY()) *
                               Eigen::AngleAxisf(sweepPitchDeg(index) * kDegToRad, Vec3::UnitX()))
                                  .toRotationMatrix();
    T_world_camera.translation() = centre - T_world_camera.linear() * centre;
    return T_world_camera.inverse();
}

recon::Pose KinectSimulator::poseAt(int index) const {
    if (params_.orbit) return bodyPoseAt(index);  // the head does not turn; the camera moves
    const Eigen::Matrix3f R = (Eigen::AngleAxisf(yawDegAt(index) * kDegToRad, Vec3::UnitY()) *
                               Eigen::AngleAxisf(pitchDegAt(index) * kDegToRad, Vec3::UnitX()))
                                  .toRotationMatrix();
    recon::Pose motion = recon::Pose::Identity();  // rotation about the neck pivot, in the head frame
    motion.linear() = R;
    motion.translation() = kPivotHead - R * kPivotHead;
    return bodyPoseAt(index) * motion;
}

bool KinectSimulator::occluderActiveAt(int index) const {
    const int start = params_.occluder_start_frame;
    return start >= 0 && index >= start && index < start + params_.occluder_frames;
}

Eigen::Vector3f KinectSimulator::occluderCentreAt(int index) const {
    // Across the face at the nose's height, from the person's right (upright camera -x) to their left.
    const recon::Pose roll = rollOf(rollDegAt(index));
    const Vec3 nose = roll.inverse() * (poseAt(index) * head_.nose_tip_head);
    const float t = params_.occluder_frames > 1 ? static_cast<float>(index - params_.occluder_start_frame) /
                                                      static_cast<float>(params_.occluder_frames - 1)
                                                : 0.5f;
    return roll * Vec3(nose.x() + kOccluderSweepM * (2.0f * t - 1.0f), nose.y(), nose.z() - params_.occluder_front_m);
}

recon::Mesh KinectSimulator::headInFirstCamera() const {
    recon::Mesh out = head_.mesh;
    const recon::Pose T = poseAt(0);
    for (const auto vh : out.vertices()) {
        const Vec3 p = T * toVec(out.point(vh));
        out.point(vh) = recon::Mesh::Point(p.x(), p.y(), p.z());
    }
    out.update_face_normals();
    out.update_vertex_normals();
    return out;
}

std::vector<uint8_t> KinectSimulator::headVertexMask(float below_cut_m) const {
    std::vector<uint8_t> mask(head_.mesh.n_vertices(), 0);
    for (const auto vh : head_.mesh.vertices())
        mask[static_cast<size_t>(vh.idx())] = head_.mesh.point(vh)[1] >= head_.neck_cut_y_m - below_cut_m;
    return mask;
}

void KinectSimulator::render(int index, recon::RgbdFrame& out, FrameTruth* truth) const {
    const Scene& s = *scene_;
    const recon::Intrinsics& k = intrinsics_;
    const recon::Pose T_camera_head = poseAt(index);
    const recon::Pose T_camera_body = bodyPoseAt(index);

    // Vertices into the camera frame; the neck blends between head and body (linear-blend skinning).
    std::vector<Vec3> pc(s.points.size()), nc(s.points.size());
    for (int i = 0; i < s.head_end; ++i) {
        const float w = s.head_weight[i];
        if (w >= 1.0f) {
            pc[i] = T_camera_head * s.points[i];
            nc[i] = T_camera_head.linear() * s.normals[i];
        } else {
            pc[i] = w * (T_camera_head * s.points[i]) + (1 - w) * (T_camera_body * s.points[i]);
            nc[i] = (w * T_camera_head.linear() * s.normals[i] + (1 - w) * T_camera_body.linear() * s.normals[i])
                        .normalized();
        }
    }
    for (int i = s.head_end; i < s.torso_end; ++i) {
        pc[i] = T_camera_body * s.points[i];
        nc[i] = T_camera_body.linear() * s.normals[i];
    }
    // The wall and the lamp are the room's: they move with the orbiting camera and roll with it too.
    const recon::Pose T_camera_world = rollOf(rollDegAt(index)) * cameraFromWorldAt(index);
    for (int i = s.torso_end; i < s.wall_end; ++i) {
        pc[i] = T_camera_world * s.points[i];
        nc[i] = T_camera_world.linear() * s.normals[i];
    }
    // The occluder when it is in the scene; otherwise behind the camera, where the rasteriser skips it.
    const Vec3 occluder_at = occluderActiveAt(index) ? occluderCentreAt(index) : Vec3(0, 0, -10);
    for (int i = s.wall_end; i < static_cast<int>(s.points.size()); ++i) {
        pc[i] = s.points[i] + occluder_at;
        nc[i] = s.normals[i];
    }

    detail::GBuffer g;
    detail::rasterise(pc, s.tris, k, g);

    const int w = k.width_px, h = k.height_px;
    out.colour_bgr.create(h, w, CV_8UC3);
    cv::Mat label(h, w, CV_8U), cos_incidence(h, w, CV_32F);
    const cv::Mat& tex = head_.texture_bgr;
    const bool textured = !s.uvs.empty();
    // A lamp above and left of the camera; Lambert shading with ambient light.
    const Vec3 lamp = rollOf(rollDegAt(index)) * Vec3(-0.25f, -0.35f, 0.0f);
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
        for (int v = rows.start; v < rows.end; ++v) {
            const int* trow = g.tri.ptr<int>(v);
            const float* zrow = g.depth_m.ptr<float>(v);
            const cv::Vec2f* brow = g.bary.ptr<cv::Vec2f>(v);
            cv::Vec3b* crow = out.colour_bgr.ptr<cv::Vec3b>(v);
            for (int u = 0; u < w; ++u) {
                const int t = trow[u];
                label.at<uint8_t>(v, u) = 0;
                cos_incidence.at<float>(v, u) = 0;
                if (t < 0) {
                    crow[u] = cv::Vec3b(0, 0, 0);
                    continue;
                }
                const Eigen::Vector3i& tri = s.tris[t];
                const float b1 = brow[u][0], b2 = brow[u][1], b0 = 1.0f - b1 - b2;
                const Vec3 p = k.backProject(static_cast<float>(u), static_cast<float>(v), zrow[u]);
                Vec3 n = (b0 * nc[tri[0]] + b1 * nc[tri[1]] + b2 * nc[tri[2]]).normalized();
                const Vec3 view = -p.normalized();
                float cos_view = n.dot(view);
                if (cos_view < 0) n = -n, cos_view = -cos_view;  // back side (open mesh): shade the side we see
                cos_incidence.at<float>(v, u) = cos_view;
                label.at<uint8_t>(v, u) = s.tri_label[t];
                Vec3 albedo;
                if (textured && t < s.head_tri_end) {
                    const Eigen::Vector2f uv = b0 * s.uvs[tri[0]] + b1 * s.uvs[tri[1]] + b2 * s.uvs[tri[2]];
                    // The scan's texture coordinates have v up (row 0 of the image is v = 1).
                    const float x = std::clamp(uv.x(), 0.0f, 1.0f) * (tex.cols - 1);
                    const float y = (1.0f - std::clamp(uv.y(), 0.0f, 1.0f)) * (tex.rows - 1);
                    const int x0 = std::min(static_cast<int>(x), tex.cols - 2),
                              y0 = std::min(static_cast<int>(y), tex.rows - 2);
                    const float fx = x - x0, fy = y - y0;
                    const cv::Vec3b c00 = tex.at<cv::Vec3b>(y0, x0), c01 = tex.at<cv::Vec3b>(y0, x0 + 1);
                    const cv::Vec3b c10 = tex.at<cv::Vec3b>(y0 + 1, x0), c11 = tex.at<cv::Vec3b>(y0 + 1, x0 + 1);
                    for (int c = 0; c < 3; ++c) {
                        albedo[c] =
                            (1 - fy) * ((1 - fx) * c00[c] + fx * c01[c]) + fy * ((1 - fx) * c10[c] + fx * c11[c]);
                    }
                } else {
                    albedo = b0 * s.colours[tri[0]] + b1 * s.colours[tri[1]] + b2 * s.colours[tri[2]];
                }
                const float diffuse = std::max(0.0f, n.dot((lamp - p).normalized()));
                const float shade = params_.shading ? 0.35f + 0.75f * diffuse : 1.0f;
                for (int c = 0; c < 3; ++c) crow[u][c] = cv::saturate_cast<uint8_t>(albedo[c] * shade);
            }
        }
    });

    if (params_.noise) {
        detail::applyDepthNoise(
            params_.noise_model, k, g.depth_m, cos_incidence, out.colour_bgr,
            detail::mix64(params_.seed) ^ detail::mix64(static_cast<uint64_t>(index) + 0x1234567ull), out.depth_m);
    } else {
        g.depth_m.copyTo(out.depth_m);
    }
    out.timestamp_ns = static_cast<int64_t>(std::llround(index * 1e9 / params_.fps));

    if (truth) {
        truth->T_camera_head = T_camera_head;
        truth->label = label;
        truth->depth_true_m = g.depth_m;
        truth->yaw_deg = yawDegAt(index);
        truth->pitch_deg = pitchDegAt(index);
        truth->head_pixels = cv::countNonZero(label == static_cast<uint8_t>(PixelLabel::kHead));
        // Face box: the visible face-region vertices (not hidden in the ideal depth), projected.
        int u_lo = w, v_lo = h, u_hi = -1, v_hi = -1, visible = 0;
        for (const int i : s.face_vertices) {
            const Vec3& p = pc[i];
            if (p.z() <= 0) continue;
            const Eigen::Vector2f px = k.project(p);
            const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
            if (!k.contains(u, v) || std::abs(g.depth_m.at<float>(v, u) - p.z()) > 0.01f) continue;
            u_lo = std::min(u_lo, u), u_hi = std::max(u_hi, u), v_lo = std::min(v_lo, v), v_hi = std::max(v_hi, v);
            ++visible;
        }
        const bool enough = visible * 4 >= static_cast<int>(s.face_vertices.size());
        truth->face_box_px = enough ? cv::Rect(u_lo, v_lo, u_hi - u_lo + 1, v_hi - v_lo + 1) : cv::Rect();
    }
}

}  // namespace facescan::synth
