#include "wire/messages.hpp"

#include <cmath>
#include <cstdio>
#include <vector>

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
    if (roll_deg != kRollUnknown && !recon::isRollStepDeg(roll_deg)) {
        return invalidArgument("camera roll " + std::to_string(roll_deg) + " deg: must be 0 to 345 in steps of " +
                               std::to_string(recon::kRollStepDeg) +
                               " (how far the person appears turned clockwise), or unknown (auto)");
    }
    if (dropped_before_seq != 0 && (!every_frame || followed_epoch == 0)) {
        return invalidArgument(
            "the agent says it dropped frames before " + std::to_string(dropped_before_seq) +
            std::string(every_frame ? " without having followed an owner" : " of a live scan, which keeps none") +
            ": the agent is broken or of another version");
    }
    if (const Status s = sensor.validate(); !s.isOk())
        return invalidArgument("camera '" + sensor.name + "': " + s.message());
    const recon::Intrinsics& c = colourIntrinsics();
    if (c.width_px < 16 || c.height_px < 16 || c.width_px > kMaxDepthWidthPx || c.height_px > kMaxDepthHeightPx) {
        return outOfRange("colour camera size " + std::to_string(c.width_px) + "x" + std::to_string(c.height_px) +
                          " outside 16..4096");
    }
    if (!(c.fx_px > 1 && c.fy_px > 1 && std::isfinite(c.fx_px) && std::isfinite(c.fy_px) && std::isfinite(c.cx_px) &&
          std::isfinite(c.cy_px))) {
        return invalidArgument("colour camera intrinsics are not usable (focal lengths must be finite and > 1 px)");
    }
    if (colour_registered && (c.width_px != k.width_px || c.height_px != k.height_px)) {
        return invalidArgument("colour is said to be registered to depth, but its size " + std::to_string(c.width_px) +
                               "x" + std::to_string(c.height_px) + " is not the depth's " + std::to_string(k.width_px) +
                               "x" + std::to_string(k.height_px) +
                               ": register it, or describe the colour camera and its extrinsics");
    }
    const Eigen::Matrix3f R = T_colour_depth.linear();
    if (!T_colour_depth.matrix().allFinite() || !(R * R.transpose()).isApprox(Eigen::Matrix3f::Identity(), 1e-3f) ||
        R.determinant() < 0.0f || T_colour_depth.translation().norm() > 1.0f) {
        return invalidArgument("depth-to-colour extrinsics are not a rotation and a translation under 1 m");
    }
    return Status::ok();
}

