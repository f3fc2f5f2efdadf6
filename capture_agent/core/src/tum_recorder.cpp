#include "capture/tum_recorder.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iomanip>
#include <opencv2/imgcodecs.hpp>

#include "wire/private_files.hpp"

namespace facescan::capture {
namespace {
namespace fs = std::filesystem;

// TUM folders hold depth in 1/5000 m, and the tum: source reads them so unless told otherwise.
constexpr double kTumDepthUnitsPerM = 5000.0;
// zlib's fastest level: a VGA depth image in a few ms, so that a stopping agent saves hundreds of frames within
// its stop budget; the files are about a third larger than at the default level.
const std::vector<int> kPngParams = {cv::IMWRITE_PNG_COMPRESSION, 1};

}  // namespace

StatusOr<TumRecorder> TumRecorder::create(const fs::path& dir, const SourceInfo& source, int jpeg_quality) {
    std::error_code ec;
    if (fs::exists(dir, ec) && !fs::is_empty(dir, ec)) {
        return Status(StatusCode::kAlreadyExists, dir.string() + " already exists and is not empty");
    }
    // A recording is a face: owner-only folders, and each file made 0600 as soon as it is written
    // (wire/private_files.hpp); nobody else can enter the folders in between.
    RETURN_IF_ERROR(wire::createPrivateDir(dir / "depth"));
    RETURN_IF_ERROR(wire::createPrivateDir(dir / "rgb"));
    RETURN_IF_ERROR(wire::createPrivateDir(dir));
    TumRecorder r;
    r.dir_ = dir;
    r.source_ = source;
    r.jpeg_quality_ = jpeg_quality;
    std::ofstream intrinsics(dir / "intrinsics.txt");
    const recon::Intrinsics& k = source.intrinsics;
    intrinsics << std::setprecision(9) << k.fx_px << ' ' << k.fy_px << ' ' << k.cx_px << ' ' << k.cy_px << '\n';
    if (source.sensor_known) {
        // The camera travels with the recording: the tum: source reads it back (readSensorFile).
        std::ofstream sensor(dir / "sensor.txt");
        sensor << source.sensor.name << ' ' << std::setprecision(9) << source.sensor.min_depth_m << ' '
               << source.sensor.max_depth_m << '\n';
        if (!sensor.flush()) return unavailable("cannot write in " + dir.string());
        RETURN_IF_ERROR(wire::makeFilePrivate(dir / "sensor.txt"));
    }
    r.depth_list_.open(dir / "depth.txt");
    r.depth_list_ << "# depth images, 16-bit PNG, 5000 units per metre (from " << source.description << ")\n"
                  << "# timestamp filename\n";
    if (!intrinsics.flush() || !r.depth_list_.flush()) return unavailable("cannot write in " + dir.string());
    RETURN_IF_ERROR(wire::makeFilePrivate(dir / "intrinsics.txt"));
    RETURN_IF_ERROR(wire::makeFilePrivate(dir / "depth.txt"));
    return r;
}

Status TumRecorder::addDepth(const cv::Mat& raw, int64_t timestamp_ns, std::string& name) {
    // The source's units to TUM's. A Kinect's millimetres are 5 TUM units each: exact. A depth beyond 16 bits
    // of TUM units (13.1 m) cannot be stored and becomes "no measurement", which no face scan is at.
    const double scale = static_cast<double>(source_.depth_units_m) * kTumDepthUnitsPerM;
    if (std::abs(scale - 1.0) < 1e-6) {
        depth_tum_ = raw;
    } else {
        depth_tum_.create(raw.size(), CV_16UC1);
        for (int y = 0; y < raw.rows; ++y) {
            const uint16_t* in = raw.ptr<uint16_t>(y);
            uint16_t* out = depth_tum_.ptr<uint16_t>(y);
            for (int x = 0; x < raw.cols; ++x) {
                const double v = std::round(in[x] * scale);
                out[x] = v > 65535.0 ? 0 : static_cast<uint16_t>(v);
            }
        }
    }
    char base[32];
    std::snprintf(base, sizeof(base), "%06d", frames_);
    name = base;
    if (!cv::imwrite((dir_ / "depth" / (name + ".png")).string(), depth_tum_, kPngParams)) {
        return unavailable("cannot write " + (dir_ / "depth" / (name + ".png")).string());
    }
    RETURN_IF_ERROR(wire::makeFilePrivate(dir_ / "depth" / (name + ".png")));
    // Timestamps as the source gave them; one frame period on where a source gives none (or repeats one), so
    // that the lists stay in time order and pair colour with its own depth.
    double t = static_cast<double>(timestamp_ns) * 1e-9;
    if (t <= last_timestamp_s_) t = last_timestamp_s_ + 1.0 / (source_.rate_hz > 0 ? source_.rate_hz : 30.0f);
    last_timestamp_s_ = t;
    depth_list_ << std::fixed << std::setprecision(6) << t << " depth/" << name << ".png\n";
    if (!depth_list_.flush()) return unavailable("cannot write " + (dir_ / "depth.txt").string());
    return Status::ok();
}

Status TumRecorder::addColour(const std::string& name, const std::string& extension, const uint8_t* data, size_t size) {
    const fs::path file = dir_ / "rgb" / (name + extension);
    if (data != nullptr) {
        std::ofstream out(file, std::ios::binary);
        out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
        if (!out.flush()) return unavailable("cannot write " + file.string());
    } else if (!cv::imwrite(
                   file.string(), colour_,
                   extension == ".jpg" ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, jpeg_quality_} : kPngParams)) {
        return unavailable("cannot write " + file.string());
    }
    RETURN_IF_ERROR(wire::makeFilePrivate(file));
    if (!has_rgb_list_) {
        rgb_list_.open(dir_ / "rgb.txt");
        rgb_list_ << "# colour images (registered to depth)\n# timestamp filename\n";
        has_rgb_list_ = true;
        if (!rgb_list_.flush()) return unavailable("cannot write " + (dir_ / "rgb.txt").string());
        RETURN_IF_ERROR(wire::makeFilePrivate(dir_ / "rgb.txt"));
    }
    rgb_list_ << std::fixed << std::setprecision(6) << last_timestamp_s_ << " rgb/" << name << extension << '\n';
    if (!rgb_list_.flush()) return unavailable("cannot write " + (dir_ / "rgb.txt").string());
    return Status::ok();
}

