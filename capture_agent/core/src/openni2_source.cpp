// OpenNI2 frame sources: a live device (`openni2[:URI]`) and playback of a recording (`oni:FILE`).
//
// Live: depth 640x480@30 in mm (the closest mode the device offers), colour RGB888 registered to depth and
// depth/colour frame sync where the device supports them. next() waits with OpenNI::waitForAnyStream in slices
// of two frame periods; a device that raises OpenNI's disconnected event, or delivers nothing for a second,
// ends the stream with an error Status instead of blocking forever.
// Playback: manual speed (each wait advances the player by one record), no repeat, exactly
// getNumberOfFrames() depth frames, then a clean end, and the device is CLOSED at the end because OpenNI's
// player thread spins at end of file until its device is closed.
#include <OpenNI.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <thread>

#include "capture/frame_source.hpp"

namespace facescan::capture {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kWantWidthPx = 640, kWantHeightPx = 480, kWantFps = 30;
// A live device that has delivered frames and then delivers none for this long is taken as gone. The first frame
// of a real camera can take a second or two after start (USB set-up, auto exposure), hence the longer limit.
constexpr auto kLiveSilenceLimit = std::chrono::milliseconds(1000);
constexpr auto kLiveFirstFrameLimit = std::chrono::milliseconds(5000);
// A recording's player answers a manual trigger at once; this long without the next record means it is corrupt.
constexpr auto kFileSilenceLimit = std::chrono::milliseconds(3000);
// Between stopping a recording's streams and destroying them: several of the file player's 10 ms idle sleeps (see
// close()).
constexpr auto kPlayerSettle = std::chrono::milliseconds(50);
// Colour reads per depth frame while looking for the matching colour (synced pairs need one).
constexpr int kMaxColourReads = 4;

std::string oniError() {
    const char* e = openni::OpenNI::getExtendedError();
    std::string s = (e != nullptr && *e != '\0') ? e : "no details from OpenNI";
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
    return s;
}

const char* pixelFormatName(openni::PixelFormat f) {
    switch (f) {
        case openni::PIXEL_FORMAT_DEPTH_1_MM: return "depth 1 mm";
        case openni::PIXEL_FORMAT_DEPTH_100_UM: return "depth 100 um";
        case openni::PIXEL_FORMAT_SHIFT_9_2: return "shift 9.2";
        case openni::PIXEL_FORMAT_SHIFT_9_3: return "shift 9.3";
        case openni::PIXEL_FORMAT_RGB888: return "RGB888";
        case openni::PIXEL_FORMAT_YUV422: return "YUV422";
        case openni::PIXEL_FORMAT_GRAY8: return "gray8";
        case openni::PIXEL_FORMAT_GRAY16: return "gray16";
        case openni::PIXEL_FORMAT_JPEG: return "JPEG";
        default: return "unknown";
    }
}

std::string modeText(const openni::VideoMode& m) {
    std::ostringstream s;
    s << m.getResolutionX() << "x" << m.getResolutionY() << "@" << m.getFps() << " "
      << pixelFormatName(m.getPixelFormat());
    return s.str();
}

// Metres per raw unit of a depth pixel format; 0 for formats we cannot use (raw disparity shifts).
float depthUnitsM(openni::PixelFormat f) {
    if (f == openni::PIXEL_FORMAT_DEPTH_1_MM) return 0.001f;
    if (f == openni::PIXEL_FORMAT_DEPTH_100_UM) return 0.0001f;
    return 0.0f;
}

// OpenNI::initialize once per process for as long as any source uses it; shutdown when the last one goes.
class OpenNiRuntime {
 public:
    static StatusOr<std::shared_ptr<OpenNiRuntime>> acquire() {
        static std::mutex mutex;
        static std::weak_ptr<OpenNiRuntime> current;
        std::lock_guard<std::mutex> lock(mutex);
        if (auto live = current.lock()) return live;
        if (openni::OpenNI::initialize() != openni::STATUS_OK) {
            return unavailable("OpenNI2 failed to initialise: " + oniError());
        }
        std::shared_ptr<OpenNiRuntime> runtime(new OpenNiRuntime());
        current = runtime;
        return runtime;
    }
    ~OpenNiRuntime() { openni::OpenNI::shutdown(); }

