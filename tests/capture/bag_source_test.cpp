// bag:FILE on RealSense recordings written in librealsense's layout with ROS's own bag library, from the synthetic
// Kinect: sizes, intrinsics, depth units, extrinsics, colour, device timestamps, and the frames themselves; and
// bags that cannot be read (no depth topic, no camera_info, cut short, not a bag) refused with one line.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "capture/recording_sources.hpp"
#include "realsense_bag.hpp"

namespace facescan::capture {
namespace {

namespace fs = std::filesystem;
using facescan::testing::RealSenseBagSpec;

class BagSource : public ::testing::Test {
 protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("facescan-bag-" + std::to_string(getpid()));
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    std::unique_ptr<FrameSource> synthetic(int frames) {
        auto source = openSource("synthetic:frames=" + std::to_string(frames) + ",subject=builtin,seed=3", {});
        EXPECT_TRUE(source.isOk()) << source.status().toString();
        return std::move(*source);
    }
    fs::path write(const std::string& name, int frames, const RealSenseBagSpec& spec) {
        const fs::path path = dir_ / name;
        auto source = synthetic(frames);
        facescan::testing::writeRealSenseBag(path.string(), *source, spec);
        return path;
    }
    fs::path dir_;
};

TEST_F(BagSource, ReadsBackWhatWasRecorded) {
    RealSenseBagSpec spec;
    spec.depth_units_m = 0.0001f;  // a D400 set to 0.1 mm units
    spec.raw_per_mm = 10.0f;
    spec.T_colour_depth.linear() = Eigen::AngleAxisf(0.05f, Eigen::Vector3f::UnitY()).toRotationMatrix();
    spec.T_colour_depth.translation() = Eigen::Vector3f(0.015f, 0.0f, 0.0f);
    const fs::path path = write("d415.bag", 5, spec);

    auto source = openBagSource(path.string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    const SourceInfo& info = (*source)->info();
    auto truth_source = synthetic(5);
    const recon::Intrinsics& k = truth_source->info().intrinsics;
    EXPECT_EQ(info.intrinsics.width_px, k.width_px);
    EXPECT_EQ(info.intrinsics.height_px, k.height_px);
    EXPECT_FLOAT_EQ(info.intrinsics.fx_px, k.fx_px);
    EXPECT_FLOAT_EQ(info.intrinsics.cy_px, k.cy_px);
    EXPECT_FLOAT_EQ(info.depth_units_m, 0.0001f);
    EXPECT_TRUE(info.has_colour);
    EXPECT_FALSE(info.colour_registered);
    EXPECT_EQ(info.colour_intrinsics.width_px, k.width_px);
    EXPECT_TRUE(info.T_colour_depth.isApprox(spec.T_colour_depth, 1e-5f));
    EXPECT_EQ(info.expected_frames, 5);
    EXPECT_NEAR(info.rate_hz, 30.0f, 0.1f);
    EXPECT_TRUE(info.sensor_known);
    EXPECT_EQ(info.sensor.name, "realsense-d415");

    CapturedFrame frame, truth;
    int frames = 0;
    for (;;) {
        auto got = (*source)->next(frame);
        ASSERT_TRUE(got.isOk()) << got.status().toString();
        if (!*got) break;
        ASSERT_TRUE(*truth_source->next(truth));
        EXPECT_EQ(frame.index, static_cast<uint32_t>(frames));
        EXPECT_EQ(frame.timestamp_ns, 1000000000 + static_cast<int64_t>(frames) * 33333333);
        // The same depth, in tenths of millimetres.
        cv::Mat expected;
        truth.depth_raw.convertTo(expected, CV_32F, truth_source->info().depth_units_m * 1e4);
        cv::Mat got_depth;
        frame.depth_raw.convertTo(got_depth, CV_32F);
        EXPECT_LE(cv::norm(got_depth, expected, cv::NORM_INF), 0.5);
        ASSERT_EQ(frame.colour_bgr.type(), CV_8UC3);
        EXPECT_EQ(cv::norm(frame.colour_bgr, truth.colour_bgr, cv::NORM_INF), 0.0) << "rgb8 back to BGR exactly";
        ++frames;
    }
    EXPECT_EQ(frames, 5);
}

TEST_F(BagSource, DepthOnlyAndMaxFrames) {
    RealSenseBagSpec spec;
    spec.colour = false;
    const fs::path path = write("depth-only.bag", 4, spec);
    SourceOptions options;
    options.max_frames = 3;
    auto source = openBagSource(path.string(), options);
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_FALSE((*source)->info().has_colour);
    EXPECT_EQ((*source)->info().expected_frames, 3);
    CapturedFrame frame;
    int frames = 0;
    while (*(*source)->next(frame)) {
        EXPECT_TRUE(frame.colour_bgr.empty());
        ++frames;
    }
    EXPECT_EQ(frames, 3);
}

TEST_F(BagSource, ColourOfAnotherEncodingReplaysDepthOnlyAndSaysSo) {
    RealSenseBagSpec spec;
    spec.colour_encoding = "yuyv";
    auto source = openBagSource(write("yuyv.bag", 2, spec).string(), {});
    ASSERT_TRUE(source.isOk()) << source.status().toString();
    EXPECT_FALSE((*source)->info().has_colour);
    EXPECT_NE((*source)->info().description.find("colour yuyv is not rgb8/bgr8: depth only"), std::string::npos)
        << (*source)->info().description;
    CapturedFrame frame;
    auto got = (*source)->next(frame);
    ASSERT_TRUE(got.isOk()) << got.status().toString();
    EXPECT_TRUE(*got);
    EXPECT_TRUE(frame.colour_bgr.empty());
}

TEST_F(BagSource, ABagWithoutDepthOrItsCameraIsRefused) {
    RealSenseBagSpec no_depth;
    no_depth.depth_stream = false;
    auto source = openBagSource(write("no-depth.bag", 2, no_depth).string(), {});
    ASSERT_FALSE(source.isOk());
    EXPECT_NE(source.status().message().find("Depth_N/image/data"), std::string::npos) << source.status().message();
    EXPECT_EQ(source.status().message().find('\n'), std::string::npos);

    RealSenseBagSpec no_info;
    no_info.depth_camera_info = false;
    source = openBagSource(write("no-info.bag", 2, no_info).string(), {});
    ASSERT_FALSE(source.isOk());
    EXPECT_NE(source.status().message().find("no camera_info"), std::string::npos) << source.status().message();
}

TEST_F(BagSource, CutShortOrNotABag) {
    const fs::path whole = write("whole.bag", 4, {});
    std::ifstream in(whole, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    for (const double kept : {0.5, 0.01}) {
        const fs::path cut = dir_ / "cut.bag";
        std::ofstream(cut, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size() * kept));
        auto source = openBagSource(cut.string(), {});
        Status status = source.status();
        if (source.isOk()) {
            CapturedFrame frame;
            for (;;) {
                auto got = (*source)->next(frame);
                if (!got.isOk()) {
                    status = got.status();
                    break;
                }
                if (!*got) break;
            }
        }
        EXPECT_FALSE(status.isOk()) << "kept " << kept;
        EXPECT_NE(status.message().find(cut.string()), std::string::npos) << status.message();
        EXPECT_NE(status.message().find("cut short"), std::string::npos) << status.message();
        EXPECT_EQ(status.message().find('\n'), std::string::npos) << status.message();
    }
    const fs::path text = dir_ / "notes.bag";
    std::ofstream(text) << "not a bag\n";
    auto source = openBagSource(text.string(), {});
    ASSERT_FALSE(source.isOk());
    EXPECT_NE(source.status().message().find("bag:"), std::string::npos) << source.status().message();
}

}  // namespace
}  // namespace facescan::capture
