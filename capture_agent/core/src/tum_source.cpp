// A TUM RGB-D folder (docs/design.md section 7): rgb.txt and depth.txt list "timestamp path"; depth PNGs are 16-bit;
// intrinsics.txt, when present, holds "fx fy cx cy". Colour is paired with the depth image nearest in time.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <vector>

#include "capture/frame_source.hpp"

namespace facescan::capture {
namespace {
namespace fs = std::filesystem;

struct Entry {
    double timestamp_s = 0;
    std::string path;
};

StatusOr<std::vector<Entry>> readList(const fs::path& file) {
    std::ifstream in(file);
    if (!in) return notFound("cannot read " + file.string());
    std::vector<Entry> entries;
    std::string line;
    int line_no = 0;
    while (std::getline(in, line)) {
        ++line_no;
        if (line.empty() || line[0] == '#') continue;
        std::istringstream fields(line);
        Entry e;
        if (!(fields >> e.timestamp_s >> e.path)) {
            return dataLoss(file.string() + ":" + std::to_string(line_no) + ": expected 'timestamp path'");
        }
        entries.push_back(std::move(e));
    }
    return entries;
}

class TumSource final : public FrameSource {
 public:
    TumSource(fs::path dir, SourceInfo info, std::vector<Entry> depth, std::vector<Entry> rgb, SourceOptions options)
        : dir_(std::move(dir)),
          info_(std::move(info)),
          depth_(std::move(depth)),
          rgb_(std::move(rgb)),
          options_(options) {}

    const SourceInfo& info() const override { return info_; }

    StatusOr<bool> next(CapturedFrame& out) override {
        if (next_ >= depth_.size() || (options_.max_frames > 0 && next_ >= static_cast<size_t>(options_.max_frames))) {
            return false;
        }
        const Entry& d = depth_[next_];
        out.depth_raw = cv::imread((dir_ / d.path).string(), cv::IMREAD_ANYDEPTH);
        if (out.depth_raw.empty() || out.depth_raw.type() != CV_16UC1) {
            return dataLoss("depth image " + (dir_ / d.path).string() + " is missing or not a 16-bit PNG");
        }
        if (out.depth_raw.cols != info_.intrinsics.width_px || out.depth_raw.rows != info_.intrinsics.height_px) {
            return dataLoss("depth image " + d.path + " is " + std::to_string(out.depth_raw.cols) + "x" +
                            std::to_string(out.depth_raw.rows) + ", the sequence is " +
                            std::to_string(info_.intrinsics.width_px) + "x" +
                            std::to_string(info_.intrinsics.height_px));
        }
        out.colour_bgr.release();
        if (info_.has_colour) {
            const Entry& c = nearestRgb(d.timestamp_s);
            out.colour_bgr = cv::imread((dir_ / c.path).string(), cv::IMREAD_COLOR);
            if (out.colour_bgr.empty()) return dataLoss("colour image " + (dir_ / c.path).string() + " unreadable");
            if (out.colour_bgr.size() != out.depth_raw.size()) {
                return dataLoss("colour image " + c.path + " differs in size from its depth image");
            }
        }
        out.timestamp_ns = static_cast<int64_t>(std::llround(d.timestamp_s * 1e9));
        out.index = static_cast<uint32_t>(next_++);
        return true;
    }

 private:
    const Entry& nearestRgb(double t) {
        // Both lists are in time order: advance a cursor instead of searching.
        while (rgb_cursor_ + 1 < rgb_.size() &&
               std::abs(rgb_[rgb_cursor_ + 1].timestamp_s - t) <= std::abs(rgb_[rgb_cursor_].timestamp_s - t)) {
            ++rgb_cursor_;
        }
        return rgb_[rgb_cursor_];
    }

