// mkv:FILE -- Azure Kinect and Orbbec Femto recordings (Matroska, as their recorders write it), demuxed by FFmpeg's
// libavformat: depth from the 'DEPTH' track (b16g: 16-bit big-endian millimetres), MJPEG colour from 'COLOR',
// the cameras from the calibration.json attachment (azure_kinect_calibration.cpp), device timestamps from the
// packets' times plus the K4A_START_OFFSET_NS tag.
//
// Both cameras' lenses are Brown-Conrady (rational) models with strong distortion on the depth camera; the
// pipeline's cameras are pinholes (the thesis' projection, eq. 2.1), so every image is undistorted onto the
// pinhole of the same fx, fy, cx, cy: depth with nearest-neighbour lookup (no depth is invented by blending an
// edge's two sides), colour bilinearly. This is also why colour is decoded here rather than its JPEG bytes passed
// through: the bytes describe the distorted image.
extern "C" {
#include <libavformat/avformat.h>
#include <libavutil/avutil.h>
#include <libavutil/dict.h>
}

#include <cmath>
#include <cstdio>
#include <deque>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "capture/recording_sources.hpp"

namespace facescan::capture {
namespace {

struct FormatCloser {
    void operator()(AVFormatContext* c) const { avformat_close_input(&c); }
};
struct PacketFree {
    void operator()(AVPacket* p) const { av_packet_free(&p); }
};

std::string avError(int code) {
    char text[AV_ERROR_MAX_STRING_SIZE] = {};
    av_strerror(code, text, sizeof(text));
    return text;
}

std::string tag(const AVDictionary* dict, const char* key) {
    const AVDictionaryEntry* e = av_dict_get(dict, key, nullptr, 0);
    return e != nullptr && e->value != nullptr ? e->value : "";
}

struct Packet {
    int64_t time_ns = 0;
    std::vector<uint8_t> bytes;
};

// Remap tables from the pinhole image to the distorted one (cv::initUndistortRectifyMap with the same K).
struct Undistorter {
    cv::Mat map_x, map_y;
    void init(const AzureKinectCamera& cam) {
        const recon::Intrinsics& k = cam.intrinsics;
        const cv::Matx33d K(k.fx_px, 0, k.cx_px, 0, k.fy_px, k.cy_px, 0, 0, 1);
        cv::initUndistortRectifyMap(K, cam.distortion, cv::noArray(), K, cv::Size(k.width_px, k.height_px), CV_32FC1,
                                    map_x, map_y);
    }
    void apply(const cv::Mat& in, cv::Mat& out, int interpolation) const {
        cv::remap(in, out, map_x, map_y, interpolation, cv::BORDER_CONSTANT, cv::Scalar::all(0));
    }
};

class MkvSource final : public FrameSource {
 public:
    MkvSource(std::unique_ptr<AVFormatContext, FormatCloser> format, SourceInfo info, int depth_stream,
              int colour_stream, int64_t start_offset_ns, const AzureKinectCalibration& calibration,
              SourceOptions options)
        : format_(std::move(format)),
          info_(std::move(info)),
          depth_stream_(depth_stream),
          colour_stream_(colour_stream),
          start_offset_ns_(start_offset_ns),
          options_(options),
          packet_(av_packet_alloc()) {
        depth_undistort_.init(calibration.depth);
        if (colour_stream_ >= 0) colour_undistort_.init(calibration.colour);
    }

    const SourceInfo& info() const override { return info_; }

