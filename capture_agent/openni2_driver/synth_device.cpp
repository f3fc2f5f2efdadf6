// The synthetic OpenNI2 device: streams, properties and the producer thread (see synth_device.hpp).
#include "synth_device.hpp"

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <opencv2/imgproc.hpp>

#include "recon/frame.hpp"
#include "synth/head_model.hpp"

namespace facescan::oni_synth {
namespace {

// Depth range reported to OpenNI (ONI_STREAM_PROPERTY_MAX_VALUE); the recorder's depth codec sizes its tables
// from it. 10 m as PrimeSense devices report; the renderer never produces more than its 4 m range.
constexpr int kMaxDepthMm = 10000;
constexpr float kDepthUnitsM = 0.001f;  // PIXEL_FORMAT_DEPTH_1_MM

bool parseInt(const char* text, long long lo, long long hi, long long* out) {
    if (text == nullptr || *text == '\0') return false;
    char* end = nullptr;
    const long long v = std::strtoll(text, &end, 10);
    if (*end != '\0' || v < lo || v > hi) return false;
    *out = v;
    return true;
}

// Typed property access with OpenNI's size check: the caller's buffer must be exactly sizeof(T).
template <typename T>
OniStatus writeProperty(const T& value, void* data, int* data_size) {
    if (data == nullptr || data_size == nullptr || *data_size != static_cast<int>(sizeof(T))) {
        return ONI_STATUS_BAD_PARAMETER;
    }
    std::memcpy(data, &value, sizeof(T));
    return ONI_STATUS_OK;
}
template <typename T>
bool readProperty(const void* data, int data_size, T* value) {
    if (data == nullptr || data_size != static_cast<int>(sizeof(T))) return false;
    std::memcpy(value, data, sizeof(T));
    return true;
}

synth::KinectSimulator makeSimulator(const SynthConfig& config) {
    synth::SequenceParams params;
    params.fps = config.fps;
    params.seed = config.seed;
    params.noise = config.noise;
    return synth::KinectSimulator(config.builtin_subject ? synth::builtinHead() : synth::defaultHead(), params);
}

}  // namespace

SynthConfig SynthConfig::fromEnvironment(std::string* error) {
    SynthConfig config;
    long long v = 0;
    auto bad = [&](const char* name, const char* what) {
        if (error != nullptr) *error += std::string(name) + " must be " + what + "; ";
    };
    if (const char* s = std::getenv("FACESCAN_SYNTH_FRAMES"); s != nullptr && *s != '\0') {
        if (parseInt(s, 0, 1'000'000'000, &v)) {
            config.frames_before_unplug = static_cast<int>(v);
        } else {
            bad("FACESCAN_SYNTH_FRAMES", "an integer >= 0");
        }
    }
    if (const char* s = std::getenv("FACESCAN_SYNTH_SEED"); s != nullptr && *s != '\0') {
        if (parseInt(s, 0, (1LL << 62), &v)) {
            config.seed = static_cast<uint64_t>(v);
        } else {
            bad("FACESCAN_SYNTH_SEED", "an integer >= 0");
        }
    }
    if (const char* s = std::getenv("FACESCAN_SYNTH_NOISE"); s != nullptr && *s != '\0') {
        if (parseInt(s, 0, 1, &v)) {
            config.noise = v == 1;
        } else {
            bad("FACESCAN_SYNTH_NOISE", "0 or 1");
        }
    }
    if (const char* s = std::getenv("FACESCAN_SYNTH_SUBJECT"); s != nullptr && *s != '\0') {
        if (std::strcmp(s, "builtin") == 0 || std::strcmp(s, "scan") == 0) {
            config.builtin_subject = std::strcmp(s, "builtin") == 0;
        } else {
            bad("FACESCAN_SYNTH_SUBJECT", "'builtin' or 'scan'");
        }
    }
    return config;
}

// ---------------------------------------------------------------------------------------------------------------
SynthStream::SynthStream(SynthDevice& device, OniSensorType type, OniVideoMode mode)
    : device_(device), type_(type), mode_(mode) {}

SynthStream::~SynthStream() { started_ = false; }

OniStatus SynthStream::start() {
    started_ = true;
    device_.onStreamStarted();
    return ONI_STATUS_OK;
}

void SynthStream::stop() { started_ = false; }

OniStatus SynthStream::setProperty(int property_id, const void* data, int data_size) {
    switch (property_id) {
        case ONI_STREAM_PROPERTY_VIDEO_MODE: {
            OniVideoMode mode{};
            if (!readProperty(data, data_size, &mode)) return ONI_STATUS_BAD_PARAMETER;
            // One mode per sensor, as the renderer draws 640x480 at the sequence rate.
            const bool same = mode.pixelFormat == mode_.pixelFormat && mode.resolutionX == mode_.resolutionX &&
                              mode.resolutionY == mode_.resolutionY && mode.fps == mode_.fps;
            return same ? ONI_STATUS_OK : ONI_STATUS_NOT_SUPPORTED;
        }
        case ONI_STREAM_PROPERTY_MIRRORING: {
            OniBool mirror = FALSE;
            if (!readProperty(data, data_size, &mirror)) return ONI_STATUS_BAD_PARAMETER;
            return mirror ? ONI_STATUS_NOT_SUPPORTED : ONI_STATUS_OK;
        }
        case ONI_STREAM_PROPERTY_CROPPING: {
            OniCropping cropping{};
            if (!readProperty(data, data_size, &cropping)) return ONI_STATUS_BAD_PARAMETER;
            return cropping.enabled ? ONI_STATUS_NOT_SUPPORTED : ONI_STATUS_OK;
        }
        default: return ONI_STATUS_NOT_SUPPORTED;
    }
}

OniStatus SynthStream::getProperty(int property_id, void* data, int* data_size) {
    switch (property_id) {
        case ONI_STREAM_PROPERTY_VIDEO_MODE: return writeProperty(mode_, data, data_size);
        case ONI_STREAM_PROPERTY_HORIZONTAL_FOV: return writeProperty(device_.horizontalFovRad(), data, data_size);
        case ONI_STREAM_PROPERTY_VERTICAL_FOV: return writeProperty(device_.verticalFovRad(), data, data_size);
        case ONI_STREAM_PROPERTY_MIRRORING: return writeProperty(OniBool(FALSE), data, data_size);
        case ONI_STREAM_PROPERTY_CROPPING: {
            OniCropping cropping{};
            cropping.enabled = FALSE;
            cropping.width = mode_.resolutionX;
            cropping.height = mode_.resolutionY;
            return writeProperty(cropping, data, data_size);
        }
        case ONI_STREAM_PROPERTY_STRIDE:
            return writeProperty(mode_.resolutionX * (type_ == ONI_SENSOR_DEPTH ? 2 : 3), data, data_size);
        case ONI_STREAM_PROPERTY_MAX_VALUE:
            if (type_ != ONI_SENSOR_DEPTH) return ONI_STATUS_NOT_SUPPORTED;
            return writeProperty(kMaxDepthMm, data, data_size);
        case ONI_STREAM_PROPERTY_MIN_VALUE:
            if (type_ != ONI_SENSOR_DEPTH) return ONI_STATUS_NOT_SUPPORTED;
            return writeProperty(0, data, data_size);
        default: return ONI_STATUS_NOT_SUPPORTED;
    }
}

OniBool SynthStream::isPropertySupported(int property_id) {
    switch (property_id) {
        case ONI_STREAM_PROPERTY_VIDEO_MODE:
        case ONI_STREAM_PROPERTY_HORIZONTAL_FOV:
        case ONI_STREAM_PROPERTY_VERTICAL_FOV:
        case ONI_STREAM_PROPERTY_MIRRORING:
        case ONI_STREAM_PROPERTY_CROPPING:
        case ONI_STREAM_PROPERTY_STRIDE: return TRUE;
        case ONI_STREAM_PROPERTY_MAX_VALUE:
        case ONI_STREAM_PROPERTY_MIN_VALUE: return type_ == ONI_SENSOR_DEPTH ? TRUE : FALSE;
        default: return FALSE;
    }
}

void SynthStream::deliver(const cv::Mat& pixels, int frame_index, uint64_t timestamp_us) {
    OniFrame* frame = getServices().acquireFrame();
    if (frame == nullptr) return;  // OpenNI is out of frame buffers: drop this one, as a camera would
    const int row_bytes = static_cast<int>(pixels.cols * pixels.elemSize());
    const size_t bytes = static_cast<size_t>(row_bytes) * static_cast<size_t>(pixels.rows);
    if (frame->data == nullptr || static_cast<size_t>(frame->dataSize) < bytes) {
        getServices().releaseFrame(frame);
        return;
    }
    for (int v = 0; v < pixels.rows; ++v) {
        std::memcpy(static_cast<uint8_t*>(frame->data) + static_cast<size_t>(v) * row_bytes, pixels.ptr(v),
                    static_cast<size_t>(row_bytes));
    }
    frame->dataSize = static_cast<int>(bytes);
    frame->sensorType = type_;
    frame->timestamp = timestamp_us;
    frame->frameIndex = frame_index;
    frame->width = pixels.cols;
    frame->height = pixels.rows;
    frame->videoMode = mode_;
    frame->croppingEnabled = FALSE;
    frame->cropOriginX = 0;
    frame->cropOriginY = 0;
    frame->stride = row_bytes;
    raiseNewFrame(frame);
    getServices().releaseFrame(frame);
}

// ---------------------------------------------------------------------------------------------------------------
SynthDevice::SynthDevice(SynthConfig config, std::function<void()> on_unplug)
    : config_(config), on_unplug_(std::move(on_unplug)), simulator_(makeSimulator(config)) {
    const recon::Intrinsics& k = simulator_.intrinsics();
    const int fps = static_cast<int>(std::lround(config_.fps));
    depth_modes_ = {OniVideoMode{ONI_PIXEL_FORMAT_DEPTH_1_MM, k.width_px, k.height_px, fps}};
    colour_modes_ = {OniVideoMode{ONI_PIXEL_FORMAT_RGB888, k.width_px, k.height_px, fps}};
    sensors_[0] = OniSensorInfo{ONI_SENSOR_DEPTH, 1, depth_modes_.data()};
    sensors_[1] = OniSensorInfo{ONI_SENSOR_COLOR, 1, colour_modes_.data()};
}

SynthDevice::~SynthDevice() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        running_ = false;
    }
    wake_.notify_all();
    if (producer_.joinable()) producer_.join();
}