Status TumRecorder::add(const wire::EncodedFrame& frame) {
    const int width = source_.intrinsics.width_px, height = source_.intrinsics.height_px;
    RETURN_IF_ERROR(
        wire::decodeDepth(frame.depth_codec, frame.depth.data(), frame.depth.size(), width, height, scratch_));
    std::string name;
    RETURN_IF_ERROR(addDepth(scratch_, frame.source_time_ns, name));
    if (frame.colour_codec == wire::ColourCodecId::kJpeg) {
        RETURN_IF_ERROR(addColour(name, ".jpg", frame.colour.data(), frame.colour.size()));
    } else if (frame.colour_codec == wire::ColourCodecId::kRawBgr) {
        if (frame.colour.size() != static_cast<size_t>(width) * height * 3) {
            return dataLoss("frame " + std::to_string(frame.seq) + ": raw colour of the wrong size");
        }
        colour_ = cv::Mat(height, width, CV_8UC3, const_cast<uint8_t*>(frame.colour.data()));
        RETURN_IF_ERROR(addColour(name, ".png", nullptr, 0));
    }
    ++frames_;
    return Status::ok();
}

Status TumRecorder::add(const CapturedFrame& frame) {
    std::string name;
    RETURN_IF_ERROR(addDepth(frame.depth_raw, frame.timestamp_ns, name));
    if (!frame.colour_bgr.empty()) {
        colour_ = frame.colour_bgr;
        RETURN_IF_ERROR(addColour(name, ".jpg", nullptr, 0));
    }
    ++frames_;
    return Status::ok();
}

StatusOr<fs::path> createFreshDir(const fs::path& parent, const std::string& name) {
    std::error_code ec;
    RETURN_IF_ERROR(wire::createPrivateDir(parent));  // the saved frames of every scan: owner-only
    for (int n = 1; n < 1000; ++n) {
        const fs::path dir = parent / (n == 1 ? name : name + "-" + std::to_string(n));
        // create_directory is false for a folder that exists: never one that someone else made.
        if (fs::create_directory(dir, ec)) {
            fs::permissions(dir, fs::perms::owner_all, ec);  // before anything is written in it
            if (ec) return unavailable("cannot make " + dir.string() + " private: " + ec.message());
            return dir;
        }
        if (ec) return unavailable("cannot create " + dir.string() + ": " + ec.message());
    }
    return unavailable("no free folder name for " + name + " in " + parent.string());
}

fs::path defaultSaveDir() {
    if (const char* state = std::getenv("XDG_STATE_HOME"); state != nullptr && *state == '/') {
        return fs::path(state) / "facescan" / "unconfirmed";
    }
    if (const char* home = std::getenv("HOME"); home != nullptr && *home == '/') {
        return fs::path(home) / ".local" / "state" / "facescan" / "unconfirmed";
    }
    return fs::current_path() / "facescan-unconfirmed";
}

}  // namespace facescan::capture
