// The camera travels with a TUM recording: the recorder writes sensor.txt when the camera is known, the tum:
// source reads it back, and a sensor.txt that cannot be right is refused with a line that says the format.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "capture/frame_source.hpp"
#include "capture/tum_recorder.hpp"

namespace facescan::capture {
namespace {

namespace fs = std::filesystem;

class TumSensor : public ::testing::Test {
 protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("facescan-tum-sensor-" + std::to_string(getpid()));
        fs::remove_all(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    // A one-frame folder recorded from a source described by `info`.
    void record(const SourceInfo& info) {
        auto recorder = TumRecorder::create(dir_, info);
        ASSERT_TRUE(recorder.isOk()) << recorder.status().toString();
        CapturedFrame frame;
        frame.depth_raw = cv::Mat(info.intrinsics.height_px, info.intrinsics.width_px, CV_16UC1, cv::Scalar(300));
        frame.timestamp_ns = 1'000'000'000;
        ASSERT_TRUE(recorder->add(frame).isOk());
    }
    void writeSensorFile(const std::string& text) { std::ofstream(dir_ / "sensor.txt") << text; }

    fs::path dir_;
};

SourceInfo nearRange() {
    SourceInfo info;
    info.intrinsics = recon::findSensorPreset("truedepth")->nominal_depth;
    info.depth_units_m = 0.001f;
    info.has_colour = false;
    info.sensor = recon::findSensorPreset("truedepth")->sensor;
    info.sensor.max_depth_m = 0.6f;  // an override travels too
    info.sensor_known = true;
    return info;
}

TEST_F(TumSensor, TheRecordedCameraComesBack) {
    record(nearRange());
    const auto source = openTumSource(dir_.string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const SourceInfo& info = (*source)->info();
    EXPECT_TRUE(info.sensor_known);
    EXPECT_EQ(info.sensor.name, "truedepth");
    EXPECT_EQ(info.sensor.family, recon::SensorFamily::kStructuredLight);
    EXPECT_FLOAT_EQ(info.sensor.min_depth_m, 0.2f);
    EXPECT_FLOAT_EQ(info.sensor.max_depth_m, 0.6f);
}

TEST_F(TumSensor, AFolderWithoutOneCannotTell) {
    SourceInfo info = nearRange();
    info.sensor_known = false;
    record(info);
    EXPECT_FALSE(fs::exists(dir_ / "sensor.txt"));
    const auto source = openTumSource(dir_.string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_FALSE((*source)->info().sensor_known);
    EXPECT_EQ((*source)->info().sensor, recon::SensorModel::kinectV1());
}

TEST_F(TumSensor, AnyNamedCameraWithItsRange) {
    record(nearRange());
    writeSensorFile("# my camera\nlab-rig 0.15 0.45\n");
    const auto source = openTumSource(dir_.string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_EQ((*source)->info().sensor.name, "lab-rig");
    EXPECT_EQ((*source)->info().sensor.family, recon::SensorFamily::kUnknown);
    EXPECT_FLOAT_EQ((*source)->info().sensor.min_depth_m, 0.15f);
}

TEST_F(TumSensor, ASensorFileThatCannotBeRightSaysTheFormat) {
    record(nearRange());
    for (const char* text : {"", "lab-rig\n", "truedepth 0.5 0.2\n", "truedepth 0 0.5\n"}) {
        writeSensorFile(text);
        const auto source = openTumSource(dir_.string(), {});
        ASSERT_FALSE(source.isOk()) << "'" << text << "' accepted";
        EXPECT_EQ(source.status().code(), StatusCode::kDataLoss);
        EXPECT_NE(source.status().message().find("sensor.txt"), std::string::npos) << source.status().message();
        EXPECT_EQ(source.status().message().find('\n'), std::string::npos) << source.status().message();
    }
}

}  // namespace
}  // namespace facescan::capture
