// An OpenNI2 device of our own that serves the synthetic Kinect (facescan_synth) as if it were a camera, so the
// OpenNI2 path of the capture agent (live device, recorder, .oni playback) runs for real without hardware.
// Loaded by libOpenNI2 from its system driver folder (deploy/openni2-test-driver.sh installs it there).
//
// One device, URI "facescan://synthetic": depth 640x480@30 in millimetres and colour RGB888 640x480@30,
// registered to depth (the renderer draws colour in the depth camera), rendered on the device's own thread.
// Environment variables, read when the device is opened:
//   FACESCAN_SYNTH_FRAMES=K   deliver K frames, then "unplug" (stop and raise OpenNI's device-disconnected event)
//   FACESCAN_SYNTH_SEED=N     noise seed of the sequence (default 1)
//   FACESCAN_SYNTH_NOISE=0|1  Kinect v1 noise model off/on (default on)
//   FACESCAN_SYNTH_SUBJECT=builtin|scan   the built-in head, or the real scan when found (default: scan)
#pragma once

// The driver API's export macro uses XnLib's allocation macros, which Debian's -dev package does not ship.
#ifndef XN_NEW
#define XN_NEW(type, ...) new type(__VA_ARGS__)
#endif
#ifndef XN_DELETE
#define XN_DELETE(p) delete (p)
#endif

#include <Driver/OniDriverAPI.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <thread>
#include <vector>

#include "synth/kinect_simulator.hpp"

namespace facescan::oni_synth {

inline constexpr const char* kSynthUri = "facescan://synthetic";
inline constexpr const char* kSynthVendor = "facescan";
inline constexpr const char* kSynthName = "Synthetic Kinect";

struct SynthConfig {
    int frames_before_unplug = 0;  // frames delivered before the device disappears; 0 = never
    uint64_t seed = 1;             // noise seed of the rendered sequence
    bool noise = true;             // Kinect v1 noise model on
    bool builtin_subject = false;  // true: the procedural head; false: the real scan when it can be found
    float fps = 30.0f;             // frames per second

    // Reads FACESCAN_SYNTH_* (see the file comment); malformed values are reported through `error`.
    static SynthConfig fromEnvironment(std::string* error);
};

class SynthDevice;

class SynthStream final : public oni::driver::StreamBase {
 public:
    SynthStream(SynthDevice& device, OniSensorType type, OniVideoMode mode);
    ~SynthStream() override;

    OniStatus start() override;
    void stop() override;
    OniStatus setProperty(int property_id, const void* data, int data_size) override;
    OniStatus getProperty(int property_id, void* data, int* data_size) override;
    OniBool isPropertySupported(int property_id) override;

    OniSensorType type() const { return type_; }
    bool started() const { return started_.load(); }
    // Producer thread: copies `pixels` (CV_16UC1 mm or CV_8UC3 RGB, the mode's size) into an OpenNI frame.
    void deliver(const cv::Mat& pixels, int frame_index, uint64_t timestamp_us);

 private:
    SynthDevice& device_;
    OniSensorType type_;
    OniVideoMode mode_;
    std::atomic<bool> started_{false};
};

class SynthDevice final : public oni::driver::DeviceBase {
 public:
    // `on_unplug` runs on the producer thread after the last frame when the device "unplugs".
    SynthDevice(SynthConfig config, std::function<void()> on_unplug);
    ~SynthDevice() override;

    OniStatus getSensorInfoList(OniSensorInfo** sensors, int* num_sensors) override;
    oni::driver::StreamBase* createStream(OniSensorType type) override;
    void destroyStream(oni::driver::StreamBase* stream) override;
    OniStatus setProperty(int property_id, const void* data, int data_size) override;
    OniStatus getProperty(int property_id, void* data, int* data_size) override;
    OniBool isPropertySupported(int property_id) override;
    OniBool isImageRegistrationModeSupported(OniImageRegistrationMode mode) override;

    // Horizontal and vertical field of view of the (shared) depth/colour camera, radians.
    float horizontalFovRad() const;
    float verticalFovRad() const;
    // A stream started: the producer thread runs while any stream is started.
    void onStreamStarted();

 private:
    void produce();

    SynthConfig config_;
    std::function<void()> on_unplug_;
    synth::KinectSimulator simulator_;
    std::vector<OniVideoMode> depth_modes_, colour_modes_;
    OniSensorInfo sensors_[2] = {};

    std::mutex mutex_;  // guards streams_ and the thread state below
    std::condition_variable wake_;
    std::vector<std::unique_ptr<SynthStream>> streams_;
    std::thread producer_;
    bool running_ = false;
    bool unplugged_ = false;
};

}  // namespace facescan::oni_synth