 private:
    OpenNiRuntime() = default;
};

// OpenNI raises device-disconnected on the driver's thread; next() polls the flag between waits.
class DisconnectWatch final : public openni::OpenNI::DeviceDisconnectedListener {
 public:
    explicit DisconnectWatch(std::string uri) : uri_(std::move(uri)) {}
    void onDeviceDisconnected(const openni::DeviceInfo* info) override {
        if (info != nullptr && uri_ == info->getUri()) gone_ = true;
    }
    bool gone() const { return gone_.load(); }

 private:
    std::string uri_;
    std::atomic<bool> gone_{false};
};

std::string deviceList() {
    openni::Array<openni::DeviceInfo> devices;
    openni::OpenNI::enumerateDevices(&devices);
    if (devices.getSize() == 0) {
        return "no OpenNI2 device is connected (is the camera plugged in and powered? a Kinect v1 needs "
               "deploy/install-kinect-driver.sh; PrimeSense/Asus Xtion work out of the box)";
    }
    std::string s = "connected devices:";
    for (int i = 0; i < devices.getSize(); ++i) {
        s +=
            std::string(" '") + devices[i].getUri() + "' (" + devices[i].getVendor() + " " + devices[i].getName() + ")";
    }
    return s;
}

// The supported mode closest to 640x480@30 in `formats` (earlier formats preferred on ties).
const openni::VideoMode* closestMode(const openni::SensorInfo& sensor,
                                     std::initializer_list<openni::PixelFormat> formats) {
    const openni::Array<openni::VideoMode>& modes = sensor.getSupportedVideoModes();
    const openni::VideoMode* best = nullptr;
    double best_cost = 0;
    for (int i = 0; i < modes.getSize(); ++i) {
        int rank = 0;
        for (openni::PixelFormat f : formats) {
            if (modes[i].getPixelFormat() == f) break;
            ++rank;
        }
        if (rank == static_cast<int>(formats.size())) continue;
        const double cost = std::abs(modes[i].getResolutionX() - kWantWidthPx) +
                            std::abs(modes[i].getResolutionY() - kWantHeightPx) +
                            10.0 * std::abs(modes[i].getFps() - kWantFps) + 1000.0 * rank;
        if (best == nullptr || cost < best_cost) {
            best = &modes[i];
            best_cost = cost;
        }
    }
    return best;
}

class OpenNi2Source final : public FrameSource {
 public:
    OpenNi2Source(std::shared_ptr<OpenNiRuntime> runtime, SourceOptions options, bool is_file)
        : runtime_(std::move(runtime)), options_(options), is_file_(is_file) {}
    ~OpenNi2Source() override { close(); }

    Status open(const std::string& uri_or_path);
    const SourceInfo& info() const override { return info_; }
    StatusOr<bool> next(CapturedFrame& out) override;

 private:
    Status openDepth();
    void openColour();
    void describeSensor();
    void computeIntrinsics(const openni::VideoMode& mode);
    Status waitDepth(openni::VideoFrameRef& frame);
    void pairColour(const openni::VideoFrameRef& depth);
    void close();

