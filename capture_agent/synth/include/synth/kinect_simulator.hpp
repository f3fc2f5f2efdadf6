// The synthetic Kinect v1: THE renderer of the project (tests, capture agent `synthetic` source, benchmarks).
// A head turns in front of a fixed camera (or the camera moves around a still head), with a torso below it and a wall
// behind it; the output is 640x480 depth (metres) and colour registered to depth, with the Kinect v1 noise model of
// docs/design.md s6 (Nguyen, Izadi, Lovell 2012), plus ground truth (pose, labels, noise-free depth, face box). Events
// for robustness tests: a nod onto the chest, a gap in which the subject walks out of view and comes back turned, and a
// hand-sized occluder crossing in front of the face.
#pragma once

#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "recon/camera.hpp"
#include "recon/frame.hpp"
#include "recon/status.hpp"
#include "synth/head_model.hpp"

namespace facescan::synth {

// How the synthetic camera measures depth; each principle has its own failure modes (depth_noise.hpp).
enum class DepthPrinciple : uint8_t {
    kStructuredLight,  // projector + camera, disparity quantised: projector shadows (Kinect v1, TrueDepth)
    kActiveStereo,     // two imagers + pattern projector: holes where matching finds no texture, stereo shadows
    kTimeOfFlight,     // modulated light, phase per pixel: flying pixels at silhouettes, multipath in concavities
};

// Depth noise. The defaults are the Kinect v1 (Nguyen, Izadi, Lovell 2012; docs/design.md s6); the factories give
// the other synthetic sensors. Axial sigma has the same form for all: a + b (z - z0)^2 + angle term.
struct NoiseParams {
    DepthPrinciple principle = DepthPrinciple::kStructuredLight;
    float axial_a_m = 0.0012f;         // metres; sigma_z = a + b (z - z0)^2 + angle term
    float axial_b_per_m = 0.0019f;     // 1/metre
    float axial_z0_m = 0.4f;           // metres
    float angle_coeff_m = 0.0001f;     // metres * sqrt(m); angle term = c / sqrt(z) * theta^2 / (pi/2 - theta)^2
    float lateral_sigma_px = 0.8f;     // pixels, std of the lateral (x, y) displacement of each sample
    float disparity_step_px = 0.125f;  // pixels, disparity quantisation (1/8 px)
    float baseline_m = 0.075f;         // metres, IR projector to IR camera (projector at +x of the camera)
    float max_incidence_deg = 75.0f;   // degrees, surfaces more oblique than this return no depth
    float min_range_m = 0.4f;          // metres, nearest measurable depth
    float max_range_m = 4.0f;          // metres, farthest measurable depth
    float dropout_rate = 0.005f;       // share of valid pixels randomly lost, [0, 1)
    bool shadow = true;                // invalidate pixels the projector cannot see (edge shadow band)
    float depth_step_m = 0.0f;         // metres, output quantisation of a sensor that reports depth directly
    // Active stereo: a pixel is matched where the projected pattern is bright enough, i.e. the frontal-equivalent
    // distance z / sqrt(cos incidence) is within pattern_range_m, or where the surface has its own texture (grey
    // standard deviation over a texture_window_px square of at least texture_min_grey, 0-255 levels).
    float pattern_range_m = 0.0f;  // metres
    int texture_window_px = 7;     // pixels (odd)
    float texture_min_grey = 6.0f;
    // Time of flight. Flying pixels: a pixel whose footprint straddles a depth jump of more than flying_jump_m
    // returns a phase mix of the two surfaces with probability flying_pixel_rate. Multipath: light scattered
    // between the walls of a concavity lengthens the path; bias = multipath_gain * (how far the pixel lies behind
    // the mean surface of a multipath_window_px square), at most multipath_max_m, only where that window holds no
    // depth jump.
    float flying_pixel_rate = 0.0f;  // [0, 1]
    float flying_jump_m = 0.05f;     // metres
    float multipath_gain = 0.0f;     // metres of bias per metre of concavity
    float multipath_max_m = 0.0f;    // metres
    int multipath_window_px = 15;    // pixels (odd)

