// mkv:FILE on a real Azure Kinect recording (the shared data's 3-frame fixture): sizes, the calibration's
// intrinsics and extrinsics, plausible depth and colour, device timestamps; and recordings that cannot be read
// (cut short, no depth track, no calibration) are refused with one line saying what is wrong.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <vector>

#include "capture/recording_sources.hpp"
#include "matroska_edit.hpp"
#include "test_data.hpp"

namespace facescan::capture {
namespace {

namespace fs = std::filesystem;
using namespace facescan::testing::matroska;

class MkvSource : public ::testing::Test {
 protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("facescan-mkv-" + std::to_string(getpid()));
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }
    fs::path dir_;
};

TEST_F(MkvSource, ReadsTheAzureKinectFixture) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    auto source = openMkvSource((data / "recording.mkv").string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const SourceInfo& info = (*source)->info();
    EXPECT_EQ(info.intrinsics.width_px, 640);
    EXPECT_EQ(info.intrinsics.height_px, 576);
    // The calibration's normalised parameters of the 1024x1024 sensor in the NFOV unbinned mode (binned 1024,
    // cropped by 192, 180, centre-origin pixels): cx = 0.51297 * 1024 - 192.5, fx = 0.49278 * 1024.
    EXPECT_NEAR(info.intrinsics.cx_px, 332.78f, 0.01f);
    EXPECT_NEAR(info.intrinsics.cy_px, 348.83f, 0.01f);
    EXPECT_NEAR(info.intrinsics.fx_px, 504.61f, 0.01f);
    EXPECT_NEAR(info.intrinsics.fy_px, 504.73f, 0.01f);
    EXPECT_FLOAT_EQ(info.depth_units_m, 0.001f);
    EXPECT_TRUE(info.sensor_known);
    EXPECT_EQ(info.sensor.name, "azure-kinect");
    EXPECT_TRUE(info.is_recording);
    EXPECT_FLOAT_EQ(info.rate_hz, 5.0f);
    // Colour: MJPEG 1280x720 (the 4:3 sensor binned to 1280x960, cropped by 120 rows), not registered.
    ASSERT_TRUE(info.has_colour);
    EXPECT_FALSE(info.colour_registered);
    EXPECT_EQ(info.colour_intrinsics.width_px, 1280);
    EXPECT_EQ(info.colour_intrinsics.height_px, 720);
    EXPECT_NEAR(info.colour_intrinsics.cx_px, 639.30f, 0.01f);
    EXPECT_NEAR(info.colour_intrinsics.cy_px, 365.85f, 0.01f);
    EXPECT_NEAR(info.colour_intrinsics.fx_px, 611.80f, 0.01f);
    EXPECT_NEAR(info.colour_intrinsics.fy_px, 611.93f, 0.01f);
    // The colour camera sits 32 mm beside the depth camera, tilted about 5 degrees.
    EXPECT_NEAR(info.T_colour_depth.translation().x(), -0.03208f, 1e-4f);
    EXPECT_NEAR(info.T_colour_depth.translation().norm(), 0.0325f, 1e-3f);
    EXPECT_NEAR(info.T_colour_depth.linear()(1, 2), 0.08616f, 1e-4f);

    CapturedFrame frame;
    int frames = 0;
    for (;;) {
        auto got = (*source)->next(frame);
        ASSERT_TRUE(got.isOk()) << got.status().toString();
        if (!*got) break;
        EXPECT_EQ(frame.index, static_cast<uint32_t>(frames));
        ASSERT_EQ(frame.depth_raw.type(), CV_16UC1);
        EXPECT_EQ(frame.depth_raw.cols, 640);
        EXPECT_EQ(frame.depth_raw.rows, 576);
        // A desk and a window seen from a tripod: most pixels measured, the median well inside 0.25-5 m.
        std::vector<uint16_t> valid;
        for (int v = 0; v < frame.depth_raw.rows; ++v) {
            for (int u = 0; u < frame.depth_raw.cols; ++u) {
                if (const uint16_t d = frame.depth_raw.at<uint16_t>(v, u); d > 0) valid.push_back(d);
            }
        }
        EXPECT_GT(valid.size(), frame.depth_raw.total() / 3);
        std::nth_element(valid.begin(), valid.begin() + static_cast<long>(valid.size() / 2), valid.end());
        const uint16_t median_mm = valid[valid.size() / 2];
        EXPECT_GT(median_mm, 250);
        EXPECT_LT(median_mm, 5000);
        ASSERT_EQ(frame.colour_bgr.type(), CV_8UC3);
        EXPECT_EQ(frame.colour_bgr.cols, 1280);
        EXPECT_EQ(frame.colour_bgr.rows, 720);
        EXPECT_GT(cv::mean(frame.colour_bgr)[1], 10.0) << "a lit room, not a black image";
        // Device time: the packet's 463945 us after the recording's start offset of 336277000 ns.
        EXPECT_EQ(frame.timestamp_ns, 463945000 + 336277000);
        ++frames;
    }
    // The file holds one capture (its one cluster has one block of colour, depth and IR each).
    EXPECT_EQ(frames, 1);
}

TEST_F(MkvSource, PairsColourByTimeAndKeepsDepthWithoutIt) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    const fs::path longer = dir_ / "three.mkv";
    writeFile(longer, repeated(readFile(data / "recording.mkv"), 3, 1));
    auto source = openMkvSource(longer.string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    CapturedFrame frame;
    std::vector<bool> coloured;
    std::vector<int64_t> times;
    for (;;) {
        auto got = (*source)->next(frame);
        ASSERT_TRUE(got.isOk()) << got.status().toString();
        if (!*got) break;
        EXPECT_EQ(frame.depth_raw.cols, 640);
        coloured.push_back(!frame.colour_bgr.empty());
        times.push_back(frame.timestamp_ns);
    }
    ASSERT_EQ(coloured.size(), 3u);
    // The middle capture lost its colour: it goes out as depth only, not with a neighbour's colour 200 ms away.
    EXPECT_EQ(coloured, (std::vector<bool>{true, false, true}));
    EXPECT_EQ(times[1] - times[0], 200000000);
    EXPECT_EQ(times[2] - times[1], 200000000);
}

TEST_F(MkvSource, MaxFramesAndNoColour) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    SourceOptions options;
    options.colour = false;
    options.max_frames = 2;
    const fs::path longer = dir_ / "three.mkv";
    writeFile(longer, repeated(readFile(data / "recording.mkv"), 3, -1));
    auto source = openMkvSource(longer.string(), options);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_FALSE((*source)->info().has_colour);
    CapturedFrame frame;
    int frames = 0;
    while (true) {
        auto got = (*source)->next(frame);
        ASSERT_TRUE(got.isOk()) << got.status().toString();
        if (!*got) break;
        EXPECT_TRUE(frame.colour_bgr.empty());
        ++frames;
    }
    EXPECT_EQ(frames, 2);
}

