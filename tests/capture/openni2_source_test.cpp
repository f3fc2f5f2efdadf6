// The OpenNI2 sources for real: facescan's synthetic OpenNI2 device (libFacescanSynth.so, installed in OpenNI2's
// system driver folder by deploy/openni2-test-driver.sh) opened as a live camera, recorded to .oni with OpenNI's
// own recorder, and played back with openOniFile. Tests that need the device skip when it is not installed.
//
// OpenNI's C++ header comes through <openni2/...> because capture_core links OpenNI2 privately (its include
// folder does not reach the tests); its library is linked through capture_core.
#include <gtest/gtest.h>
#include <openni2/OpenNI.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <random>
#include <thread>

#include "capture/frame_source.hpp"

namespace facescan::capture {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr const char* kUri = "facescan://synthetic";

double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Sets the synthetic device's knobs for this test (read when the device opens). The built-in head keeps device
// start-up fast and independent of ../shared/data.
void configureDevice(int frames_before_unplug) {
    setenv("FACESCAN_SYNTH_FRAMES", std::to_string(frames_before_unplug).c_str(), 1);
    setenv("FACESCAN_SYNTH_SUBJECT", "builtin", 1);
    setenv("FACESCAN_SYNTH_SEED", "7", 1);
    setenv("FACESCAN_SYNTH_NOISE", "1", 1);
}

bool synthDeviceInstalled() {
    if (openni::OpenNI::initialize() != openni::STATUS_OK) return false;
    openni::Array<openni::DeviceInfo> devices;
    openni::OpenNI::enumerateDevices(&devices);
    bool found = false;
    for (int i = 0; i < devices.getSize(); ++i) found = found || std::string(devices[i].getUri()) == kUri;
    openni::OpenNI::shutdown();
    return found;
}

#define REQUIRE_SYNTH_DEVICE()                                                                                \
    if (!synthDeviceInstalled()) {                                                                            \
        GTEST_SKIP() << "facescan's synthetic OpenNI2 device is not installed; run (as root) "                \
                     << "deploy/openni2-test-driver.sh install BUILD_DIR (deploy/test.sh does it for ctest)"; \
    }

class TempDir {
 public:
    TempDir() {
        std::random_device rd;
        path_ = fs::temp_directory_path() / ("facescan-oni-" + std::to_string(rd()) + std::to_string(::getpid()));
        fs::create_directories(path_);
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path_, ec);
    }
    const fs::path& path() const { return path_; }

 private:
    fs::path path_;
};

// Median of the valid (non-zero) depth in the central third of the image, in raw units.
double centralMedian(const cv::Mat& depth_raw) {
    const cv::Mat centre =
        depth_raw(cv::Rect(depth_raw.cols / 3, depth_raw.rows / 3, depth_raw.cols / 3, depth_raw.rows / 3));
    std::vector<uint16_t> v;
    for (int r = 0; r < centre.rows; ++r) {
        for (int c = 0; c < centre.cols; ++c) {
            if (centre.at<uint16_t>(r, c) != 0) v.push_back(centre.at<uint16_t>(r, c));
        }
    }
    if (v.empty()) return 0;
    std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
    return v[v.size() / 2];
}

TEST(OpenNi2Source, LiveSyntheticDeviceDeliversKinectFrames) {
    REQUIRE_SYNTH_DEVICE();
    configureDevice(0);
    auto source = openOpenNi2Device(kUri, SourceOptions{});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const SourceInfo& info = (*source)->info();
    EXPECT_EQ(info.intrinsics.width_px, 640);
    EXPECT_EQ(info.intrinsics.height_px, 480);
    // fx from the reported field of view: the renderer's Kinect v1 focal length, to float rounding.
    EXPECT_NEAR(info.intrinsics.fx_px, 575.8f, 0.05f);
    EXPECT_NEAR(info.intrinsics.fy_px, 575.8f, 0.05f);
    EXPECT_FLOAT_EQ(info.depth_units_m, 0.001f);
    EXPECT_TRUE(info.has_colour);
    EXPECT_TRUE(info.colour_registered);
    EXPECT_FALSE(info.is_recording);
    EXPECT_EQ(info.rate_hz, 30.0f);
    EXPECT_NE(info.description.find("Synthetic Kinect"), std::string::npos) << info.description;
    EXPECT_NE(info.description.find("synced"), std::string::npos) << info.description;
    // The device names its camera: a Kinect, so the Kinect v1's range and noise (its stream reports no minimum).
    EXPECT_TRUE(info.sensor_known);
    EXPECT_EQ(info.sensor, recon::SensorModel::kinectV1());

    constexpr int kFrames = 30;
    CapturedFrame frame;
    const auto t0 = Clock::now();
    int64_t previous_ns = -1;
    for (int i = 0; i < kFrames; ++i) {
        auto got = (*source)->next(frame);
        ASSERT_TRUE(got.isOk()) << got.status().toString();
        ASSERT_TRUE(*got);
        EXPECT_EQ(frame.index, static_cast<uint32_t>(i));
        ASSERT_EQ(frame.depth_raw.type(), CV_16UC1);
        ASSERT_EQ(frame.depth_raw.size(), cv::Size(640, 480));
        ASSERT_EQ(frame.colour_bgr.type(), CV_8UC3);
        ASSERT_EQ(frame.colour_bgr.size(), cv::Size(640, 480));
        // The head's face is 0.6-0.7 m from the camera (head frame origin at 0.7 m, nose 0.1 m in front).
        const double median_mm = centralMedian(frame.depth_raw);
        EXPECT_GT(median_mm, 550.0) << "frame " << i;
        EXPECT_LT(median_mm, 800.0) << "frame " << i;
        // Device clock: the synthetic device stamps frame i at i/30 s, whatever the wall-clock rate.
        if (previous_ns >= 0) {
            EXPECT_NEAR(frame.timestamp_ns - previous_ns, 33'333'333, 1000) << "frame " << i;
        }
        previous_ns = frame.timestamp_ns;
    }
    const double fps = (kFrames - 1) / secondsSince(t0);
    std::printf("synthetic OpenNI2 device: %d frames at %.1f frames/s\n", kFrames, fps);
    // Paced at 30 Hz, never faster; slower only when rendering cannot keep up (the renderer takes ~25-110 ms a
    // frame on 2 shared cores, depending on load), so the lower bound is a sanity check, not a rate requirement.
    EXPECT_LT(fps, 33.0);
    EXPECT_GT(fps, 2.0);
    // Colour is real imagery (not blank) and differs from frame to frame only as the head moves.
    cv::Scalar mean, stddev;
    cv::meanStdDev(frame.colour_bgr, mean, stddev);
    EXPECT_GT(stddev[0] + stddev[1] + stddev[2], 10.0);
}