Status CameraInfoData::checkDepthUnits(const cv::Mat& depth_raw) const {
    if (depth_raw.empty() || depth_raw.type() != CV_16UC1) return Status::ok();
    // A histogram of the raw values: the median without sorting a frame.
    std::vector<uint32_t> histogram(65536, 0);
    uint64_t valid = 0;
    for (int v = 0; v < depth_raw.rows; v += 2) {
        const uint16_t* row = depth_raw.ptr<uint16_t>(v);
        for (int u = 0; u < depth_raw.cols; u += 2) {
            if (row[u] == 0) continue;
            ++histogram[row[u]];
            ++valid;
        }
    }
    if (valid == 0) return Status::ok();
    uint64_t seen = 0;
    int median_raw = 0;
    for (; median_raw < 65536; ++median_raw) {
        seen += histogram[static_cast<size_t>(median_raw)];
        if (2 * seen >= valid) break;
    }
    const float median_m = static_cast<float>(median_raw) * depth_units_m;
    // A scene is never tenths of the sensor's near limit away, nor ten times its far limit.
    if (median_m < 0.1f * sensor.min_depth_m || median_m > 10.0f * sensor.max_depth_m) {
        char text[512];
        std::snprintf(text, sizeof(text),
                      "depth units look wrong: the frame's median depth is %.4g m (raw %d x %g m), but '%s' "
                      "measures %.2f-%.2f m; give the source's depth units in raw units per metre (--tum-depth-scale "
                      "for a TUM folder, --depth-scale for an .mkv or .bag recording: 1000 for millimetres) or "
                      "the right --sensor",
                      static_cast<double>(median_m), median_raw, static_cast<double>(depth_units_m),
                      sensor.name.c_str(), static_cast<double>(sensor.min_depth_m),
                      static_cast<double>(sensor.max_depth_m));
        return invalidArgument(text);
    }
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
    msg.min_depth_m = info.sensor.min_depth_m;
    msg.max_depth_m = info.sensor.max_depth_m;
    msg.sensor_family = static_cast<facescan_wire_SensorFamily>(info.sensor.family);
    msg.sensor_name = stringView(info.sensor.name);
    msg.noise_c0_m = info.sensor.noise.c0_m;
    msg.noise_c1 = info.sensor.noise.c1;
    msg.noise_c2_per_m = info.sensor.noise.c2_per_m;
    msg.colour_width = static_cast<uint32_t>(info.colour_intrinsics.width_px);
    msg.colour_height = static_cast<uint32_t>(info.colour_intrinsics.height_px);
    msg.colour_fx = info.colour_intrinsics.fx_px;
    msg.colour_fy = info.colour_intrinsics.fy_px;
    msg.colour_cx = info.colour_intrinsics.cx_px;
    msg.colour_cy = info.colour_intrinsics.cy_px;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) msg.R_colour_depth[3 * r + c] = info.T_colour_depth.linear()(r, c);
        msg.t_colour_depth_m[r] = info.T_colour_depth.translation()(r);
    }
    // 0 on the wire is "unknown" (what an older agent leaves), so upright and known travels as a full turn.
    msg.roll_deg = info.roll_deg == CameraInfoData::kRollUnknown ? 0 : info.roll_deg == 0 ? 360 : info.roll_deg;
    msg.followed_epoch = info.followed_epoch;
    msg.dropped_before_seq = info.dropped_before_seq;
    msg.serving_epoch = info.serving_epoch;
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
    if (msg.min_depth_m == 0.0f && msg.max_depth_m == 0.0f) {
        // An agent from before the camera travelled with the stream: it only ever drove a Kinect v1.
        info.sensor = recon::SensorModel::kinectV1();
    } else {
        info.sensor.min_depth_m = msg.min_depth_m;
        info.sensor.max_depth_m = msg.max_depth_m;
        info.sensor.family = msg.sensor_family >= facescan_wire_SENSOR_UNKNOWN &&
                                     msg.sensor_family <= facescan_wire_SENSOR_TIME_OF_FLIGHT
                                 ? static_cast<recon::SensorFamily>(msg.sensor_family)
                                 : recon::SensorFamily::kUnknown;
        info.sensor.name = fromDds(msg.sensor_name);
        if (info.sensor.name.empty()) info.sensor.name = "custom";
        info.sensor.noise = {msg.noise_c0_m, msg.noise_c1, msg.noise_c2_per_m};
    }
    // Width 0 (an older agent's, or registered colour): the colour camera is the depth camera's.
    if (msg.colour_width != 0 || msg.colour_height != 0) {
        if (msg.colour_width > static_cast<uint32_t>(kMaxDepthWidthPx) ||
            msg.colour_height > static_cast<uint32_t>(kMaxDepthHeightPx)) {
            return outOfRange("CameraInfo colour size " + std::to_string(msg.colour_width) + "x" +
                              std::to_string(msg.colour_height) + " exceeds 4096x4096");
        }
        info.colour_intrinsics.width_px = static_cast<int>(msg.colour_width);
        info.colour_intrinsics.height_px = static_cast<int>(msg.colour_height);
        info.colour_intrinsics.fx_px = msg.colour_fx;
        info.colour_intrinsics.fy_px = msg.colour_fy;
        info.colour_intrinsics.cx_px = msg.colour_cx;
        info.colour_intrinsics.cy_px = msg.colour_cy;
        bool rotation_zero = true;
        for (const float v : msg.R_colour_depth) rotation_zero = rotation_zero && v == 0.0f;
        info.T_colour_depth = recon::Pose::Identity();
        if (!rotation_zero) {
            for (int r = 0; r < 3; ++r) {
                for (int c = 0; c < 3; ++c) info.T_colour_depth.matrix()(r, c) = msg.R_colour_depth[3 * r + c];
            }
        }
        for (int r = 0; r < 3; ++r) info.T_colour_depth.matrix()(r, 3) = msg.t_colour_depth_m[r];
    }
    // 360 is upright and known (0 means unknown); a tilt between quarter turns is its step.
    if (msg.roll_deg != 360 && !recon::isRollStepDeg(msg.roll_deg)) {
        return invalidArgument("CameraInfo roll_deg " + std::to_string(msg.roll_deg) +
                               " is none of 0 (unknown), 15 to 345 in steps of " + std::to_string(recon::kRollStepDeg) +
                               " or 360 (upright): the agent is broken or of another version; run facescan-agent "
                               "--roll auto or a step from 0 to 345");
    }
    info.roll_deg = msg.roll_deg == 0 ? CameraInfoData::kRollUnknown : msg.roll_deg % 360;
    info.followed_epoch = msg.followed_epoch;
    info.dropped_before_seq = msg.dropped_before_seq;
    info.serving_epoch = msg.serving_epoch;
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
    // Colour that is not registered to depth cannot be used per depth pixel. CameraInfo carries the colour
    // camera and its extrinsics (colour_intrinsics, T_colour_depth), but the stages that read colour (detection,
    // integration) take it per depth pixel and nothing registers it yet: it is dropped and the depth-only paths
    // take over.
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