// Reads a source to its end; the first error, or ok.
Status readAll(FrameSource& source) {
    CapturedFrame frame;
    for (;;) {
        auto got = source.next(frame);
        if (!got.isOk()) return got.status();
        if (!*got) return Status::ok();
    }
}

TEST_F(MkvSource, ACutShortRecordingIsRefused) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    const std::vector<uint8_t> bytes = readFile(data / "recording.mkv");
    // Cut in the depth block, in the colour block, in the header.
    for (const double kept : {0.4, 0.1, 0.001}) {
        const fs::path cut = dir_ / "cut.mkv";
        writeFile(cut, std::vector<uint8_t>(bytes.begin(), bytes.begin() + static_cast<long>(bytes.size() * kept)));
        auto source = openMkvSource(cut.string(), {});
        const Status status = source.isOk() ? readAll(**source) : source.status();
        EXPECT_FALSE(status.isOk()) << "kept " << kept;
        EXPECT_EQ(status.message().find('\n'), std::string::npos) << status.message();
        EXPECT_NE(status.message().find(cut.string()), std::string::npos) << status.message();
    }
}

TEST_F(MkvSource, ARecordingWithoutDepthIsRefused) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    const fs::path no_depth = dir_ / "no-depth.mkv";
    std::vector<uint8_t> bytes = readFile(data / "recording.mkv");
    const Element tracks = find(segmentChildren(bytes), kTracks);
    const std::vector<Element> entries = children(bytes, tracks.body, tracks.end);
    ASSERT_EQ(entries.size(), 4u) << "COLOR, DEPTH, IR, IMU";
    ASSERT_EQ(entries[1].id, kTrackEntry);
    blank(bytes, entries[1]);  // DEPTH
    writeFile(no_depth, bytes);
    auto source = openMkvSource(no_depth.string(), {});
    ASSERT_FALSE(source.isOk());
    EXPECT_NE(source.status().message().find("no DEPTH track"), std::string::npos) << source.status().message();
    EXPECT_NE(source.status().message().find("--depth-mode"), std::string::npos) << "says what to do";
}