TEST(OpenNi2Source, FirstDeviceOpensWhenNoUriIsGiven) {
    REQUIRE_SYNTH_DEVICE();
    configureDevice(0);
    auto source = openOpenNi2Device("", SourceOptions{.colour = false});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_FALSE((*source)->info().has_colour);
    CapturedFrame frame;
    auto got = (*source)->next(frame);
    ASSERT_TRUE(got.isOk()) << got.status().toString();
    EXPECT_TRUE(*got);
    EXPECT_TRUE(frame.colour_bgr.empty());
}

TEST(OpenNi2Source, UnpluggedDeviceEndsWithAClearErrorNotAHang) {
    REQUIRE_SYNTH_DEVICE();
    constexpr int kFrames = 12;
    configureDevice(kFrames);
    auto source = openOpenNi2Device(kUri, SourceOptions{});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    CapturedFrame frame;
    int frames = 0;
    Clock::time_point last_frame = Clock::now();
    Status error;
    for (int i = 0; i < kFrames + 5; ++i) {
        auto got = (*source)->next(frame);
        if (!got.isOk()) {
            error = got.status();
            break;
        }
        ASSERT_TRUE(*got) << "a live device never ends cleanly by itself";
        ++frames;
        last_frame = Clock::now();
    }
    const double error_after_s = secondsSince(last_frame);
    EXPECT_EQ(frames, kFrames);
    ASSERT_FALSE(error.isOk());
    EXPECT_EQ(error.code(), StatusCode::kUnavailable);
    EXPECT_NE(error.message().find("disconnected"), std::string::npos) << error.message();
    EXPECT_NE(error.message().find(kUri), std::string::npos) << error.message();
    EXPECT_LT(error_after_s, 2.0) << "the unplug must be reported within a second or two";
    // The error is final: asking again says the same at once.
    const auto t0 = Clock::now();
    auto again = (*source)->next(frame);
    EXPECT_FALSE(again.isOk());
    EXPECT_LT(secondsSince(t0), 0.1);
}

TEST(OpenNi2Source, MissingDeviceNamesTheDevicesThereAre) {
    REQUIRE_SYNTH_DEVICE();
    auto source = openOpenNi2Device("facescan://no-such-camera", SourceOptions{});
    ASSERT_FALSE(source.isOk());
    EXPECT_EQ(source.status().code(), StatusCode::kNotFound);
    EXPECT_NE(source.status().message().find("facescan://no-such-camera"), std::string::npos);
    EXPECT_NE(source.status().message().find(kUri), std::string::npos) << source.status().message();
}

TEST(OpenNi2Source, MissingOrCorruptRecordingGivesClearErrors) {
    auto missing = openOniFile("/nonexistent/scan.oni", SourceOptions{});
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
    EXPECT_NE(missing.status().message().find("/nonexistent/scan.oni"), std::string::npos);

    TempDir dir;
    const fs::path corrupt = dir.path() / "corrupt.oni";
    {
        std::ofstream f(corrupt, std::ios::binary);
        std::mt19937 rng(3);
        for (int i = 0; i < 100000; ++i) f.put(static_cast<char>(rng()));
    }
    const auto t0 = Clock::now();
    auto bad = openOniFile(corrupt.string(), SourceOptions{});
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.status().message().find("corrupt.oni"), std::string::npos) << bad.status().message();
    EXPECT_LT(secondsSince(t0), 5.0);
}

}  // namespace
}  // namespace facescan::capture