    std::shared_ptr<OpenNiRuntime> runtime_;
    SourceOptions options_;
    bool is_file_;
    SourceInfo info_;
    std::string name_;  // for messages: the URI or the file
    openni::Device device_;
    openni::VideoStream depth_, colour_;
    bool has_colour_stream_ = false;
    bool mirrored_ = false;  // data arrives mirrored and the device cannot turn that off: flip it back
    std::unique_ptr<DisconnectWatch> watch_;
    openni::PlaybackControl* playback_ = nullptr;
    openni::VideoFrameRef latest_colour_;
    cv::Mat colour_rgb_;  // scratch
    uint32_t delivered_ = 0;
    Status failed_;  // sticky: once the device is gone, every next() says so
    bool ended_ = false;
};

Status OpenNi2Source::open(const std::string& uri_or_path) {
    name_ = uri_or_path;
    const char* uri = uri_or_path.empty() ? openni::ANY_DEVICE : uri_or_path.c_str();
    if (device_.open(uri) != openni::STATUS_OK) {
        if (is_file_) return dataLoss("oni: cannot open recording '" + uri_or_path + "': " + oniError());
        const std::string which =
            uri_or_path.empty() ? "the first OpenNI2 device" : "OpenNI2 device '" + uri_or_path + "'";
        return notFound("openni2: cannot open " + which + ": " + oniError() + "; " + deviceList());
    }
    const openni::DeviceInfo& dev = device_.getDeviceInfo();
    if (!is_file_) {
        name_ = dev.getUri();
        watch_ = std::make_unique<DisconnectWatch>(name_);
        openni::OpenNI::addDeviceDisconnectedListener(watch_.get());
    } else {
        playback_ = device_.getPlaybackControl();
        if (playback_ == nullptr || !playback_->isValid())
            return internalError("oni: '" + name_ + "' opened without a player");
        // Manual speed: the player reads the next record only when a wait asks for it, so no frame is skipped
        // however slowly the consumer reads. No repeat: the recording plays once.
        if (playback_->setSpeed(-1.0f) != openni::STATUS_OK ||
            playback_->setRepeatEnabled(false) != openni::STATUS_OK) {
            return internalError("oni: cannot set manual playback on '" + name_ + "': " + oniError());
        }
    }
    RETURN_IF_ERROR(openDepth());
    if (options_.colour) openColour();

    if (depth_.start() != openni::STATUS_OK)
        return unavailable("openni2: cannot start the depth stream of '" + name_ + "': " + oniError());
    if (has_colour_stream_ && colour_.start() != openni::STATUS_OK) {
        colour_.destroy();  // depth alone is still a scan
        has_colour_stream_ = false;
        info_.has_colour = false;
    }

    std::ostringstream d;
    d << (is_file_ ? "oni:" : "openni2:") << name_ << " (";
    if (!is_file_) d << dev.getVendor() << " " << dev.getName() << ", ";
    d << "depth " << modeText(depth_.getVideoMode());
    if (has_colour_stream_)
        d << ", colour " << modeText(colour_.getVideoMode())
          << (info_.colour_registered ? " registered" : " not registered");
    if (!is_file_ && has_colour_stream_) d << (device_.getDepthColorSyncEnabled() ? ", synced" : ", not synced");
    if (mirrored_) d << ", un-mirrored in software";
    if (is_file_) d << ", " << info_.expected_frames << " frames";
    d << ")";
    info_.description = d.str();
    return Status::ok();
}

Status OpenNi2Source::openDepth() {
    if (!device_.hasSensor(openni::SENSOR_DEPTH)) return notFound("openni2: '" + name_ + "' has no depth sensor");
    if (depth_.create(device_, openni::SENSOR_DEPTH) != openni::STATUS_OK) {
        return unavailable("openni2: cannot create the depth stream of '" + name_ + "': " + oniError());
    }
    if (!is_file_) {
        const openni::SensorInfo* sensor = device_.getSensorInfo(openni::SENSOR_DEPTH);
        const openni::VideoMode* mode =
            sensor ? closestMode(*sensor, {openni::PIXEL_FORMAT_DEPTH_1_MM, openni::PIXEL_FORMAT_DEPTH_100_UM})
                   : nullptr;
        if (mode == nullptr) return notFound("openni2: '" + name_ + "' offers no depth mode in mm or 100 um");
        if (depth_.setVideoMode(*mode) != openni::STATUS_OK) {
            return unavailable("openni2: '" + name_ + "' refused depth mode " + modeText(*mode) + ": " + oniError());
        }
        // Mirrored depth flips the scene's handedness; turn it off, or undo it ourselves if the device cannot.
        depth_.setMirroringEnabled(false);
    }
    mirrored_ = depth_.getMirroringEnabled();
    const openni::VideoMode mode = depth_.getVideoMode();
    info_.depth_units_m = depthUnitsM(mode.getPixelFormat());
    if (info_.depth_units_m <= 0 || mode.getResolutionX() <= 0 || mode.getResolutionY() <= 0) {
        return invalidArgument("openni2: '" + name_ + "' delivers depth as " + modeText(mode) +
                               "; need depth in mm or 100 um");
    }
    info_.rate_hz = mode.getFps() > 0 ? static_cast<float>(mode.getFps()) : 30.0f;
    info_.is_recording = is_file_;
    info_.has_colour = false;
    info_.colour_registered = false;
    computeIntrinsics(mode);
    describeSensor();
    if (is_file_) {
        const int frames = playback_->getNumberOfFrames(depth_);
        if (frames <= 0) return dataLoss("oni: '" + name_ + "' holds no depth frames");
        info_.expected_frames = options_.max_frames > 0 ? std::min(frames, options_.max_frames) : frames;
    }
    return Status::ok();
}

void OpenNi2Source::openColour() {
    if (!device_.hasSensor(openni::SENSOR_COLOR)) return;
    if (colour_.create(device_, openni::SENSOR_COLOR) != openni::STATUS_OK) return;
    if (!is_file_) {
        const openni::SensorInfo* sensor = device_.getSensorInfo(openni::SENSOR_COLOR);
        const openni::VideoMode* mode = sensor ? closestMode(*sensor, {openni::PIXEL_FORMAT_RGB888}) : nullptr;
        if (mode == nullptr || colour_.setVideoMode(*mode) != openni::STATUS_OK) {
            colour_.destroy();
            return;
        }
        colour_.setMirroringEnabled(mirrored_);  // same orientation as depth, so one flip undoes both
        // Registration maps depth into the colour camera so that pixel (u, v) of both sees the same point.
        if (device_.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) &&
            device_.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) == openni::STATUS_OK) {
            info_.colour_registered = true;
        }
        device_.setDepthColorSyncEnabled(true);  // best effort: pairs are matched by timestamp anyway
    } else {
        // A recording does not store the device's registration mode; like TUM folders (docs/design.md s7), colour is
        // taken as registered unless the player says otherwise.
        info_.colour_registered = device_.getImageRegistrationMode() != openni::IMAGE_REGISTRATION_OFF ||
                                  !device_.isPropertySupported(openni::DEVICE_PROPERTY_IMAGE_REGISTRATION);
    }
    if (colour_.getVideoMode().getPixelFormat() != openni::PIXEL_FORMAT_RGB888 ||
        colour_.getMirroringEnabled() != mirrored_) {
        colour_.destroy();  // only RGB888 in the depth's orientation is used; depth alone is still a scan
        info_.colour_registered = false;
        return;
    }
    has_colour_stream_ = true;
    info_.has_colour = true;
}

