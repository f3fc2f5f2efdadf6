// Message <-> core conversion: the only place that knows how RgbdFrame/CameraInfo samples map to recon types.
// Everything read from the network is validated here and comes back as a Status, never a crash.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "recon/frame.hpp"
#include "recon/sensor.hpp"
#include "wire/colour_codec.hpp"
#include "wire/depth_codec.hpp"
#include "wire/topics.hpp"

namespace facescan::wire {

// CameraInfo as a C++ value (the agent fills it; the server validates what it receives).
struct CameraInfoData {
    std::string session_id;
    recon::Intrinsics intrinsics;
    float depth_units_m = 0.001f;  // metres per raw unit
    bool colour_registered = true;
    float rate_hz = 30.0f;
    bool every_frame = false;      // recording: process every frame
    uint32_t expected_frames = 0;  // 0 = unknown
    std::string source;
    std::string agent_host;
    // The camera (appended to the message): an older agent's CameraInfo has none, and reads as a Kinect v1.
    recon::SensorModel sensor;
    // The colour camera's own size and intrinsics (width 0: the depth camera's), and where it sits: maps
    // depth-camera points into it. Registered colour has the depth camera's and the identity.
    recon::Intrinsics colour_intrinsics{0, 0, 0.0f, 0.0f, 0.0f, 0.0f};
    recon::Pose T_colour_depth = recon::Pose::Identity();
    // How the camera is held (the agent's --roll; recon::FacePipelineParams::roll_deg's meaning): 0 to 345 degrees
    // in steps of recon::kRollStepDeg, or kRollUnknown for the server to find it from the frames (an older agent
    // sends none).
    static constexpr int kRollUnknown = -1;
    int roll_deg = kRollUnknown;
    // A recording's progress as its agent last wrote it (the message's comment): the highest owner epoch followed,
    // and the first frame it still holds (0: none dropped).
    uint32_t followed_epoch = 0;
    uint32_t dropped_before_seq = 0;
    // The epoch of the owner serving the session in the agent's view, live or recording (0: none; the message's
    // comment).
    uint32_t serving_epoch = 0;
    const recon::Intrinsics& colourIntrinsics() const {
        return colour_intrinsics.width_px == 0 ? intrinsics : colour_intrinsics;
    }

    // Sizes within the codec caps, positive focal lengths, sane units, a usable range and a colour camera whose
    // size matches registered frames: each fault is one line that says what to fix.
    Status validate() const;
    // The first frames' depth, in the camera's units, against its working range: a median of 300 m or 0.3 mm
    // means the units are wrong. depth_raw is CV_16UC1; ok when it holds no measurement.
    Status checkDepthUnits(const cv::Mat& depth_raw) const;
};

// Session ids travel as DDS keys and end up in file names on the server: 1-64 of [A-Za-z0-9._-], not ".."/".".
// (Defined with the other id rules in cluster_codec.cpp.)
Status validateSessionId(const std::string& session_id);

// Holds the strings the message points at: keep it alive until the sample is written.
facescan_wire_CameraInfo toMessage(const CameraInfoData& info);
StatusOr<CameraInfoData> fromMessage(const facescan_wire_CameraInfo& msg);

// ScanStatus as a C++ value: the server fills it, the client and tests read it. One conversion each way, so the
// message's 24 fields are listed in exactly one place (messages.cpp).
struct ScanStatusData {
    std::string session_id;
    std::string server_id;
    facescan_wire_ScanState state = facescan_wire_STATE_WAITING;
    std::string detail;
    uint32_t frames_received = 0;
    uint32_t frames_integrated = 0;
    uint32_t frames_rejected = 0;  // could not be aligned, or no head
    uint32_t frames_skipped = 0;   // live stream: older frames skipped to stay real-time
    uint32_t frames_dropped = 0;   // gaps in seq, or undecodable payloads
    bool every_frame = false;      // recording mode: every frame processed
    float fps = 0;
    float ms_detect = 0, ms_segment = 0, ms_filter = 0, ms_icp = 0, ms_integrate = 0, ms_raycast = 0, ms_mesh = 0;
    float latency_p95_ms = 0;  // capture to pose known
    uint32_t snapshot_seq = 0;
    int64_t updated_ns = 0;  // server's CLOCK_REALTIME when published
    // The cluster.
    std::string standby_id;
    uint32_t owner_epoch = 0;
    uint32_t failovers = 0;
    float last_takeover_ms = 0;
    bool behind = false;  // live session not keeping up: throttled or skipping frames (detail says how much)
    uint32_t frames_tracked_only = 0;  // tracked (pose known) but not fused: a loaded server's last economy step
};
// The message points at `status`'s strings: keep it alive until the sample is written.
facescan_wire_ScanStatus toMessage(const ScanStatusData& status);
// Any state value outside the IDL enum reads as WAITING (a newer server's state this build does not know).
ScanStatusData fromMessage(const facescan_wire_ScanStatus& msg);

// One compressed frame, buffers reused frame to frame.
struct EncodedFrame {
    uint32_t seq = 0;
    int64_t capture_time_ns = 0;  // agent's CLOCK_REALTIME at capture (latency)
    int64_t source_time_ns = 0;   // the source's timestamp (trajectories)
    DepthCodecId depth_codec = DepthCodecParams{}.codec;
    std::vector<uint8_t> depth;
    ColourCodecId colour_codec = ColourCodecId::kNone;
    std::vector<uint8_t> colour;

