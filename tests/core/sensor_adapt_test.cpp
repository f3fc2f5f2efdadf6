// Every stage's camera-dependent limits from the camera (recon/sensor_adapt.hpp): a Kinect v1 at 640x480 gets
// exactly the defaults the pipeline was tuned with; a near-range camera gets its own range, advice and pixel
// thresholds; every preset gives parameters the stages accept.
#include "recon/sensor_adapt.hpp"

#include <gtest/gtest.h>

namespace facescan::recon {
namespace {

struct Adapted {
    ReconParams recon = ReconParams::faceDefaults();
    FacePipelineParams face;
    AdviceParams advice;
};

Adapted adapt(const SensorModel& sensor, const Intrinsics& k) {
    Adapted a;
    adaptToSensor(sensor, k, a.recon, a.face, a.advice);
    return a;
}

TEST(SensorAdapt, AKinectV1GetsExactlyTheDefaults) {
    const Adapted d;  // untouched
    const Adapted a = adapt(SensorModel::kinectV1(), Intrinsics::kinectV1());
    EXPECT_EQ(a.face.detector.min_depth_m, d.face.detector.min_depth_m);
    EXPECT_EQ(a.face.detector.max_depth_m, d.face.detector.max_depth_m);
    EXPECT_EQ(a.face.segmenter.min_depth_m, d.face.segmenter.min_depth_m);
    EXPECT_EQ(a.face.segmenter.max_depth_m, d.face.segmenter.max_depth_m);
    EXPECT_EQ(a.recon.filter.min_depth_m, d.recon.filter.min_depth_m);
    EXPECT_EQ(a.recon.filter.max_depth_m, d.recon.filter.max_depth_m);
    EXPECT_EQ(a.advice.near_m, d.advice.near_m);
    EXPECT_EQ(a.advice.far_m, d.advice.far_m);
    EXPECT_EQ(a.recon.min_head_pixels, d.recon.min_head_pixels);
    EXPECT_EQ(a.recon.roi_margin_px, d.recon.roi_margin_px);
    EXPECT_EQ(a.face.model.min_pixels, d.face.model.min_pixels);
    EXPECT_EQ(a.face.finder.level, d.face.finder.level);
    EXPECT_EQ(a.face.finder.min_blob_px, d.face.finder.min_blob_px);
    EXPECT_EQ(a.recon.tsdf.resolution_vox, d.recon.tsdf.resolution_vox);
    EXPECT_EQ(a.recon.tsdf.trunc_dist_m, d.recon.tsdf.trunc_dist_m);
    EXPECT_EQ(a.recon.tsdf.max_blocks, d.recon.tsdf.max_blocks);
    // An older agent's CameraInfo is a Kinect v1: its values are the ones the Kinect-only pipeline had.
    EXPECT_EQ(a.face.segmenter.min_depth_m, 0.4f);
    EXPECT_EQ(a.advice.near_m, 0.5f);
}

TEST(SensorAdapt, ANearRangeCameraGetsItsOwnRangeAdviceAndPixelThresholds) {
    const SensorPreset truedepth = *findSensorPreset("truedepth");
    const Adapted a = adapt(truedepth.sensor, truedepth.nominal_depth);
    EXPECT_EQ(a.face.detector.min_depth_m, 0.2f);
    EXPECT_EQ(a.face.segmenter.min_depth_m, 0.2f);
    EXPECT_EQ(a.face.segmenter.max_depth_m, 0.5f);
    EXPECT_LT(a.recon.filter.min_depth_m, 0.2f);
    EXPECT_GE(a.recon.filter.max_depth_m, 0.3f);
    // A head at 0.3 m is neither "too close" nor "too far" for it.
    EXPECT_LT(a.advice.near_m, 0.3f);
    EXPECT_GT(a.advice.far_m, 0.3f);
    EXPECT_LE(a.advice.far_m, 0.5f);
    // 320x240 at f = 217.5 px: a head covers about 1/7 of the Kinect's pixels at the same distance.
    EXPECT_LT(a.recon.min_head_pixels, 100);
    EXPECT_GE(a.recon.min_head_pixels, 50);
    EXPECT_EQ(a.face.finder.level, 1) << "blobs at 160x120, as on VGA";
    EXPECT_TRUE(a.recon.validate().isOk());
    EXPECT_TRUE(a.face.validate().isOk());
    EXPECT_TRUE(a.advice.validate().isOk());
}

TEST(SensorAdapt, ALowerNoiseGivesAFinerModel) {
    SensorPreset truedepth = *findSensorPreset("truedepth");
    const Adapted unknown = adapt(truedepth.sensor, truedepth.nominal_depth);
    EXPECT_EQ(unknown.recon.tsdf.resolution_vox, 256) << "unknown noise: Meyer's volume";
    EXPECT_EQ(unknown.recon.tsdf.trunc_dist_m, 0.005f);
    truedepth.sensor.noise = {0.0008f, -0.004f, 0.01f};  // 0.4 + 10 (z - 0.2)^2 mm: 0.5 mm at 0.3 m
    const Adapted a = adapt(truedepth.sensor, truedepth.nominal_depth);
    EXPECT_GT(a.recon.tsdf.resolution_vox, 256);
    EXPECT_EQ(a.recon.tsdf.resolution_vox % kBlockSide, 0);
    EXPECT_LE(a.recon.tsdf.voxelSizeM(), 0.00102f);
    EXPECT_LT(a.recon.tsdf.trunc_dist_m, 0.005f);
    EXPECT_GE(a.recon.tsdf.trunc_dist_m, 2.0f * a.recon.tsdf.voxelSizeM() - 1e-6f);
    EXPECT_TRUE(a.recon.validate().isOk()) << a.recon.validate().toString();
    const std::string line = describeSensor(truedepth.sensor, a.advice, a.recon.tsdf);
    EXPECT_NE(line.find("finer than a Kinect"), std::string::npos) << line;
    // A noisier camera than the Kinect is never given a coarser volume than Meyer's.
    SensorModel noisy = SensorModel::kinectV1();
    noisy.noise.c0_m *= 3.0f;
    const Adapted n = adapt(noisy, Intrinsics::kinectV1());
    EXPECT_EQ(n.recon.tsdf.resolution_vox, 256);
    EXPECT_EQ(n.recon.tsdf.trunc_dist_m, 0.005f);
}

TEST(SensorAdapt, EveryPresetGivesParametersTheStagesAccept) {
    for (const SensorPreset& p : sensorPresets()) {
        const Adapted a = adapt(p.sensor, p.nominal_depth);
        EXPECT_TRUE(a.recon.validate().isOk()) << p.name << ": " << a.recon.validate().toString();
        EXPECT_TRUE(a.face.validate().isOk()) << p.name << ": " << a.face.validate().toString();
        EXPECT_TRUE(a.advice.validate().isOk()) << p.name << ": " << a.advice.validate().toString();
        EXPECT_GE(a.advice.near_m, p.sensor.min_depth_m) << p.name;
        EXPECT_LE(a.advice.far_m, p.sensor.max_depth_m) << p.name;
        EXPECT_NE(describeSensor(p.sensor, a.advice, a.recon.tsdf).find(p.name), std::string::npos);
    }
}

}  // namespace
}  // namespace facescan::recon