OniStatus SynthDevice::getSensorInfoList(OniSensorInfo** sensors, int* num_sensors) {
    *sensors = sensors_;
    *num_sensors = 2;
    return ONI_STATUS_OK;
}

oni::driver::StreamBase* SynthDevice::createStream(OniSensorType type) {
    if (type != ONI_SENSOR_DEPTH && type != ONI_SENSOR_COLOR) return nullptr;
    const OniVideoMode mode = type == ONI_SENSOR_DEPTH ? depth_modes_[0] : colour_modes_[0];
    std::lock_guard<std::mutex> lock(mutex_);
    streams_.push_back(std::make_unique<SynthStream>(*this, type, mode));
    return streams_.back().get();
}

void SynthDevice::destroyStream(oni::driver::StreamBase* stream) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = streams_.begin(); it != streams_.end(); ++it) {
        if (it->get() == stream) {
            streams_.erase(it);
            return;
        }
    }
}

OniStatus SynthDevice::setProperty(int property_id, const void* data, int data_size) {
    if (property_id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION) {
        OniImageRegistrationMode mode{};
        if (!readProperty(data, data_size, &mode)) return ONI_STATUS_BAD_PARAMETER;
        return isImageRegistrationModeSupported(mode) ? ONI_STATUS_OK : ONI_STATUS_NOT_SUPPORTED;
    }
    return ONI_STATUS_NOT_SUPPORTED;
}

