// bag:FILE -- Intel RealSense recordings: ROS 1 bags in librealsense's layout, read with ROS's rosbag storage
// library. Per stream (s the sensor, i the stream index):
//   /device_0/sensor_s/Depth_i/image/data         sensor_msgs/Image, 16UC1 (or mono16) in depth units
//   /device_0/sensor_s/Color_i/image/data         sensor_msgs/Image, rgb8 / bgr8 / rgba8 / bgra8
//   /device_0/sensor_s/<stream>/info/camera_info  sensor_msgs/CameraInfo (size, K)
//   /device_0/sensor_s/<stream>/tf/<ref>          geometry_msgs/Transform: reference stream (depth) to this one
//   /device_0/sensor_s/option/Depth Units/value   std_msgs/Float32, metres per depth unit (absent: 1 mm)
// D400 depth is computed on rectified stereo images and the colour cameras' calibrations are (near) distortion-free,
// so the recorded K is used as a pinhole (the thesis' projection, eq. 2.1) and the distortion coefficients are not
// applied. Colour is paired with the depth frame nearest in time.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>
#include <functional>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <regex>

#include "capture/recording_sources.hpp"
#include "capture/ros_messages.hpp"

namespace facescan::capture {
namespace {

using ros1::CameraInfo;
using ros1::Image;

struct Streams {
    std::string depth, colour;                       // image/data topics (colour empty: none)
    std::string depth_info, colour_info, colour_tf;  // their camera_info and the colour's extrinsics
    std::string depth_units;                         // the depth sensor's Depth Units option
};

// The prefix /device_0/sensor_s/Stream_i of an image/data topic.
std::string prefixOf(const std::string& data_topic) { return data_topic.substr(0, data_topic.size() - 11); }

Streams findStreams(rosbag::Bag& bag) {
    Streams s;
    const std::regex image(R"(^/device_\d+/sensor_(\d+)/(Depth|Color)_\d+/image/data$)");
    rosbag::View all(bag);
    for (const rosbag::ConnectionInfo* c : all.getConnections()) {
        std::smatch m;
        if (!std::regex_match(c->topic, m, image)) continue;
        std::string& slot = m[2] == "Depth" ? s.depth : s.colour;
        if (slot.empty() || c->topic < slot) slot = c->topic;  // the first stream of its kind
    }
    for (const rosbag::ConnectionInfo* c : all.getConnections()) {
        if (!s.depth.empty() && c->topic == prefixOf(s.depth) + "/info/camera_info") s.depth_info = c->topic;
        if (!s.colour.empty() && c->topic == prefixOf(s.colour) + "/info/camera_info") s.colour_info = c->topic;
        if (!s.colour.empty() && c->topic.rfind(prefixOf(s.colour) + "/tf/", 0) == 0) s.colour_tf = c->topic;
        if (!s.depth.empty()) {
            const std::string sensor = s.depth.substr(0, s.depth.find('/', s.depth.find("sensor_")));
            if (c->topic == sensor + "/option/Depth Units/value") s.depth_units = c->topic;
        }
    }
    return s;
}

template <typename Msg>
std::optional<typename Msg::ConstPtr> firstMessage(rosbag::Bag& bag, const std::string& topic) {
    if (topic.empty()) return std::nullopt;
    rosbag::View view(bag, rosbag::TopicQuery(topic));
    for (const rosbag::MessageInstance& m : view) {
        if (auto msg = m.instantiate<Msg>()) return msg;
    }
    return std::nullopt;
}

StatusOr<recon::Intrinsics> intrinsicsOf(const CameraInfo& info, const std::string& topic) {
    recon::Intrinsics k{static_cast<int>(info.width),  static_cast<int>(info.height), static_cast<float>(info.K[0]),
                        static_cast<float>(info.K[4]), static_cast<float>(info.K[2]), static_cast<float>(info.K[5])};
    if (k.width_px < 16 || k.height_px < 16 || k.width_px > 4096 || k.height_px > 4096 || !(k.fx_px > 1) ||
        !(k.fy_px > 1) || !std::isfinite(k.fx_px) || !std::isfinite(k.fy_px) || !std::isfinite(k.cx_px) ||
        !std::isfinite(k.cy_px)) {
        return dataLoss(topic + " holds no usable camera (size 16..4096 px, focal lengths > 1 px)");
    }
    return k;
}

int64_t stampNs(const Image& image, const rosbag::MessageInstance& m) {
    const ros::Time t = image.header.stamp.isZero() ? m.getTime() : image.header.stamp;
    return static_cast<int64_t>(t.sec) * 1000000000 + t.nsec;
}

struct Pending {
    Image::ConstPtr image;
    int64_t time_ns = 0;
};

class BagSource final : public FrameSource {
 public:
    BagSource(std::unique_ptr<rosbag::Bag> bag, Streams streams, SourceInfo info, SourceOptions options)
        : bag_(std::move(bag)), streams_(std::move(streams)), info_(std::move(info)), options_(options) {
        std::vector<std::string> topics{streams_.depth};
        if (info_.has_colour) topics.push_back(streams_.colour);
        view_ = std::make_unique<rosbag::View>(*bag_, rosbag::TopicQuery(topics));
        it_ = view_->begin();
    }