    // A near-range structured-light camera like a phone's TrueDepth front camera (0.2-0.5 m). There is no
    // published noise model of it that this project could check; the figures are assumed, in the same form as
    // the Kinect's: axial sigma 0.4 mm at 0.2 m growing to 0.5 mm at 0.3 m (a + b (z - z0)^2 with a = 0.4 mm,
    // b = 0.01 /m, z0 = 0.2 m) and 1.3 mm at 0.5 m, the Kinect's incidence term scaled by the same 1/3, half a
    // pixel of lateral jitter, a 25 mm projector baseline and 1/64 px disparity steps (0.26 mm at 0.3 m).
    static NoiseParams nearRangeStructuredLight();
    // An active stereo camera like the RealSense D415 at 848x480 (focal length f_px there), from Intel's RMS error
    // of stereo depth (Grunnet-Jepsen et al., "Tuning depth cameras for best performance", Intel RealSense white
    // paper, 2019): sigma = z^2 * subpixel / (f * baseline), subpixel 0.08 px, baseline 55 mm. Its range 0.3-3 m
    // is Intel's; the pattern's reach (1.2 m on a frontal surface), the texture threshold, lateral jitter and
    // incidence limit are assumed.
    static NoiseParams activeStereo(float f_px);
    // A time-of-flight camera like the Azure Kinect in NFOV unbinned mode (0.5-3.86 m, 1 mm depth units).
    // Microsoft's specification (Azure Kinect DK hardware specification / "Azure Kinect DK depth camera") bounds
    // the random error at std <= 17 mm and the systematic error at < 11 mm + 0.1 % of distance, both confirmed by
    // Toelgyessy et al., "Evaluation of the Azure Kinect and its comparison to Kinect V1 and Kinect V2" (Sensors
    // 21(2) 413, 2021), which also shows the flying pixels at edges and the multipath in corners that the same
    // Microsoft page describes. A bound is not a model: the random sigma at a face's range (0.8 mm + 0.7 mm/m^2
    // z^2: 1.05 mm at 0.6 m, 9.4 mm at 3.5 m, within the bound), the flying-pixel share and the multipath gain are
    // assumed.
    static NoiseParams timeOfFlight();

    Status validate() const;
};

struct SequenceParams {
    int frames = 300;                    // frame count
    float fps = 30.0f;                   // frames per second (timestamps)
    float distance_m = 0.7f;             // metres, camera to head-frame origin at rest
    float yaw_amplitude_deg = 35.0f;     // degrees, head turns left-right by +- this
    float pitch_amplitude_deg = 12.0f;   // degrees, head nods by +- this
    float yaw_period_frames = 300.0f;    // frames per full left-right-left cycle (sets angular speed)
    float pitch_period_frames = 150.0f;  // frames per full nod cycle
    float sway_amplitude_m = 0.01f;      // metres, slow lateral/vertical sway of the whole body (phases from seed)
    uint64_t seed = 1;                   // noise and sway phases; frame i uses a generator seeded from (seed, i)
    bool noise = true;                   // false: exact depth (no noise, quantisation, dropouts, shadows, angle loss)
    bool torso = true;                   // render a torso below the head (segmentation must remove it)
    // false: colour is the subject's own (albedo), unlit, so that colour measured on a model compares with the
    // subject's texture directly (the texture benchmark); true: a lamp above-left of the camera (Lambert + ambient)
    bool shading = true;
    bool wall = true;  // render a wall behind the subject
    // true: the head, torso and wall stand still and the camera moves around the head instead (the background
    // moves in the image): the yaw and pitch amplitudes and periods then drive the camera's orbit about the
    // head-frame origin (the middle of the head) at distance_m, not the head's turn.
    bool orbit = false;
    float wall_distance_m = 1.6f;  // metres, camera to wall
    NoiseParams noise_model;       // used when noise == true
    // The camera's roll about its optical axis (degrees, any angle): a camera held in portrait (90, 270), upside
    // down (180) or tilted. The scene (head, torso, wall, lamp) stays put; the image shows it turned clockwise by
    // this much (roll 90 renders what cv::rotate(ROTATE_90_CLOCKWISE) makes of the upright frame, where both
    // frames see the scene). The projector stays at the camera's +x, as it is fixed to the camera.
    float roll_deg = 0.0f;
    // A camera turned during the scan: the roll grows by this much from the first frame to the last (degrees).
    float roll_turn_deg = 0.0f;

    // A nod instead of a symmetric pitch: pitch goes 0 -> pitch_amplitude_deg -> 0 over each pitch period (a
    // positive amplitude lowers the chin onto the chest).
    bool nod = false;
    // The gap: from gap_start_frame the subject walks sideways out of view (gap_walk_frames), stays out for
    // gap_frames, and walks back in turned by gap_turn_deg (yaw of the whole body about the neck). With
    // gap_leave = false the subject stays in view and turns smoothly over the same frames instead (the gap's
    // twin without the loss, for comparisons). -1 = no gap.
    int gap_start_frame = -1;   // frame index
    int gap_frames = 30;        // frames with the subject out of view (1 s at 30 Hz)
    int gap_walk_frames = 5;    // frames to walk out, and again to walk back in
    float gap_turn_deg = 0.0f;  // degrees; the body comes back turned by this (positive: towards the person's left)
    float gap_side_m = 1.2f;    // metres; how far sideways the subject goes (out of view at face range)
    bool gap_leave = true;      // false: no walk, the subject turns in view
    // A hand-sized occluder (an ellipsoid 9 x 18 x 3 cm, skin-coloured) that crosses in front of the face from the
    // person's right to left over occluder_frames, starting at occluder_start_frame (-1 = none).
    int occluder_start_frame = -1;   // frame index
    int occluder_frames = 30;        // frames (1 s at 30 Hz)
    float occluder_front_m = 0.08f;  // metres in front of the nose tip (towards the camera)

