// The capture agent: reads a FrameSource, compresses, publishes CameraInfo once and then RgbdFrames over DDS.
// The camera thread never waits on the network: it hands frames to the publisher through a small queue; a live
// camera drops the oldest queued frame when the network falls behind (counted), a recording sent with
// --rate max waits instead, so no frame of it is ever lost.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "capture/frame_source.hpp"
#include "wire/dds.hpp"
#include "wire/depth_codec.hpp"
#include "wire/messages.hpp"

namespace facescan::capture {

enum class RateMode {
    kReal,   // the source's own rate (live cameras: as delivered; recordings: paced by their timestamps/rate)
    kMax,    // as fast as the server takes them, every frame processed (DDS back-pressure, no loss)
    kFixed,  // a fixed rate in Hz
};

struct AgentOptions {
    std::string source = "openni2";  // openni2[:URI] | oni:FILE | tum:DIR | synthetic[:k=v,...]
    SourceOptions source_options;
    wire::DomainConfig dds;
    std::string session_id;  // empty: a fresh unique id
    RateMode rate = RateMode::kReal;
    float rate_hz = 0;      // Hz, with RateMode::kFixed
    int jpeg_quality = 90;  // 1..100
    wire::DepthCodecParams depth;
    float wait_for_server_s = 0;  // seconds to wait for a server before giving up; 0 = wait forever
    int queue_frames = 4;         // frames between the camera thread and the publisher
    // Recording frames kept until the owner confirms them (replicated to its standby or on its disk), to resend
    // after a takeover. When full, the agent waits for the owner (nothing is lost).
    int keep_frames = 300;
    float finish_timeout_s = 120;  // seconds to wait, after the last frame, for the server to finish the scan
    // An owner that has taken no frame for this long while the agent's writes wait is reported in the status
    // line as having stopped taking frames.
    float stalled_after_s = 10;
    // Where frames that no server confirmed are saved, as a TUM folder, when the agent stops before its scan
    // finished (a recording only: --rate max). Empty: defaultSaveDir().
    std::string save_dir;
    // Read the whole recording into memory before streaming (preloadSource): the agent then costs only its
    // encoding, like a capture PC that does not share the server's cores. Recordings only.
    bool preload = false;
    std::function<void(int, int)> preload_progress;  // (frames read, frames expected or 0), while preloading
    // The camera: a preset name (recon::sensorPresets()) replaces what the source reports; empty keeps it (a
    // source that cannot tell means a Kinect v1). Then each override that is set (not 0) replaces its field.
    std::string sensor;
    float depth_min_m = 0;  // metres; --depth-range MIN:MAX
    float depth_max_m = 0;  // metres
    // How the camera is held (--roll): how far the person appears turned clockwise in the image, 0, 90, 180 or 270
    // degrees, told to the server in CameraInfo; unknown (auto) leaves the server to find it from the frames.
    int roll_deg = wire::CameraInfoData::kRollUnknown;

    // The sensor the stream will describe: the source's, or the preset, with the overrides applied.
    StatusOr<recon::SensorModel> resolveSensor(const SourceInfo& source) const;

    Status validate() const;
};

// A frame against the camera description the stream announces: depth units that put the scene at 300 m or
// 0.3 mm, or colour of another size than the colour camera's, get one line that says what to do.
Status checkFrameFitsCamera(const wire::CameraInfoData& camera, const CapturedFrame& frame);

struct AgentStats {
    uint32_t captured = 0;   // frames read from the source
    uint32_t published = 0;  // frames written to DDS
    uint32_t dropped = 0;    // live frames dropped because the network fell behind
    double elapsed_s = 0;
    double fps = 0;          // published frames per second over the last interval
    double bytes_per_s = 0;  // compressed bytes per second over the last interval
    double ratio = 0;        // raw bytes / compressed bytes so far
    int servers = 0;         // servers alive on the domain
    // The session's owner.
    std::string owner;  // empty: none yet
    std::string standby;
    uint32_t epoch = 0;
    uint32_t takeovers = 0;  // owner changes seen while streaming
    uint32_t replayed = 0;   // frames sent again to a new owner
    size_t kept = 0;         // recording frames kept until the owner confirms them
    std::string waiting;     // why nothing is sent right now (empty: streaming)
    uint64_t digest = 0;     // of every frame sent (wire::frameDigest): the server's summary has the same
};

// Once `stop` is set, the agent tells the owner the stream ended and gives it what is left of this budget to
// finish the scan (a stuck server costs no more). The rest of the 2 s a stop may take goes to saving the frames
// no server confirmed and to leaving the domain, which take most of a second on a loaded machine.
inline constexpr float kStopBudgetS = 0.6f;

// A fresh session id: host-YYYYmmdd-HHMMSS-xxxx (unique per scan, valid as a DDS key and a file name).
std::string newSessionId();

class Agent {
 public:
    static StatusOr<std::unique_ptr<Agent>> create(AgentOptions options);
    ~Agent();

    const std::string& sessionId() const { return session_id_; }
    const SourceInfo& sourceInfo() const { return source_->info(); }
    bool everyFrame() const { return options_.rate == RateMode::kMax; }

    // Publishes until the source ends, `stop` becomes true (Ctrl-C) or the source fails; in every case the
    // server is told the stream ended. `on_event` gets a one-line message for notable events (waiting for a
    // server, server found or lost, where unconfirmed frames were saved) and `on_stats` about once a second.
    // When the domain erases the session (`facescan delete`: an EraseRequest for it), the agent stops as on
    // Ctrl-C, drops the frames it kept for the owner, saves none (and deletes what a save had written) and
    // says so.
    Status run(const std::atomic<bool>& stop, const std::function<void(const std::string&)>& on_event,
               const std::function<void(const AgentStats&)>& on_stats);

 private:
    struct Impl;
    explicit Agent(AgentOptions options);
    // Saves `kept` (sent, not confirmed) and `queued` (captured, not sent) as a TUM folder under the save dir,
    // and says where; the folder (empty when there was nothing to save).
    StatusOr<std::filesystem::path> saveUnconfirmed(const std::vector<wire::EncodedFrame>& kept,
                                                    const std::vector<const CapturedFrame*>& queued,
                                                    const std::function<void(const std::string&)>& on_event);
    // Who asked to erase this session, when an EraseRequest for it is on the domain (empty: none yet).
    std::string erasureRequested();

    AgentOptions options_;
    std::string session_id_;
    std::unique_ptr<FrameSource> source_;
    std::unique_ptr<Impl> impl_;
};

}  // namespace facescan::capture