    const SourceInfo& info() const override { return info_; }

    StatusOr<bool> next(CapturedFrame& out) override {
        if (options_.max_frames > 0 && index_ >= static_cast<uint32_t>(options_.max_frames)) return false;
        try {
            while (depth_.empty() && it_ != view_->end()) RETURN_IF_ERROR(readMessage());
            if (depth_.empty()) return false;
            const Pending depth = std::move(depth_.front());
            depth_.pop_front();
            while (info_.has_colour && it_ != view_->end() &&
                   (colour_.empty() || colour_.back().time_ns < depth.time_ns) && depth_.size() < 8) {
                RETURN_IF_ERROR(readMessage());
            }
            RETURN_IF_ERROR(toDepth(*depth.image, out.depth_raw));
            out.colour_bgr.release();
            if (!colour_.empty()) {
                size_t best = 0;
                for (size_t i = 1; i < colour_.size(); ++i) {
                    if (std::llabs(colour_[i].time_ns - depth.time_ns) <=
                        std::llabs(colour_[best].time_ns - depth.time_ns))
                        best = i;
                }
                const double half_period_ns = 0.5e9 / static_cast<double>(info_.rate_hz);
                if (static_cast<double>(std::llabs(colour_[best].time_ns - depth.time_ns)) <= half_period_ns) {
                    RETURN_IF_ERROR(toColour(*colour_[best].image, out.colour_bgr));
                }
                colour_.erase(colour_.begin(), colour_.begin() + static_cast<std::ptrdiff_t>(best));
            }
            out.timestamp_ns = depth.time_ns;
            out.index = index_++;
            return true;
        } catch (const std::exception& e) {  // rosbag reports a damaged chunk or message by throwing
            return dataLoss(info_.description + ": cannot read on after frame " + std::to_string(index_) + " (" +
                            e.what() + "): the file is damaged or cut short");
        }
    }

 private:
    Status readMessage() {
        const rosbag::MessageInstance& m = *it_;
        auto image = m.instantiate<Image>();
        if (!image) return dataLoss(info_.description + ": " + m.getTopic() + " does not hold sensor_msgs/Image");
        (m.getTopic() == streams_.depth ? depth_ : colour_).push_back({image, stampNs(*image, m)});
        ++it_;
        return Status::ok();
    }

    Status toDepth(const Image& image, cv::Mat& out) const {
        const recon::Intrinsics& k = info_.intrinsics;
        if (image.encoding != "16UC1" && image.encoding != "mono16") {
            return dataLoss(info_.description + ": depth frame " + std::to_string(index_) + " is '" +
                            std::string(image.encoding.begin(), image.encoding.end()) +
                            "', not 16-bit depth (16UC1/mono16)");
        }
        if (static_cast<int>(image.width) != k.width_px || static_cast<int>(image.height) != k.height_px ||
            image.step < image.width * 2 || image.data.size() < static_cast<size_t>(image.step) * image.height) {
            return dataLoss(info_.description + ": depth frame " + std::to_string(index_) + " is not a " +
                            std::to_string(k.width_px) + "x" + std::to_string(k.height_px) +
                            " image as its camera_info says: the file is damaged");
        }
        const cv::Mat view(k.height_px, k.width_px, CV_16UC1, const_cast<uint8_t*>(image.data.data()), image.step);
        view.copyTo(out);
        if (image.is_bigendian) {
            for (int v = 0; v < out.rows; ++v) {
                auto* row = out.ptr<uint16_t>(v);
                for (int u = 0; u < out.cols; ++u) row[u] = static_cast<uint16_t>((row[u] >> 8) | (row[u] << 8));
            }
        }
        return Status::ok();
    }