OniStatus SynthDevice::getProperty(int property_id, void* data, int* data_size) {
    switch (property_id) {
        case ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION:
            return writeProperty(ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR, data, data_size);
        case ONI_DEVICE_PROPERTY_DRIVER_VERSION: return writeProperty(OniVersion{1, 0, 0, 0}, data, data_size);
        case ONI_DEVICE_PROPERTY_SERIAL_NUMBER: {
            const std::string serial = "synthetic-" + std::to_string(config_.seed);
            if (data == nullptr || data_size == nullptr || *data_size <= static_cast<int>(serial.size())) {
                return ONI_STATUS_BAD_PARAMETER;
            }
            std::memcpy(data, serial.c_str(), serial.size() + 1);
            *data_size = static_cast<int>(serial.size() + 1);
            return ONI_STATUS_OK;
        }
        default: return ONI_STATUS_NOT_SUPPORTED;
    }
}

OniBool SynthDevice::isPropertySupported(int property_id) {
    return (property_id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION ||
            property_id == ONI_DEVICE_PROPERTY_DRIVER_VERSION || property_id == ONI_DEVICE_PROPERTY_SERIAL_NUMBER)
               ? TRUE
               : FALSE;
}

// The renderer draws colour in the depth camera, so colour is always registered to depth; turning registration
// off would be a lie about the pixels, hence the one mode.
OniBool SynthDevice::isImageRegistrationModeSupported(OniImageRegistrationMode mode) {
    return mode == ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR ? TRUE : FALSE;
}