    Status validate() const;
};

// Per-pixel labels of FrameTruth::label.
enum class PixelLabel : uint8_t { kNone = 0, kHead = 1, kBody = 2, kOccluder = 3 };

struct FrameTruth {
    recon::Pose T_camera_head = recon::Pose::Identity();  // true head pose of this frame
    cv::Mat label;         // CV_8UC1 PixelLabel per pixel (of the ideal render; wall and empty are 0)
    cv::Mat depth_true_m;  // CV_32FC1 noise-free depth, metres, 0 where nothing is hit
    cv::Rect face_box_px;  // box of the visible face (brows to chin, cheek to cheek); empty when not visible
    float yaw_deg = 0;     // degrees, head yaw of this frame (0 = frontal)
    float pitch_deg = 0;   // degrees
    int head_pixels = 0;   // pixels labelled kHead (0 while the subject is out of view)
};

class KinectSimulator {
 public:
    KinectSimulator(HeadModel head, SequenceParams params,
                    recon::Intrinsics intrinsics = recon::Intrinsics::kinectV1());
    ~KinectSimulator();
    KinectSimulator(KinectSimulator&&) noexcept;
    KinectSimulator& operator=(KinectSimulator&&) noexcept;

    int frameCount() const { return params_.frames; }
    const recon::Intrinsics& intrinsics() const { return intrinsics_; }
    const SequenceParams& params() const { return params_; }
    const HeadModel& head() const { return head_; }

    // T_camera_head of frame `index` (any integer; the motion is periodic and smooth apart from the gap).
    recon::Pose poseAt(int index) const;
    // T_camera_body: the torso (and the head at rest) of frame `index`; includes sway, the gap's walk and turn.
    recon::Pose bodyPoseAt(int index) const;
    // T_camera_world: where the camera is. The world is the camera's rest pose (identity unless params().orbit).
    recon::Pose cameraFromWorldAt(int index) const;
    // Head yaw and pitch of frame `index` relative to the body (degrees; 0 when the camera orbits instead), and
    // whether the occluder is in the scene.
    float yawDegAt(int index) const;
    float pitchDegAt(int index) const;
    // The camera's roll of frame `index` (degrees; SequenceParams::roll_deg, roll_turn_deg).
    float rollDegAt(int index) const;
    bool occluderActiveAt(int index) const;
    // Where the occluder's centre is (camera frame, metres) at `index`; meaningful when occluderActiveAt(index).
    Eigen::Vector3f occluderCentreAt(int index) const;
    // The head mesh in the first camera frame (T_camera0_head applied): what a reconstruction should produce.
    recon::Mesh headInFirstCamera() const;
    // Per head mesh vertex, 1 where it belongs to the head proper: at most below_cut_m under the neck cut (just
    // under the chin), 0 on the neck and shoulders below. What a scan may hold; anything else is not the head.
    std::vector<uint8_t> headVertexMask(float below_cut_m = 0.03f) const;

    // Renders frame `index` into `out` (depth metres CV_32F, colour CV_8UC3 registered, timestamp).
    // Thread-safe: several threads may render different (or equal) indices at once. Deterministic.
    void render(int index, recon::RgbdFrame& out, FrameTruth* truth = nullptr) const;

 private:
    struct Scene;
    float sweepYawDeg(int index) const;
    float sweepPitchDeg(int index) const;
    HeadModel head_;
    SequenceParams params_;
    recon::Intrinsics intrinsics_;
    std::unique_ptr<Scene> scene_;  // renderable copies of head, torso, wall
};

// Writes frames [0, frameCount) as a TUM RGB-D folder (docs/design.md s7):
//   rgb/<t>.png, depth/<t>.png (16-bit, 5000 units per metre), rgb.txt, depth.txt,
//   groundtruth.txt   `t tx ty tz qx qy qz qw`: camera i in the reference frame = the FIRST camera frame
//                     (T_camera0_camera_i; the head is static in that frame),
//   intrinsics.txt    `fx fy cx cy`,
//   head_gt.ply       the head mesh in metres in the HEAD frame (the ruler's --gt),
//   T_camera0_head.txt 4x4 row-major: maps head_gt.ply into the first camera frame (the ruler's --init).
Status writeTumSequence(const KinectSimulator& simulator, const std::filesystem::path& dir);

}  // namespace facescan::synth