    Status toColour(const Image& image, cv::Mat& out) const {
        const recon::Intrinsics& c = info_.colour_intrinsics;
        const std::string e(image.encoding.begin(), image.encoding.end());
        const int channels = (e == "rgb8" || e == "bgr8") ? 3 : (e == "rgba8" || e == "bgra8") ? 4 : 0;
        if (channels == 0 || static_cast<int>(image.width) != c.width_px ||
            static_cast<int>(image.height) != c.height_px ||
            image.step < image.width * static_cast<uint32_t>(channels) ||
            image.data.size() < static_cast<size_t>(image.step) * image.height) {
            return dataLoss(info_.description + ": colour frame '" + e + "' " + std::to_string(image.width) + "x" +
                            std::to_string(image.height) + " is not the " + std::to_string(c.width_px) + "x" +
                            std::to_string(c.height_px) + " rgb8/bgr8 image its camera_info says (or use --no-colour)");
        }
        const cv::Mat view(c.height_px, c.width_px, CV_8UC(channels), const_cast<uint8_t*>(image.data.data()),
                           image.step);
        if (e == "rgb8") cv::cvtColor(view, out, cv::COLOR_RGB2BGR);
        if (e == "bgr8") view.copyTo(out);
        if (e == "rgba8") cv::cvtColor(view, out, cv::COLOR_RGBA2BGR);
        if (e == "bgra8") cv::cvtColor(view, out, cv::COLOR_BGRA2BGR);
        return Status::ok();
    }