    StatusOr<bool> next(CapturedFrame& out) override {
        if (options_.max_frames > 0 && index_ >= static_cast<uint32_t>(options_.max_frames)) return false;
        while (depth_.empty() && !eof_) RETURN_IF_ERROR(readPacket());
        if (depth_.empty()) return endOfRecording();
        const Packet depth = std::move(depth_.front());
        depth_.pop_front();
        // Colour nearest in time: read on until a colour packet at or after the depth frame (or the end).
        while (colour_stream_ >= 0 && !eof_ && (colour_.empty() || colour_.back().time_ns < depth.time_ns) &&
               depth_.size() < 8) {
            RETURN_IF_ERROR(readPacket());
        }

        const recon::Intrinsics& k = info_.intrinsics;
        const size_t expected = static_cast<size_t>(k.width_px) * static_cast<size_t>(k.height_px) * 2;
        if (depth.bytes.size() != expected) {
            return dataLoss(info_.description + ": depth frame " + std::to_string(index_) + " holds " +
                            std::to_string(depth.bytes.size()) + " bytes, not the " + std::to_string(expected) +
                            " of a " + std::to_string(k.width_px) + "x" + std::to_string(k.height_px) +
                            " 16-bit image: the file is damaged");
        }
        raw_.create(k.height_px, k.width_px, CV_16UC1);
        for (size_t i = 0; i < expected / 2; ++i) {  // b16g: big-endian
            raw_.ptr<uint16_t>()[i] = static_cast<uint16_t>((depth.bytes[2 * i] << 8) | depth.bytes[2 * i + 1]);
        }
        depth_undistort_.apply(raw_, out.depth_raw, cv::INTER_NEAREST);

        out.colour_bgr.release();
        if (colour_stream_ >= 0 && !colour_.empty()) {
            size_t best = 0;
            for (size_t i = 1; i < colour_.size(); ++i) {
                if (std::llabs(colour_[i].time_ns - depth.time_ns) <= std::llabs(colour_[best].time_ns - depth.time_ns))
                    best = i;
            }
            // A capture without its colour image (the device dropped it) goes out as depth only, rather than with
            // the colour of another moment.
            const double half_period_ns = 0.5e9 / static_cast<double>(info_.rate_hz);
            if (static_cast<double>(std::llabs(colour_[best].time_ns - depth.time_ns)) <= half_period_ns) {
                const cv::Mat decoded = cv::imdecode(colour_[best].bytes, cv::IMREAD_COLOR);
                const recon::Intrinsics& c = info_.colour_intrinsics;
                if (decoded.empty() || decoded.cols != c.width_px || decoded.rows != c.height_px) {
                    return dataLoss(info_.description + ": the colour image at " +
                                    std::to_string(colour_[best].time_ns / 1000000) +
                                    " ms is not a JPEG of the colour track's size: the file is damaged");
                }
                colour_undistort_.apply(decoded, out.colour_bgr, cv::INTER_LINEAR);
            }
            colour_.erase(colour_.begin(), colour_.begin() + static_cast<std::ptrdiff_t>(best));
        }
        out.timestamp_ns = depth.time_ns + start_offset_ns_;
        out.index = index_++;
        return true;
    }

 private:
    Status readPacket() {
        const int rc = av_read_frame(format_.get(), packet_.get());
        if (rc == AVERROR_EOF) {
            eof_ = true;
            return Status::ok();
        }
        if (rc < 0) {
            return dataLoss(info_.description + ": cannot read on after frame " + std::to_string(index_) + " (" +
                            avError(rc) + "): the file is damaged or cut short");
        }
        const int stream = packet_->stream_index;
        if (stream == depth_stream_ || stream == colour_stream_) {
            const AVRational tb = format_->streams[stream]->time_base;
            Packet p;
            p.time_ns = packet_->pts == AV_NOPTS_VALUE ? 0 : av_rescale_q(packet_->pts, tb, AVRational{1, 1000000000});
            p.bytes.assign(packet_->data, packet_->data + packet_->size);
            if (stream == depth_stream_) last_depth_ns_ = p.time_ns;
            (stream == depth_stream_ ? depth_ : colour_).push_back(std::move(p));
        }
        av_packet_unref(packet_.get());
        return Status::ok();
    }

    // The end of the packets: a clean end when the last depth frame is the one the file's header (its duration)
    // announces; before that the file was cut short, e.g. a copy that did not finish.
    StatusOr<bool> endOfRecording() const {
        if (options_.max_frames > 0 && index_ >= static_cast<uint32_t>(options_.max_frames)) return false;
        if (format_->duration == AV_NOPTS_VALUE || format_->duration <= 0) return false;
        const double duration_s = static_cast<double>(format_->duration) / AV_TIME_BASE;
        const double last_s = last_depth_ns_ < 0 ? -1.0 : static_cast<double>(last_depth_ns_) * 1e-9;
        if (last_s >= duration_s - 1.5 / static_cast<double>(info_.rate_hz)) return false;
        char text[160];
        if (last_s < 0) {
            std::snprintf(text, sizeof(text), "holds no depth frame of its %.2f s", duration_s);
        } else {
            std::snprintf(text, sizeof(text), "ends at %.2f s of its %.2f s", last_s, duration_s);
        }
        return dataLoss(info_.description + " is cut short: it " + text +
                        "; copy the whole recording again (the frames read so far are kept)");
    }