// The camera from its name (a known family's preset) and the range its depth stream reports. A recording does not
// store the device's name, so an .oni file keeps the Kinect v1 unless --sensor says otherwise.
void OpenNi2Source::describeSensor() {
    if (is_file_) return;
    const openni::DeviceInfo& dev = device_.getDeviceInfo();
    std::string name = std::string(dev.getVendor()) + " " + dev.getName();
    std::string lower = name;
    for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    const char* preset = nullptr;
    if (lower.find("kinect") != std::string::npos) {
        preset = "kinect-v1";
    } else if (lower.find("xtion") != std::string::npos || lower.find("ps1080") != std::string::npos ||
               lower.find("carmine") != std::string::npos || lower.find("primesense") != std::string::npos) {
        preset = "xtion";
    } else if (lower.find("astra") != std::string::npos || lower.find("orbbec") != std::string::npos) {
        preset = "astra";
    }
    if (preset != nullptr) {
        if (auto found = recon::findSensorPreset(preset); found.isOk()) info_.sensor = found->sensor;
    } else {
        info_.sensor.family = recon::SensorFamily::kUnknown;
        info_.sensor.noise = {};
    }
    info_.sensor.name = preset != nullptr ? preset : name;
    // The stream's own range, when it gives one that can be right (many drivers report 0 as their minimum).
    const float min_m = static_cast<float>(depth_.getMinPixelValue()) * info_.depth_units_m;
    const float max_m = static_cast<float>(depth_.getMaxPixelValue()) * info_.depth_units_m;
    if (min_m > 0.05f && max_m > min_m && max_m <= 20.0f) {
        info_.sensor.min_depth_m = min_m;
        info_.sensor.max_depth_m = max_m;
    }
    info_.sensor_known = preset != nullptr || min_m > 0.05f;
}

// fx = width / (2 tan(hfov / 2)) from the stream's field of view; the principal point at the image centre
// (pixel centres at integer coordinates, as recon::Intrinsics defines them).
void OpenNi2Source::computeIntrinsics(const openni::VideoMode& mode) {
    const float hfov = depth_.getHorizontalFieldOfView(), vfov = depth_.getVerticalFieldOfView();
    recon::Intrinsics k;
    k.width_px = mode.getResolutionX();
    k.height_px = mode.getResolutionY();
    if (std::isfinite(hfov) && std::isfinite(vfov) && hfov > 0.1f && hfov < 3.0f && vfov > 0.1f && vfov < 3.0f) {
        k.fx_px = static_cast<float>(k.width_px) / (2.0f * std::tan(hfov / 2.0f));
        k.fy_px = static_cast<float>(k.height_px) / (2.0f * std::tan(vfov / 2.0f));
    } else {
        // No usable field of view: the Kinect v1's, scaled to this resolution.
        const recon::Intrinsics kinect = recon::Intrinsics::kinectV1();
        k.fx_px = kinect.fx_px * static_cast<float>(k.width_px) / static_cast<float>(kinect.width_px);
        k.fy_px = kinect.fy_px * static_cast<float>(k.height_px) / static_cast<float>(kinect.height_px);
    }
    k.cx_px = (static_cast<float>(k.width_px) - 1.0f) / 2.0f;
    k.cy_px = (static_cast<float>(k.height_px) - 1.0f) / 2.0f;
    info_.intrinsics = k;
}

