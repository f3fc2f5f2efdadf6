// Where frames come from: one interface for a live OpenNI2 camera, an .oni recording, a TUM RGB-D folder and the
// synthetic Kinect (docs/design.md section 2). Sources deliver raw depth (16-bit, in the source's units) because the
// wire codecs are lossless on raw units; conversion to metres happens at the server's boundary.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "recon/camera.hpp"
#include "recon/sensor.hpp"
#include "recon/status.hpp"

namespace facescan::capture {

struct SourceInfo {
    recon::Intrinsics intrinsics;   // of the depth camera
    float depth_units_m = 0.001f;   // metres per raw depth unit (OpenNI: mm; TUM: 1/5000 m)
    bool colour_registered = true;  // colour pixels line up with depth pixels
    bool has_colour = true;
    float rate_hz = 30.0f;      // the source's own frame rate
    bool is_recording = false;  // a file or generator: can be read as fast as the consumer takes it
    int expected_frames = 0;    // 0 when unknown or live
    std::string description;    // e.g. "synthetic:leeperrysmith", "oni:/data/scan.oni"
    // The camera, as far as the source can tell (a device's name and range, a recording's metadata); the agent's
    // --sensor and --depth-range replace it. A source that cannot tell leaves a Kinect v1 and sensor_known false.
    recon::SensorModel sensor;
    bool sensor_known = false;
    // The colour camera's own size and intrinsics (width 0: the depth camera's) and the depth-to-colour
    // extrinsics, for colour that is not registered to depth.
    recon::Intrinsics colour_intrinsics{0, 0, 0.0f, 0.0f, 0.0f, 0.0f};
    recon::Pose T_colour_depth = recon::Pose::Identity();
};

struct CapturedFrame {
    cv::Mat depth_raw;         // CV_16UC1, depth_units_m per unit, 0 = no measurement
    cv::Mat colour_bgr;        // CV_8UC3, or empty when the source has no colour
    int64_t timestamp_ns = 0;  // the source's timestamp (device clock, file time, or synthetic time)
    uint32_t index = 0;        // 0, 1, 2, ... in source order
};

class FrameSource {
 public:
    virtual ~FrameSource() = default;
    virtual const SourceInfo& info() const = 0;
    // Next frame into `out` (buffers reused when sizes match). Returns true for a frame, false at a clean end
    // of stream, or an error Status (device unplugged, corrupt file) that says what happened.
    // Live sources block until the device delivers (at most a couple of frame periods before an error).
    virtual StatusOr<bool> next(CapturedFrame& out) = 0;
};

struct SourceOptions {
    bool colour = true;                    // false: do not read colour at all (--no-colour)
    int max_frames = 0;                    // 0 = all; otherwise stop after this many
    float tum_depth_units_m = 0.0002f;     // TUM PNG units (5000 per metre); 0.001 for Kinect/OpenNI millimetres
    float recording_depth_units_m = 0.0f;  // mkv:/bag: metres per raw unit over the file's own; 0 = the file's
};

// Opens a source from its command-line spec:
//   openni2[:URI]   the first OpenNI2 device, or the one with this URI
//   oni:FILE        an OpenNI2 recording, every frame in order
//   tum:DIR         a TUM RGB-D folder (rgb.txt, depth.txt, optional intrinsics.txt and sensor.txt)
//   synthetic[:k=v,...]  the virtual Kinect (keys: frames, distance, yaw, pitch, seed, noise,
//   subject=builtin|scan|PATH)
StatusOr<std::unique_ptr<FrameSource>> openSource(const std::string& spec, const SourceOptions& options);

// Per-kind openers (used by openSource; exposed for tests).
StatusOr<std::unique_ptr<FrameSource>> openTumSource(const std::string& dir, const SourceOptions& options);
// A TUM folder's camera, from its optional sensor.txt: "NAME [MIN_M MAX_M]", NAME a preset (recon::sensorPresets,
// the range overriding its own) or any name with its range. DataLoss, saying the format, for anything else.
StatusOr<recon::SensorModel> readSensorFile(const std::filesystem::path& file);
StatusOr<std::unique_ptr<FrameSource>> openSyntheticSource(const std::string& options_text,
                                                           const SourceOptions& options);
// uri empty = first device. Live camera: depth 640x480@30 in mm, registration and sync on where supported.
StatusOr<std::unique_ptr<FrameSource>> openOpenNi2Device(const std::string& uri, const SourceOptions& options);
// Playback of an .oni recording at manual speed: every frame in order, then a clean end.
StatusOr<std::unique_ptr<FrameSource>> openOniFile(const std::string& path, const SourceOptions& options);

// Reads every frame of a recording (tum:, oni:, synthetic) into memory now and returns a source that replays them
// (same info; pacing stays with the caller). Memory: width x height x 5 bytes per frame (1.5 MB at VGA with
// colour). `progress(frames_read, frames_expected)` is called after each frame (expected is 0 when unknown).
// InvalidArgument for a live camera, whose frames do not exist yet.
StatusOr<std::unique_ptr<FrameSource>> preloadSource(std::unique_ptr<FrameSource> source,
                                                     const std::function<void(int, int)>& progress = {});

}  // namespace facescan::capture