TEST_F(MkvSource, ARecordingWithoutItsCalibrationIsRefused) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    const fs::path no_calibration = dir_ / "no-calibration.mkv";
    std::vector<uint8_t> bytes = readFile(data / "recording.mkv");
    blank(bytes, find(segmentChildren(bytes), kAttachments));
    writeFile(no_calibration, bytes);
    auto source = openMkvSource(no_calibration.string(), {});
    ASSERT_FALSE(source.isOk());
    EXPECT_NE(source.status().message().find("no calibration.json"), std::string::npos) << source.status().message();
}

TEST_F(MkvSource, ColourOfAnotherFormatReplaysDepthOnlyAndSaysSo) {
    FACESCAN_REQUIRE_DATA(data, "azure_kinect_mkv");
    std::vector<uint8_t> bytes = readFile(data / "recording.mkv");
    const Element tracks = find(segmentChildren(bytes), kTracks);
    const std::string mjpeg = "MJPG";  // the COLOR track's FourCC (a VFW bitmap header)
    const auto at = std::search(bytes.begin() + static_cast<long>(tracks.body),
                                bytes.begin() + static_cast<long>(tracks.end), mjpeg.begin(), mjpeg.end());
    ASSERT_NE(at, bytes.begin() + static_cast<long>(tracks.end));
    std::copy_n(std::string("NV12").begin(), 4, at);  // as the recorder writes NV12 colour
    const fs::path other = dir_ / "other-colour.mkv";
    writeFile(other, bytes);
    auto source = openMkvSource(other.string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_FALSE((*source)->info().has_colour);
    EXPECT_NE((*source)->info().description.find("depth only"), std::string::npos) << (*source)->info().description;
    CapturedFrame frame;
    auto got = (*source)->next(frame);
    ASSERT_TRUE(got.isOk()) << got.status().toString();
    EXPECT_TRUE(*got);
    EXPECT_EQ(frame.depth_raw.cols, 640);
    EXPECT_TRUE(frame.colour_bgr.empty());
}

TEST_F(MkvSource, NotARecordingAtAll) {
    const fs::path text = dir_ / "notes.mkv";
    std::ofstream(text) << "these are notes, not a recording\n";
    auto source = openMkvSource(text.string(), {});
    ASSERT_FALSE(source.isOk());
    EXPECT_NE(source.status().message().find(text.string()), std::string::npos);
    auto missing = openMkvSource((dir_ / "absent.mkv").string(), {});
    ASSERT_FALSE(missing.isOk());
    EXPECT_NE(missing.status().message().find("mkv:"), std::string::npos) << "says how to give one";
}

TEST(AzureKinectCalibration, RefusesWhatIsNoCalibration) {
    EXPECT_FALSE(parseAzureKinectCalibration("", 640, 576, 0, 0).isOk());
    EXPECT_FALSE(parseAzureKinectCalibration("{\"a\": 1}", 640, 576, 0, 0).isOk());
    EXPECT_FALSE(parseAzureKinectCalibration("{\"CalibrationInformation\": {\"Cameras\": [", 640, 576, 0, 0).isOk());
    EXPECT_FALSE(parseAzureKinectCalibration("[1, 2, 3]", 640, 576, 0, 0).isOk());
}

// A calibration in the layout of the fixture's attachment; the tests below change one value at a time.
std::string calibrationJson(const std::string& depth_fx = "0.493", const std::string& colour_rotation_00 = "0.99999922",
                            const std::string& colour_translation_x = "-0.0321") {
    return R"({"CalibrationInformation":{"Cameras":[{"Intrinsics":{"ModelParameterCount":14,"ModelParameters":)"
           R"([0.513,0.517,)" +
           depth_fx +
           R"(,0.493,0.548,-0.021,-0.0027,0.89,0.086,-0.014,0,0,-7.2E-5,2.1E-5],)"
           R"("ModelType":"CALIBRATION_LensDistortionModelBrownConrady"},)"
           R"("Purpose":"CALIBRATION_CameraPurposeDepth","Rt":{"Rotation":[1,0,0,0,1,0,0,0,1],"Translation":[0,0,0]},)"
           R"("SensorHeight":1024,"SensorWidth":1024},{"Intrinsics":{"ModelParameterCount":14,"ModelParameters":)"
           R"([0.4998,0.5066,0.478,0.637,0.33,-2.49,1.45,0.209,-2.30,1.375,0,0,-1.3E-4,-1.6E-4],)"
           R"("ModelType":"CALIBRATION_LensDistortionModelBrownConrady"},)"
           R"("Purpose":"CALIBRATION_CameraPurposePhotoVideo","Rt":{"Rotation":[)" +
           colour_rotation_00 +
           R"(,0.00118,-0.000448,-0.001139,0.99628,0.08616,0.000548,-0.08616,0.99628],"Translation":[)" +
           colour_translation_x + R"(,-0.0022,0.0039]},"SensorHeight":3072,"SensorWidth":4096}]}})";
}

TEST(AzureKinectCalibration, ReadsAWellFormedCalibration) {
    const auto parsed = parseAzureKinectCalibration(calibrationJson(), 640, 576, 1280, 720);
    ASSERT_TRUE(parsed.isOk()) << parsed.status().message();
    EXPECT_NEAR(parsed->depth.intrinsics.fx_px, 0.493f * 1024, 1e-2f);
    EXPECT_NEAR(parsed->colour.intrinsics.fx_px, 0.478f * 1280, 1e-2f);
    EXPECT_NEAR(parsed->T_colour_depth.translation().x(), -0.0321f, 1e-6f);
}

// Finite numbers in the file can still make an unusable camera: a normalised focal length of 1e300 overflows the
// float pixel value, a negative one is no pinhole, and a "rotation" of scale 1e20 (or a mirror) makes the
// depth-to-colour transform meaningless. Each is refused with a line that names the camera.
TEST(AzureKinectCalibration, RefusesFiniteValuesThatMakeNoCamera) {
    const auto refusal = [](const std::string& json) {
        const auto parsed = parseAzureKinectCalibration(json, 640, 576, 1280, 720);
        return parsed.isOk() ? std::string() : parsed.status().message();
    };
    EXPECT_NE(refusal(calibrationJson("1e300")).find("depth camera's pinhole"), std::string::npos);
    EXPECT_NE(refusal(calibrationJson("-0.493")).find("depth camera's pinhole"), std::string::npos);
    EXPECT_NE(refusal(calibrationJson("0.493", "1e20")).find("colour camera's Rt rotation"), std::string::npos);
    EXPECT_NE(refusal(calibrationJson("0.493", "-0.99999922")).find("colour camera's Rt rotation"), std::string::npos);
    EXPECT_NE(refusal(calibrationJson("0.493", "0.99999922", "3e30")).find("translation is over 10 m"),
              std::string::npos);
}

}  // namespace
}  // namespace facescan::capture