Status OpenNi2Source::waitDepth(openni::VideoFrameRef& frame) {
    const int slice_ms = std::max(10, static_cast<int>(std::lround(2000.0f / info_.rate_hz)));  // two frame periods
    const auto limit = is_file_ ? kFileSilenceLimit : (delivered_ == 0 ? kLiveFirstFrameLimit : kLiveSilenceLimit);
    const auto start = Clock::now();
    for (;;) {
        if (watch_ && watch_->gone()) {
            return unavailable("openni2: device '" + name_ + "' was disconnected (unplugged?) after " +
                               std::to_string(delivered_) + " frames");
        }
        openni::VideoStream* streams[] = {&depth_};
        int ready = -1;
        const openni::Status rc = openni::OpenNI::waitForAnyStream(streams, 1, &ready, slice_ms);
        if (rc == openni::STATUS_OK) {
            if (depth_.readFrame(&frame) != openni::STATUS_OK || !frame.isValid()) {
                return dataLoss("openni2: reading a depth frame from '" + name_ + "' failed: " + oniError());
            }
            return Status::ok();
        }
        if (rc != openni::STATUS_TIME_OUT) {
            return unavailable("openni2: waiting for depth from '" + name_ + "' failed: " + oniError());
        }
        const auto waited_ms = std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - start).count();
        if (Clock::now() - start >= limit) {
            if (is_file_) {
                return dataLoss("oni: '" + name_ + "' ended after " + std::to_string(delivered_) + " of " +
                                std::to_string(info_.expected_frames) +
                                " depth frames (truncated or corrupt recording)");
            }
            return unavailable("openni2: device '" + name_ + "' delivered no depth frame for " +
                               std::to_string(waited_ms) + " ms after " + std::to_string(delivered_) +
                               " frames (unplugged or stalled?)");
        }
    }
}

// The colour frame that goes with `depth`: same frame index in a recording (the recorder numbers both streams
// from 1), nearest timestamp live. Reads colour until it reaches the depth frame, but never past a pending
// depth frame: in manual playback every wait on an empty stream advances the player, and a second depth record
// would overwrite the one not yet read.
void OpenNi2Source::pairColour(const openni::VideoFrameRef& depth) {
    const auto half_period_us = static_cast<uint64_t>(5e5 / info_.rate_hz);
    auto caughtUp = [&] {
        if (!latest_colour_.isValid()) return false;
        if (is_file_) return latest_colour_.getFrameIndex() >= depth.getFrameIndex();
        return latest_colour_.getTimestamp() + half_period_us >= depth.getTimestamp();
    };
    const int wait_ms = std::max(10, static_cast<int>(std::lround(1000.0f / info_.rate_hz)));  // one frame period
    for (int reads = 0; !caughtUp() && reads < kMaxColourReads; ++reads) {
        openni::VideoStream* streams[] = {&colour_, &depth_};
        int ready = -1;
        if (openni::OpenNI::waitForAnyStream(streams, 2, &ready, wait_ms) != openni::STATUS_OK || ready != 0) break;
        openni::VideoFrameRef colour;
        if (colour_.readFrame(&colour) != openni::STATUS_OK || !colour.isValid()) break;
        latest_colour_ = colour;
    }
}