    size_t bytes() const { return depth.size() + colour.size(); }
};

// Agent side: raw 16-bit depth (+ optional colour) to codec payloads. No allocation per frame after warm-up.
class FrameEncoder {
 public:
    FrameEncoder(DepthCodecParams depth = {}, ColourJpegParams colour = {});
    Status encode(const cv::Mat& depth_raw_u16, const cv::Mat& colour_bgr, EncodedFrame& out);

 private:
    DepthEncoder depth_;
    ColourJpegEncoder colour_;
};

// A sample that points into `frame`'s buffers and `session_id` (no copy): write it before they change.
facescan_wire_RgbdFrame toMessage(const std::string& session_id, const EncodedFrame& frame);

// What FrameDecoder does with a frame's colour (when it has some, registered to depth).
enum class ColourDecode {
    kNone,      // left out
    kEager,     // decoded whole, into RgbdFrame::colour_bgr
    kOnDemand,  // its header checked now; RgbdFrame::colour_on_demand decodes what a stage reads, when it reads it
};

// Server side: a received sample to a frame in metres, checked against the session's CameraInfo.
class FrameDecoder {
 public:
    FrameDecoder() = default;
    FrameDecoder(const FrameDecoder&) = delete;  // `out.colour_on_demand` points into it
    FrameDecoder& operator=(const FrameDecoder&) = delete;

    // Decodes depth, and colour as `colour` says, into `out` (buffers reused). With kOnDemand the colour is
    // decoded from msg's bytes: they must outlive the frame's processing, and releaseColour() forgets them.
    Status decode(const facescan_wire_RgbdFrame& msg, const CameraInfoData& camera, ColourDecode colour,
                  recon::RgbdFrame& out);
    // Why the last frame's on-demand colour could not be decoded (ok: it could, or nothing asked for it).
    const Status& colourStatus() const { return on_demand_.status(); }
    void releaseColour() { on_demand_.release(); }

 private:
    // The colour regions a frame's stages ask for, decoded from its JPEG (each region once).
    class OnDemandJpeg final : public recon::ColourSource {
     public:
        void reset(const uint8_t* jpeg, size_t size, int width_px, int height_px);
        void release() { jpeg_ = nullptr; }
        const Status& status() const { return status_; }
        const cv::Mat& colour(const cv::Rect& roi_px) override;
        ColourJpegDecoder& decoder() { return decoder_; }

     private:
        ColourJpegDecoder decoder_;
        const uint8_t* jpeg_ = nullptr;
        size_t size_ = 0;
        int width_px_ = 0;
        int height_px_ = 0;
        cv::Rect decoded_;  // the region bgr_ holds for this frame
        cv::Mat bgr_;
        const cv::Mat none_;
        Status status_;
    };
    DepthDecoder depth_;
    OnDemandJpeg on_demand_;
    cv::Mat depth_raw_;
};

}  // namespace facescan::wire