    fs::path dir_;
    SourceInfo info_;
    std::vector<Entry> depth_;
    std::vector<Entry> rgb_;
    SourceOptions options_;
    size_t next_ = 0;
    size_t rgb_cursor_ = 0;
};

}  // namespace

StatusOr<recon::SensorModel> readSensorFile(const fs::path& file) {
    std::ifstream in(file);
    std::string line;
    while (std::getline(in, line) && (line.empty() || line[0] == '#')) {
    }
    std::istringstream fields(line);
    std::string name;
    float min_m = 0, max_m = 0;
    fields >> name;
    const bool has_range = static_cast<bool>(fields >> min_m >> max_m);
    const std::string what = file.string() + " must hold 'NAME [MIN_M MAX_M]' (NAME one of " +
                             recon::sensorPresetNames() + ", or any name with its range in metres)";
    if (name.empty()) return dataLoss(what);
    recon::SensorModel sensor;
    if (const auto preset = recon::findSensorPreset(name); preset.isOk()) {
        sensor = preset->sensor;
    } else if (!has_range) {
        return dataLoss(what + "; '" + name + "' is no preset, so give its range");
    } else {
        sensor.name = name;
        sensor.family = recon::SensorFamily::kUnknown;
        sensor.noise = {};
    }
    if (has_range) {
        sensor.min_depth_m = min_m;
        sensor.max_depth_m = max_m;
    }
    if (const Status valid = sensor.validate(); !valid.isOk()) return dataLoss(file.string() + ": " + valid.message());
    return sensor;
}

StatusOr<std::unique_ptr<FrameSource>> openTumSource(const std::string& dir_text, const SourceOptions& options) {
    const fs::path dir(dir_text);
    if (!fs::is_directory(dir)) return notFound("TUM folder '" + dir_text + "' does not exist");
    ASSIGN_OR_RETURN(std::vector<Entry> depth, readList(dir / "depth.txt"));
    if (depth.empty()) return dataLoss(dir_text + "/depth.txt lists no frames");
    std::vector<Entry> rgb;
    if (options.colour && fs::exists(dir / "rgb.txt")) {
        ASSIGN_OR_RETURN(rgb, readList(dir / "rgb.txt"));
    }

    SourceInfo info;
    // TUM's default intrinsics (the ROS default for Kinect-class cameras) when the folder does not say.
    info.intrinsics = recon::Intrinsics{640, 480, 525.0f, 525.0f, 319.5f, 239.5f};
    if (std::ifstream k(dir / "intrinsics.txt"); k) {
        if (!(k >> info.intrinsics.fx_px >> info.intrinsics.fy_px >> info.intrinsics.cx_px >> info.intrinsics.cy_px)) {
            return dataLoss(dir_text + "/intrinsics.txt must hold 'fx fy cx cy'");
        }
    }
    const cv::Mat first = cv::imread((dir / depth.front().path).string(), cv::IMREAD_ANYDEPTH);
    if (first.empty() || first.type() != CV_16UC1) {
        return dataLoss("first depth image " + (dir / depth.front().path).string() + " is missing or not 16-bit");
    }
    info.intrinsics.width_px = first.cols;
    info.intrinsics.height_px = first.rows;
    info.depth_units_m = options.tum_depth_units_m;
    info.has_colour = !rgb.empty();
    info.colour_registered = true;  // TUM folders hold registered colour (docs/design.md s7)
    info.is_recording = true;
    info.expected_frames = options.max_frames > 0 ? std::min<int>(options.max_frames, static_cast<int>(depth.size()))
                                                  : static_cast<int>(depth.size());
    if (depth.size() > 1) {
        const double span_s = depth.back().timestamp_s - depth.front().timestamp_s;
        if (span_s > 0) info.rate_hz = static_cast<float>((depth.size() - 1) / span_s);
    }
    info.description = "tum:" + dir_text;
    if (fs::exists(dir / "sensor.txt")) {
        ASSIGN_OR_RETURN(info.sensor, readSensorFile(dir / "sensor.txt"));
        info.sensor_known = true;
    }
    return std::unique_ptr<FrameSource>(
        std::make_unique<TumSource>(dir, std::move(info), std::move(depth), std::move(rgb), options));
}

}  // namespace facescan::capture
