#include "wire/messages.hpp"

#include <cmath>

namespace facescan::wire {

Status CameraInfoData::validate() const {
    RETURN_IF_ERROR(validateSessionId(session_id));
    const recon::Intrinsics& k = intrinsics;
    if (k.width_px < 16 || k.height_px < 16 || k.width_px > kMaxDepthWidthPx || k.height_px > kMaxDepthHeightPx) {
        return outOfRange("camera size " + std::to_string(k.width_px) + "x" + std::to_string(k.height_px) +
                          " outside 16..4096");
    }
    if (!(k.fx_px > 1 && k.fy_px > 1 && std::isfinite(k.fx_px) && std::isfinite(k.fy_px)) || !std::isfinite(k.cx_px) ||
        !std::isfinite(k.cy_px)) {
        return invalidArgument("camera intrinsics are not usable (focal lengths must be finite and > 1 px)");
    }
    if (!(depth_units_m > 1e-6f && depth_units_m <= 0.01f)) {
        return invalidArgument("depth units must be in (1e-6, 0.01] metres per raw unit, got " +
                               std::to_string(depth_units_m));
    }
    if (!(rate_hz > 0 && rate_hz <= 1000)) return invalidArgument("frame rate must be in (0, 1000] Hz");
    return Status::ok();
}

facescan_wire_ScanStatus toMessage(const ScanStatusData& status) {
    facescan_wire_ScanStatus m{};
    m.session_id = stringView(status.session_id);
    m.server_id = stringView(status.server_id);
    m.state = status.state;
    m.detail = stringView(status.detail);
    m.frames_received = status.frames_received;
    m.frames_integrated = status.frames_integrated;
    m.frames_rejected = status.frames_rejected;
    m.frames_skipped = status.frames_skipped;
    m.frames_dropped = status.frames_dropped;
    m.every_frame = status.every_frame;
    m.fps = status.fps;
    m.ms_detect = status.ms_detect;
    m.ms_segment = status.ms_segment;
    m.ms_filter = status.ms_filter;
    m.ms_icp = status.ms_icp;
    m.ms_integrate = status.ms_integrate;
    m.ms_raycast = status.ms_raycast;
    m.ms_mesh = status.ms_mesh;
    m.latency_p95_ms = status.latency_p95_ms;
    m.snapshot_seq = status.snapshot_seq;
    m.updated_ns = status.updated_ns;
    m.standby_id = stringView(status.standby_id);
    m.owner_epoch = status.owner_epoch;
    m.failovers = status.failovers;
    m.last_takeover_ms = status.last_takeover_ms;
    m.behind = status.behind;
    m.frames_tracked_only = status.frames_tracked_only;
    return m;
}

ScanStatusData fromMessage(const facescan_wire_ScanStatus& m) {
    ScanStatusData s;
    s.session_id = fromDds(m.session_id);
    s.server_id = fromDds(m.server_id);
    s.state = m.state >= facescan_wire_STATE_WAITING && m.state <= facescan_wire_STATE_REFUSED
                  ? m.state
                  : facescan_wire_STATE_WAITING;
    s.detail = fromDds(m.detail);
    s.frames_received = m.frames_received;
    s.frames_integrated = m.frames_integrated;
    s.frames_rejected = m.frames_rejected;
    s.frames_skipped = m.frames_skipped;
    s.frames_dropped = m.frames_dropped;
    s.every_frame = m.every_frame;
    s.fps = m.fps;
    s.ms_detect = m.ms_detect;
    s.ms_segment = m.ms_segment;
    s.ms_filter = m.ms_filter;
    s.ms_icp = m.ms_icp;
    s.ms_integrate = m.ms_integrate;
    s.ms_raycast = m.ms_raycast;
    s.ms_mesh = m.ms_mesh;
    s.latency_p95_ms = m.latency_p95_ms;
    s.snapshot_seq = m.snapshot_seq;
    s.updated_ns = m.updated_ns;
    s.standby_id = fromDds(m.standby_id);
    s.owner_epoch = m.owner_epoch;
    s.failovers = m.failovers;
    s.last_takeover_ms = m.last_takeover_ms;
    s.behind = m.behind;
    s.frames_tracked_only = m.frames_tracked_only;
    return s;
}

facescan_wire_CameraInfo toMessage(const CameraInfoData& info) {
    facescan_wire_CameraInfo msg{};
    msg.session_id = stringView(info.session_id);
    msg.width = static_cast<uint32_t>(info.intrinsics.width_px);
    msg.height = static_cast<uint32_t>(info.intrinsics.height_px);
    msg.fx = info.intrinsics.fx_px;
    msg.fy = info.intrinsics.fy_px;
    msg.cx = info.intrinsics.cx_px;
    msg.cy = info.intrinsics.cy_px;
    msg.depth_units_m = info.depth_units_m;
    msg.colour_registered = info.colour_registered;
    msg.source_rate_hz = info.rate_hz;
    msg.every_frame = info.every_frame;
    msg.expected_frames = info.expected_frames;
    msg.source = stringView(info.source);
    msg.agent_host = stringView(info.agent_host);
    return msg;
}

StatusOr<CameraInfoData> fromMessage(const facescan_wire_CameraInfo& msg) {
    CameraInfoData info;
    info.session_id = fromDds(msg.session_id);
    if (msg.width > static_cast<uint32_t>(kMaxDepthWidthPx) || msg.height > static_cast<uint32_t>(kMaxDepthHeightPx)) {
        return outOfRange("CameraInfo size " + std::to_string(msg.width) + "x" + std::to_string(msg.height) +
                          " exceeds 4096x4096");
    }
    info.intrinsics.width_px = static_cast<int>(msg.width);
    info.intrinsics.height_px = static_cast<int>(msg.height);
    info.intrinsics.fx_px = msg.fx;
    info.intrinsics.fy_px = msg.fy;
    info.intrinsics.cx_px = msg.cx;
    info.intrinsics.cy_px = msg.cy;
    info.depth_units_m = msg.depth_units_m;
    info.colour_registered = msg.colour_registered;
    info.rate_hz = msg.source_rate_hz;
    info.every_frame = msg.every_frame;
    info.expected_frames = msg.expected_frames;
    info.source = fromDds(msg.source);
    info.agent_host = fromDds(msg.agent_host);
    RETURN_IF_ERROR(info.validate());
    return info;
}

FrameEncoder::FrameEncoder(DepthCodecParams depth, ColourJpegParams colour) : depth_(depth), colour_(colour) {}

Status FrameEncoder::encode(const cv::Mat& depth_raw_u16, const cv::Mat& colour_bgr, EncodedFrame& out) {
    out.depth_codec = depth_.params().codec;
    RETURN_IF_ERROR(depth_.encode(depth_raw_u16, out.depth));
    if (colour_bgr.empty()) {
        out.colour_codec = ColourCodecId::kNone;
        out.colour.clear();
        return Status::ok();
    }
    out.colour_codec = ColourCodecId::kJpeg;
    return colour_.encode(colour_bgr, out.colour);
}

facescan_wire_RgbdFrame toMessage(const std::string& session_id, const EncodedFrame& frame) {
    facescan_wire_RgbdFrame msg{};
    msg.session_id = stringView(session_id);
    msg.seq = frame.seq;
    msg.capture_time_ns = frame.capture_time_ns;
    msg.source_time_ns = frame.source_time_ns;
    msg.depth_codec = static_cast<facescan_wire_DepthCodec>(frame.depth_codec);
    msg.depth = octetView(frame.depth.data(), frame.depth.size());
    msg.colour_codec = static_cast<facescan_wire_ColourCodec>(frame.colour_codec);
    msg.colour = octetView(frame.colour.data(), frame.colour.size());
    msg.end_of_stream = false;
    return msg;
}

Status FrameDecoder::decode(const facescan_wire_RgbdFrame& msg, const CameraInfoData& camera, ColourDecode colour,
                            recon::RgbdFrame& out) {
    out.colour_on_demand = nullptr;
    on_demand_.release();
    if (msg.depth._length > 0 && msg.depth._buffer == nullptr) return dataLoss("depth payload has no bytes");
    ASSIGN_OR_RETURN(const DepthCodecId codec, depthCodecFromTag(static_cast<uint32_t>(msg.depth_codec)));
    const int w = camera.intrinsics.width_px;
    const int h = camera.intrinsics.height_px;
    RETURN_IF_ERROR(depth_.decode(codec, msg.depth._buffer, msg.depth._length, w, h, depth_raw_));
    recon::depthRawToMetres(depth_raw_, camera.depth_units_m, out.depth_m);
    // Trajectories are stamped with the source's time so they line up with a recording's ground truth.
    out.timestamp_ns = msg.source_time_ns;
    out.colour_bgr.release();
    const bool has_colour = msg.colour_codec == facescan_wire_COLOUR_JPEG && msg.colour._length > 0;
    if (colour == ColourDecode::kNone || !has_colour) return Status::ok();
    if (msg.colour._buffer == nullptr) return dataLoss("colour payload has no bytes");
    // Colour that is not registered to depth cannot be used per depth pixel, and CameraInfo carries no
    // extrinsics to register it (recon::ColourCamera could); it is dropped and the depth-only paths take over.
    if (!camera.colour_registered) return Status::ok();
    if (colour == ColourDecode::kEager) {
        return on_demand_.decoder().decode(msg.colour._buffer, msg.colour._length, w, h, out.colour_bgr);
    }
    // A payload of the wrong size or no JPEG at all is refused with the frame, as an eager decode would; damage
    // in its entropy data shows only where a stage reads it (colourStatus()).
    RETURN_IF_ERROR(on_demand_.decoder().checkHeader(msg.colour._buffer, msg.colour._length, w, h));
    on_demand_.reset(msg.colour._buffer, msg.colour._length, w, h);
    out.colour_on_demand = &on_demand_;
    return Status::ok();
}

void FrameDecoder::OnDemandJpeg::reset(const uint8_t* jpeg, size_t size, int width_px, int height_px) {
    jpeg_ = jpeg;
    size_ = size;
    width_px_ = width_px;
    height_px_ = height_px;
    decoded_ = cv::Rect();
    status_ = Status::ok();
}

const cv::Mat& FrameDecoder::OnDemandJpeg::colour(const cv::Rect& roi_px) {
    if (jpeg_ == nullptr || !status_.isOk()) return none_;
    const cv::Rect want = roi_px & cv::Rect(0, 0, width_px_, height_px_);
    if (want.empty() || (want & decoded_) == want) return decoded_.empty() ? none_ : bgr_;
    status_ = decoder_.decodeRegion(jpeg_, size_, width_px_, height_px_, want, bgr_);
    if (!status_.isOk()) return none_;
    decoded_ = want;
    return bgr_;
}

}  // namespace facescan::wire