float SynthDevice::horizontalFovRad() const {
    const recon::Intrinsics& k = simulator_.intrinsics();
    return 2.0f * std::atan(static_cast<float>(k.width_px) / (2.0f * k.fx_px));
}

float SynthDevice::verticalFovRad() const {
    const recon::Intrinsics& k = simulator_.intrinsics();
    return 2.0f * std::atan(static_cast<float>(k.height_px) / (2.0f * k.fy_px));
}

void SynthDevice::onStreamStarted() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (running_ || unplugged_) return;
    if (producer_.joinable()) producer_.join();  // a previous run that ended on its own
    running_ = true;
    producer_ = std::thread([this] { produce(); });
}

// Renders frame i, waits for its slot on the 1/fps grid, then hands it to every started stream. Depth and
// colour of one render share frameIndex (OpenNI's frame sync pairs frames by index) and the timestamp.
void SynthDevice::produce() {
    using Clock = std::chrono::steady_clock;
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / config_.fps));
    recon::RgbdFrame rendered;
    cv::Mat depth_mm, colour_rgb;
    auto slot = Clock::now();
    for (int i = 0;; ++i) {
        if (config_.frames_before_unplug > 0 && i >= config_.frames_before_unplug) break;
        // The motion is periodic over the sequence, so looping the index gives an endless smooth stream.
        simulator_.render(i % simulator_.frameCount(), rendered);
        recon::depthMetresToRaw(rendered.depth_m, kDepthUnitsM, depth_mm);
        cv::cvtColor(rendered.colour_bgr, colour_rgb, cv::COLOR_BGR2RGB);
        const auto timestamp_us = static_cast<uint64_t>(std::llround(1e6 * i / static_cast<double>(config_.fps)));
        slot += period;
        std::unique_lock<std::mutex> lock(mutex_);
        if (wake_.wait_until(lock, slot, [this] { return !running_; })) return;  // closed
        for (const auto& stream : streams_) {
            if (!stream->started()) continue;
            stream->deliver(stream->type() == ONI_SENSOR_DEPTH ? depth_mm : colour_rgb, i + 1, timestamp_us);
        }
    }
    {
        std::lock_guard<std::mutex> lock(mutex_);
        unplugged_ = true;
        running_ = false;
    }
    // Outside our lock: OpenNI's disconnect handling takes its own locks and calls the application.
    if (on_unplug_) on_unplug_();
}

}  // namespace facescan::oni_synth