StatusOr<bool> OpenNi2Source::next(CapturedFrame& out) {
    if (!failed_.isOk()) return failed_;
    if (ended_) return false;
    const bool limit_reached = options_.max_frames > 0 && delivered_ >= static_cast<uint32_t>(options_.max_frames);
    if (limit_reached || (is_file_ && delivered_ >= static_cast<uint32_t>(info_.expected_frames))) {
        close();  // the player thread spins at end of file until its device is closed
        ended_ = true;
        return false;
    }
    openni::VideoFrameRef depth;
    if (Status s = waitDepth(depth); !s.isOk()) {
        failed_ = s;
        close();
        return s;
    }
    const openni::VideoMode mode = depth.getVideoMode();
    if (depth.getWidth() != info_.intrinsics.width_px || depth.getHeight() != info_.intrinsics.height_px ||
        mode.getPixelFormat() != depth_.getVideoMode().getPixelFormat() ||
        depth.getStrideInBytes() < depth.getWidth() * 2 ||
        depth.getDataSize() < depth.getStrideInBytes() * (depth.getHeight() - 1) + depth.getWidth() * 2) {
        failed_ =
            dataLoss("openni2: depth frame " + std::to_string(delivered_) + " of '" + name_ + "' is " +
                     std::to_string(depth.getWidth()) + "x" + std::to_string(depth.getHeight()) + " (" +
                     std::to_string(depth.getDataSize()) + " bytes), expected " +
                     std::to_string(info_.intrinsics.width_px) + "x" + std::to_string(info_.intrinsics.height_px));
        close();
        return failed_;
    }
    const cv::Mat raw(depth.getHeight(), depth.getWidth(), CV_16UC1, const_cast<void*>(depth.getData()),
                      static_cast<size_t>(depth.getStrideInBytes()));
    if (mirrored_) {
        cv::flip(raw, out.depth_raw, 1);
    } else {
        raw.copyTo(out.depth_raw);
    }

    out.colour_bgr.release();
    if (has_colour_stream_) {
        pairColour(depth);
        const openni::VideoFrameRef& c = latest_colour_;
        if (c.isValid() && c.getStrideInBytes() >= c.getWidth() * 3 &&
            c.getDataSize() >= c.getStrideInBytes() * (c.getHeight() - 1) + c.getWidth() * 3) {
            const cv::Mat rgb(c.getHeight(), c.getWidth(), CV_8UC3, const_cast<void*>(c.getData()),
                              static_cast<size_t>(c.getStrideInBytes()));
            cv::cvtColor(rgb, colour_rgb_, cv::COLOR_RGB2BGR);
            if (mirrored_) cv::flip(colour_rgb_, colour_rgb_, 1);
            if (colour_rgb_.size() != out.depth_raw.size()) {
                cv::resize(colour_rgb_, out.colour_bgr, out.depth_raw.size(), 0, 0, cv::INTER_AREA);
            } else {
                colour_rgb_.copyTo(out.colour_bgr);
            }
        }
    }
    out.timestamp_ns = static_cast<int64_t>(depth.getTimestamp()) * 1000;  // OpenNI timestamps are microseconds
    out.index = delivered_++;
    return true;
}

void OpenNi2Source::close() {
    latest_colour_.release();
    // Both streams stop before either is destroyed. OpenNI 2.2's file player (libOniFile PlayerDevice::MainLoop)
    // walks its stream list without its lock, spinning at end of file while a stream is started, and
    // destroyStream unlinks and frees a stream without the lock either: destroying under the spin crashed about
    // one playback in eight on a loaded machine. With every stream stopped the loop only looks at the list once
    // per 10 ms sleep, so after a pause of a few of those the destroy cannot meet it mid-walk (upstream bug; its
    // close() joins the thread, but only after the streams are gone).
    if (depth_.isValid()) depth_.stop();
    if (colour_.isValid()) colour_.stop();
    if (is_file_ && (depth_.isValid() || colour_.isValid())) std::this_thread::sleep_for(kPlayerSettle);
    if (depth_.isValid()) depth_.destroy();
    if (colour_.isValid()) colour_.destroy();
    has_colour_stream_ = false;
    playback_ = nullptr;
    if (device_.isValid()) device_.close();
    if (watch_) {
        openni::OpenNI::removeDeviceDisconnectedListener(watch_.get());
        watch_.reset();
    }
}

}  // namespace

StatusOr<std::unique_ptr<FrameSource>> openOpenNi2Device(const std::string& uri, const SourceOptions& options) {
    ASSIGN_OR_RETURN(auto runtime, OpenNiRuntime::acquire());
    auto source = std::make_unique<OpenNi2Source>(std::move(runtime), options, /*is_file=*/false);
    RETURN_IF_ERROR(source->open(uri));
    return std::unique_ptr<FrameSource>(std::move(source));
}

StatusOr<std::unique_ptr<FrameSource>> openOniFile(const std::string& path, const SourceOptions& options) {
    std::error_code ec;
    if (path.empty()) return invalidArgument("oni: no file given (oni:FILE)");
    if (!std::filesystem::is_regular_file(path, ec)) return notFound("oni: no such recording '" + path + "'");
    ASSIGN_OR_RETURN(auto runtime, OpenNiRuntime::acquire());
    auto source = std::make_unique<OpenNi2Source>(std::move(runtime), options, /*is_file=*/true);
    RETURN_IF_ERROR(source->open(std::filesystem::absolute(path, ec).string()));
    return std::unique_ptr<FrameSource>(std::move(source));
}

}  // namespace facescan::capture