    std::unique_ptr<rosbag::Bag> bag_;
    Streams streams_;
    SourceInfo info_;
    SourceOptions options_;
    std::unique_ptr<rosbag::View> view_;
    rosbag::View::iterator it_;
    std::deque<Pending> depth_, colour_;
    uint32_t index_ = 0;
};

// ROS's bag library trusts the lengths and positions it reads (a damaged file makes it read past its buffers), so
// the record structure of a ROS bag 2.0 file is checked first: every record's header and data, and every header
// field, lie inside the file (inside its record), a connection record's data is a list of fields too, the records
// inside uncompressed chunks are checked the same way, and the positions the bag header and chunk infos point at
// (index_pos, chunk_pos) are starts of records. Compressed chunks' insides are left to the library.
Status checkBagStructure(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    const std::vector<char> d((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto u32 = [&](size_t at) {
        uint32_t v = 0;
        std::memcpy(&v, d.data() + at, 4);  // little-endian on the machines facescan runs on
        return static_cast<size_t>(v);
    };
    std::vector<size_t> starts, targets;  // top-level record starts; positions the file points at
    std::vector<int> ops;                 // the op of each top-level record
    size_t index_pos = 0, conn_count = 0, chunk_count = 0;
    // A list of fields "len name=value" filling [at, end); calls `field(name, value)` on each.
    const auto fields = [&](size_t at, size_t end,
                            const std::function<void(const std::string&, const std::string&)>& field) {
        while (at < end) {
            if (end - at < 4 || u32(at) > end - at - 4) return false;
            const std::string text(d.data() + at + 4, u32(at));
            const size_t eq = text.find('=');
            if (eq == std::string::npos) return false;
            field(text.substr(0, eq), text.substr(eq + 1));
            at += 4 + u32(at);
        }
        return true;
    };
    const auto position = [](const std::string& value) {
        uint64_t v = 0;
        std::memcpy(&v, value.data(), std::min<size_t>(8, value.size()));
        return static_cast<size_t>(v);
    };
    const std::function<bool(size_t, size_t, int)> records = [&](size_t at, size_t end, int depth) {
        while (at < end) {
            if (depth == 0) starts.push_back(at);
            if (end - at < 4 || u32(at) > end - at - 4) return false;
            const size_t header = at + 4, header_end = header + u32(at);
            int op = -1;
            bool compressed = false;
            const bool ok = fields(header, header_end, [&](const std::string& name, const std::string& value) {
                if (name == "op" && value.size() == 1) op = static_cast<unsigned char>(value[0]);
                if (name == "compression") compressed = value != "none";
                if ((name == "index_pos" || name == "chunk_pos") && value.size() == 8) {
                    targets.push_back(position(value));
                }
                if (depth == 0 && name == "index_pos" && value.size() == 8) index_pos = position(value);
                if (depth == 0 && name == "conn_count" && value.size() == 4) conn_count = position(value);
                if (depth == 0 && name == "chunk_count" && value.size() == 4) chunk_count = position(value);
            });
            if (!ok) return false;
            if (depth == 0) ops.push_back(op);
            if (end - header_end < 4 || u32(header_end) > end - header_end - 4) return false;
            const size_t data = header_end + 4, data_end = data + u32(header_end);
            if (op == 0x05 && !compressed && depth == 0 && !records(data, data_end, 1)) return false;
            if (op == 0x07 && !fields(data, data_end, [](const std::string&, const std::string&) {})) return false;
            at = data_end;
        }
        return true;
    };
    bool ok = d.size() >= 13 && records(13, d.size(), 0);
    for (const size_t target : targets) {
        if (ok && !std::binary_search(starts.begin(), starts.end(), target)) ok = false;
    }
    if (ok) {
        // From index_pos on the library reads conn_count connection records, then chunk_count chunk infos.
        const auto first = std::lower_bound(starts.begin(), starts.end(), index_pos);
        const auto from = static_cast<size_t>(first - starts.begin());
        size_t conns = 0, infos = 0;
        for (size_t i = from; i < ops.size(); ++i) {
            conns += ops[i] == 0x07 ? 1 : 0;
            infos += ops[i] == 0x06 ? 1 : 0;
        }
        if (index_pos == 0 || conns < conn_count || infos < chunk_count) ok = false;
    }
    if (!ok) {
        return dataLoss("'" + path +
                        "' is cut short or damaged: its records do not fit together; copy the whole "
                        "recording again");
    }
    return Status::ok();
}

}  // namespace

StatusOr<std::unique_ptr<FrameSource>> openBagSource(const std::string& path, const SourceOptions& options) {
    {
        char magic[13] = {};
        std::ifstream(path, std::ios::binary).read(magic, sizeof(magic));
        if (std::string(magic, sizeof(magic)) == "#ROSBAG V2.0\n") RETURN_IF_ERROR(checkBagStructure(path));
    }
    auto bag = std::make_unique<rosbag::Bag>();
    try {
        bag->open(path, rosbag::bagmode::Read);
    } catch (const std::exception& e) {
        char magic[13] = {};
        std::ifstream(path, std::ios::binary).read(magic, sizeof(magic));
        if (std::string(magic, sizeof(magic)) == "#ROSBAG V2.0\n") {
            // A bag's index is written when it is closed: without it the recording was cut short.
            return dataLoss("'" + path + "' is a ROS bag that is cut short or was never closed (" + e.what() +
                            "): copy the whole recording again, or rebuild its index with `rosbag reindex`");
        }
        return notFound("cannot open the recording '" + path + "' (" + e.what() +
                        "): give a RealSense .bag, e.g. --source bag:scan.bag");
    }
    try {
        const Streams streams = findStreams(*bag);
        const std::string what = "'" + path + "' ";
        if (streams.depth.empty()) {
            return dataLoss(what +
                            "has no /device_N/sensor_N/Depth_N/image/data topic: not a RealSense recording, "
                            "or recorded without depth (record the depth stream too)");
        }
        if (streams.depth_info.empty()) {
            return dataLoss(what + "has no camera_info for " + prefixOf(streams.depth) +
                            ", so the depth camera's intrinsics are unknown: replay the original recording");
        }
        SourceInfo info;
        const auto depth_info = firstMessage<CameraInfo>(*bag, streams.depth_info);
        if (!depth_info) return dataLoss(what + streams.depth_info + " holds no sensor_msgs/CameraInfo");
        auto depth_k = intrinsicsOf(**depth_info, streams.depth_info);
        if (!depth_k.isOk()) return dataLoss(what + depth_k.status().message());
        info.intrinsics = *depth_k;
        info.depth_units_m = 0.001f;
        if (const auto units = firstMessage<ros1::Float32>(*bag, streams.depth_units)) {
            info.depth_units_m = (*units)->data;
            if (!(info.depth_units_m > 1e-6f && info.depth_units_m <= 0.01f)) {
                return dataLoss(what + "says its depth units are " + std::to_string((*units)->data) +
                                " m, outside (1e-6, 0.01]: the option is damaged");
            }
        }
        if (options.recording_depth_units_m > 0) info.depth_units_m = options.recording_depth_units_m;
        info.has_colour = options.colour && !streams.colour.empty() && !streams.colour_info.empty();
        std::string colour_note;
        info.colour_registered = false;
        if (info.has_colour) {
            const auto colour_info = firstMessage<CameraInfo>(*bag, streams.colour_info);
            if (!colour_info) return dataLoss(what + streams.colour_info + " holds no sensor_msgs/CameraInfo");
            auto colour_k = intrinsicsOf(**colour_info, streams.colour_info);
            if (!colour_k.isOk()) return dataLoss(what + colour_k.status().message());
            info.colour_intrinsics = *colour_k;
            // Colour in another encoding (YUYV, a Bayer pattern) is not converted: replay depth only, and say so.
            if (const auto first = firstMessage<Image>(*bag, streams.colour)) {
                const std::string e((*first)->encoding.begin(), (*first)->encoding.end());
                if (e != "rgb8" && e != "bgr8" && e != "rgba8" && e != "bgra8") {
                    info.has_colour = false;
                    colour_note = " (colour " + e + " is not rgb8/bgr8: depth only)";
                }
            }
            if (const auto tf = firstMessage<ros1::Transform>(*bag, streams.colour_tf)) {
                const auto& q = (*tf)->rotation;
                const auto& t = (*tf)->translation;
                const Eigen::Quaternionf rotation(static_cast<float>(q.w), static_cast<float>(q.x),
                                                  static_cast<float>(q.y), static_cast<float>(q.z));
                if (!(std::abs(rotation.norm() - 1.0f) < 1e-3f) || !std::isfinite(t.x) || !std::isfinite(t.y) ||
                    !std::isfinite(t.z)) {
                    return dataLoss(what + streams.colour_tf + " is no rotation and translation");
                }
                info.T_colour_depth.linear() = rotation.toRotationMatrix();
                info.T_colour_depth.translation() =
                    Eigen::Vector3f(static_cast<float>(t.x), static_cast<float>(t.y), static_cast<float>(t.z));
            }
        }
        if (!info.has_colour) {
            info.colour_intrinsics = recon::Intrinsics{0, 0, 0.0f, 0.0f, 0.0f, 0.0f};
            info.T_colour_depth = recon::Pose::Identity();
        }
        rosbag::View depth_view(*bag, rosbag::TopicQuery(streams.depth));
        const int frames = static_cast<int>(depth_view.size());
        if (frames == 0) return dataLoss(what + "holds no depth frame");
        const double span_s = (depth_view.getEndTime() - depth_view.getBeginTime()).toSec();
        info.rate_hz = frames > 1 && span_s > 0 ? static_cast<float>((frames - 1) / span_s) : 30.0f;
        info.is_recording = true;
        info.expected_frames = options.max_frames > 0 ? std::min(options.max_frames, frames) : frames;
        info.description = "bag:" + path + colour_note;
        if (const auto preset = recon::findSensorPreset("realsense-d415"); preset.isOk()) {
            info.sensor = preset->sensor;  // the D400 family's active stereo
            info.sensor_known = true;
        }
        return std::unique_ptr<FrameSource>(
            std::make_unique<BagSource>(std::move(bag), streams, std::move(info), options));
    } catch (const std::exception& e) {
        return dataLoss("'" + path + "' is not a readable RealSense recording (" + e.what() + ")");
    }
}

}  // namespace facescan::capture