    std::unique_ptr<AVFormatContext, FormatCloser> format_;
    SourceInfo info_;
    int depth_stream_;
    int colour_stream_;
    int64_t start_offset_ns_;
    SourceOptions options_;
    std::unique_ptr<AVPacket, PacketFree> packet_;
    Undistorter depth_undistort_, colour_undistort_;
    std::deque<Packet> depth_, colour_;
    cv::Mat raw_;
    int64_t last_depth_ns_ = -1;
    bool eof_ = false;
    uint32_t index_ = 0;
};

}  // namespace

StatusOr<std::unique_ptr<FrameSource>> openMkvSource(const std::string& path, const SourceOptions& options) {
    av_log_set_level(AV_LOG_QUIET);  // errors come back as Status, each one line
    AVFormatContext* raw_format = nullptr;
    if (const int rc = avformat_open_input(&raw_format, path.c_str(), nullptr, nullptr); rc < 0) {
        return notFound("cannot open the recording '" + path + "' (" + avError(rc) +
                        "): give an Azure Kinect or Femto .mkv, e.g. --source mkv:scan.mkv");
    }
    std::unique_ptr<AVFormatContext, FormatCloser> format(raw_format);
    if (const int rc = avformat_find_stream_info(format.get(), nullptr); rc < 0) {
        return dataLoss("'" + path + "' is not a readable Matroska recording (" + avError(rc) + ")");
    }
    int depth_stream = -1, colour_stream = -1;
    std::string calibration_json;
    for (unsigned i = 0; i < format->nb_streams; ++i) {
        const AVStream* s = format->streams[i];
        const AVCodecParameters* par = s->codecpar;
        const std::string title = tag(s->metadata, "title");
        if (par->codec_type == AVMEDIA_TYPE_ATTACHMENT) {
            if (tag(s->metadata, "filename") == "calibration.json" && par->extradata != nullptr) {
                calibration_json.assign(reinterpret_cast<const char*>(par->extradata),
                                        static_cast<size_t>(par->extradata_size));
            }
        } else if (par->codec_type == AVMEDIA_TYPE_VIDEO && title == "DEPTH") {
            depth_stream = static_cast<int>(i);
        } else if (par->codec_type == AVMEDIA_TYPE_VIDEO && title == "COLOR") {
            colour_stream = static_cast<int>(i);
        }
    }
    const std::string what = "'" + path + "' ";
    if (depth_stream < 0) {
        return dataLoss(what +
                        "has no DEPTH track: not an Azure Kinect/Femto recording, or recorded without depth "
                        "(record with a depth mode, e.g. k4arecorder --depth-mode NFOV_UNBINNED)");
    }
    const AVCodecParameters* dpar = format->streams[depth_stream]->codecpar;
    if (dpar->codec_id != AV_CODEC_ID_RAWVIDEO || dpar->codec_tag != MKTAG('b', '1', '6', 'g')) {
        return dataLoss(what + "has a DEPTH track that is not 16-bit raw depth (b16g): an unknown layout");
    }
    std::string colour_note;
    if (colour_stream >= 0 && options.colour &&
        format->streams[colour_stream]->codecpar->codec_id != AV_CODEC_ID_MJPEG) {
        // Other colour formats (YUY2, NV12, BGRA) are not decoded: replay depth only rather than refuse the scan,
        // and say so where the source is described.
        colour_note = " (colour not MJPG: depth only)";
        colour_stream = -1;
    }
    if (!options.colour) colour_stream = -1;
    if (calibration_json.empty()) {
        return dataLoss(what +
                        "has no calibration.json attachment, so its cameras' intrinsics are unknown: "
                        "replay the original recording (its recorder attaches the calibration)");
    }
    const AVCodecParameters* cpar = colour_stream >= 0 ? format->streams[colour_stream]->codecpar : nullptr;
    StatusOr<AzureKinectCalibration> calibration = parseAzureKinectCalibration(
        calibration_json, dpar->width, dpar->height, cpar ? cpar->width : 0, cpar ? cpar->height : 0);
    if (!calibration.isOk()) return dataLoss(what + calibration.status().message());

    SourceInfo info;
    info.intrinsics = calibration->depth.intrinsics;
    info.depth_units_m = 0.001f;  // b16g depth is in millimetres
    if (options.recording_depth_units_m > 0) info.depth_units_m = options.recording_depth_units_m;
    info.has_colour = colour_stream >= 0;
    info.colour_registered = false;
    if (info.has_colour) {
        info.colour_intrinsics = calibration->colour.intrinsics;
        info.T_colour_depth = calibration->T_colour_depth;
    }
    const AVRational rate = format->streams[depth_stream]->avg_frame_rate;
    const std::string fps = tag(format->metadata, "K4A_FPS");  // "FPS_5", "FPS_15", "FPS_30"
    if (fps.rfind("FPS_", 0) == 0) {
        info.rate_hz = std::strtof(fps.c_str() + 4, nullptr);
    } else if (rate.num > 0 && rate.den > 0) {
        info.rate_hz = static_cast<float>(av_q2d(rate));
    }
    info.is_recording = true;
    info.expected_frames = options.max_frames;  // Matroska does not count frames; 0 = unknown
    info.description = "mkv:" + path + colour_note;
    if (const auto preset = recon::findSensorPreset("azure-kinect"); preset.isOk()) {
        // Femto Bolt and Mega carry the same time-of-flight sensor and write the same recordings.
        info.sensor = preset->sensor;
        info.sensor_known = true;
    }
    int64_t start_offset_ns = 0;
    const std::string offset = tag(format->metadata, "K4A_START_OFFSET_NS");
    if (!offset.empty()) start_offset_ns = std::strtoll(offset.c_str(), nullptr, 10);
    return std::unique_ptr<FrameSource>(std::make_unique<MkvSource>(
        std::move(format), std::move(info), depth_stream, colour_stream, start_offset_ns, *calibration, options));
}

}  // namespace facescan::capture
