// CameraInfo carries the camera: its range, kind, noise, colour camera and extrinsics round-trip; an older agent's
// CameraInfo (the appended fields zero) and an older server's replica (format 2) read as a Kinect v1; and each
// description that cannot be right, and depth in the wrong units, is refused with one line saying what to do. The
// agent's roll hint travels too (0 on the wire, an older agent's, is unknown) and a roll that is no quarter turn is
// refused; so does a recording's progress (the owner epoch followed, the frames dropped), where it can be.
#include <gtest/gtest.h>

#include <cstring>

#include "recon/sensor.hpp"
#include "sample_replica.hpp"
#include "wire/replica_codec.hpp"

namespace facescan::wire {
namespace {

CameraInfoData trueDepthCamera() {
    CameraInfoData c;
    c.session_id = "cam-1";
    c.intrinsics = recon::findSensorPreset("truedepth")->nominal_depth;
    c.sensor = recon::findSensorPreset("truedepth")->sensor;
    c.sensor.noise = {0.0004f, 0.0f, 0.001f};
    c.colour_registered = false;
    c.colour_intrinsics = {1280, 720, 910.0f, 905.0f, 640.5f, 360.5f};
    c.T_colour_depth = recon::Pose::Identity();
    c.T_colour_depth.linear() = Eigen::AngleAxisf(0.02f, Eigen::Vector3f::UnitY()).toRotationMatrix();
    c.T_colour_depth.translation() = Eigen::Vector3f(-0.032f, 0.001f, 0.0005f);
    return c;
}

TEST(CameraInfo, TheCameraRoundTrips) {
    const CameraInfoData in = trueDepthCamera();
    ASSERT_TRUE(in.validate().isOk()) << in.validate().toString();
    const auto out = fromMessage(toMessage(in));
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    EXPECT_EQ(out->sensor, in.sensor);
    EXPECT_EQ(out->intrinsics, in.intrinsics);
    EXPECT_EQ(out->colour_intrinsics, in.colour_intrinsics);
    EXPECT_TRUE(out->T_colour_depth.matrix().isApprox(in.T_colour_depth.matrix(), 1e-6f));
    EXPECT_FALSE(out->colour_registered);
}

TEST(CameraInfo, AnOlderAgentsCameraInfoIsAKinectV1) {
    CameraInfoData in;
    in.session_id = "old-agent";
    facescan_wire_CameraInfo msg = toMessage(in);
    // What an agent from before the appended fields sends: they arrive as zeros.
    msg.min_depth_m = msg.max_depth_m = 0.0f;
    msg.sensor_family = facescan_wire_SENSOR_UNKNOWN;
    msg.sensor_name = const_cast<char*>("");
    msg.noise_c0_m = msg.noise_c1 = msg.noise_c2_per_m = 0.0f;
    msg.colour_width = msg.colour_height = 0;
    msg.colour_fx = msg.colour_fy = msg.colour_cx = msg.colour_cy = 0.0f;
    std::memset(msg.R_colour_depth, 0, sizeof(msg.R_colour_depth));
    std::memset(msg.t_colour_depth_m, 0, sizeof(msg.t_colour_depth_m));
    const auto out = fromMessage(msg);
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    EXPECT_EQ(out->sensor, recon::SensorModel::kinectV1());
    EXPECT_EQ(out->colourIntrinsics(), out->intrinsics);
    EXPECT_TRUE(out->T_colour_depth.matrix().isIdentity());
}

TEST(CameraInfo, TheRollHintRoundTripsAndAnOlderAgentsIsUnknown) {
    for (const int roll : {CameraInfoData::kRollUnknown, 0, 90, 180, 270, 15, 30, 45, 345}) {
        CameraInfoData in = trueDepthCamera();
        in.roll_deg = roll;
        ASSERT_TRUE(in.validate().isOk()) << roll << ": " << in.validate().toString();
        const facescan_wire_CameraInfo msg = toMessage(in);
        // Unknown travels as the 0 an older agent leaves; upright and known as a full turn.
        EXPECT_EQ(msg.roll_deg, roll == CameraInfoData::kRollUnknown ? 0 : roll == 0 ? 360 : roll);
        const auto out = fromMessage(msg);
        ASSERT_TRUE(out.isOk()) << roll << ": " << out.status().toString();
        EXPECT_EQ(out->roll_deg, roll);
    }
    CameraInfoData in;
    in.session_id = "old-agent";
    facescan_wire_CameraInfo msg = toMessage(in);
    msg.roll_deg = 0;  // an agent from before the field
    const auto out = fromMessage(msg);
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    EXPECT_EQ(out->roll_deg, CameraInfoData::kRollUnknown);
}

TEST(CameraInfo, ARollThatIsNoStepIsRefusedWithOneLine) {
    for (const int wire_roll : {40, -90, 1, 359, 375, 450, 720}) {
        CameraInfoData in = trueDepthCamera();
        facescan_wire_CameraInfo msg = toMessage(in);
        msg.roll_deg = wire_roll;
        const auto out = fromMessage(msg);
        ASSERT_FALSE(out.isOk()) << wire_roll;
        EXPECT_NE(out.status().message().find("--roll"), std::string::npos) << out.status().message();
        EXPECT_EQ(out.status().message().find('\n'), std::string::npos) << out.status().message();
    }
    CameraInfoData c = trueDepthCamera();
    c.roll_deg = 50;
    const Status s = c.validate();
    ASSERT_FALSE(s.isOk());
    EXPECT_NE(s.message().find("0 to 345 in steps of 15"), std::string::npos) << s.message();
}

TEST(CameraInfo, ARecordingsProgressRoundTripsAndAnImpossibleOneIsRefused) {
    CameraInfoData in = trueDepthCamera();
    in.every_frame = true;
    in.followed_epoch = 3;
    in.dropped_before_seq = 41;
    in.serving_epoch = 3;
    ASSERT_TRUE(in.validate().isOk()) << in.validate().toString();
    const auto out = fromMessage(toMessage(in));
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    EXPECT_EQ(out->followed_epoch, 3u);
    EXPECT_EQ(out->dropped_before_seq, 41u);
    EXPECT_EQ(out->serving_epoch, 3u);
    // Frames dropped by a live scan's agent (it keeps none), or before any owner confirmed them.
    for (const auto& [every_frame, epoch] : {std::pair{false, 3u}, std::pair{true, 0u}}) {
        facescan_wire_CameraInfo msg = toMessage(in);
        msg.every_frame = every_frame;
        msg.followed_epoch = epoch;
        const auto bad = fromMessage(msg);
        ASSERT_FALSE(bad.isOk()) << every_frame << " " << epoch;
        EXPECT_NE(bad.status().message().find("dropped frames before 41"), std::string::npos) << bad.status().message();
        EXPECT_EQ(bad.status().message().find('\n'), std::string::npos) << bad.status().message();
    }
}

void expectRefused(const CameraInfoData& c, const std::string& says) {
    const Status s = c.validate();
    EXPECT_FALSE(s.isOk()) << "accepted; expected: " << says;
    EXPECT_NE(s.message().find(says), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << "one line: " << s.message();
}

TEST(CameraInfo, ADescriptionThatCannotBeRightIsRefusedWithOneLine) {
    CameraInfoData c = trueDepthCamera();
    c.sensor.min_depth_m = 0.5f;
    c.sensor.max_depth_m = 0.2f;
    expectRefused(c, "inverted");
    c = trueDepthCamera();
    c.sensor.min_depth_m = 0.0f;
    expectRefused(c, "0 < min < max");
    c = trueDepthCamera();
    c.intrinsics.fx_px = 0.0f;
    expectRefused(c, "focal lengths");
    c = trueDepthCamera();
    c.colour_intrinsics.fy_px = 0.0f;
    expectRefused(c, "colour camera intrinsics");
    c = trueDepthCamera();
    c.colour_registered = true;  // registered colour must have the depth's size
    expectRefused(c, "registered");
    c = trueDepthCamera();
    c.T_colour_depth.linear() *= 2.0f;
    expectRefused(c, "extrinsics");
    // And through the message, as a server receives it.
    c = trueDepthCamera();
    c.sensor.max_depth_m = 0.1f;
    EXPECT_FALSE(fromMessage(toMessage(c)).isOk());
}

TEST(CameraInfo, DepthInTheWrongUnitsIsRefusedWithOneLine) {
    CameraInfoData c = trueDepthCamera();  // 0.2-0.5 m
    c.depth_units_m = 0.001f;
    const cv::Mat head(240, 320, CV_16UC1, cv::Scalar(300));  // 0.3 m in millimetres
    EXPECT_TRUE(c.checkDepthUnits(head).isOk());
    EXPECT_TRUE(c.checkDepthUnits(cv::Mat(240, 320, CV_16UC1, cv::Scalar(0))).isOk()) << "no measurement yet";
    // Metres per unit where millimetres were meant: a median of 300 m.
    c.depth_units_m = 1.0f;
    Status s = c.checkDepthUnits(head);
    ASSERT_FALSE(s.isOk());
    EXPECT_NE(s.message().find("300 m"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("depth units"), std::string::npos) << s.message();
    // Micrometres per unit where millimetres were meant: 0.3 mm.
    c.depth_units_m = 1e-6f;
    s = c.checkDepthUnits(head);
    ASSERT_FALSE(s.isOk());
    EXPECT_NE(s.message().find("0.0003 m"), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos);
}

TEST(CameraInfo, AnUnknownPresetListsTheKnownOnes) {
    const auto found = recon::findSensorPreset("kinect-v3");
    ASSERT_FALSE(found.isOk());
    for (const char* name : {"kinect-v1", "xtion", "astra", "realsense-d415", "azure-kinect", "truedepth"}) {
        EXPECT_NE(found.status().message().find(name), std::string::npos) << found.status().message();
        const auto preset = recon::findSensorPreset(name);
        ASSERT_TRUE(preset.isOk()) << name;
        EXPECT_TRUE(preset->sensor.validate().isOk()) << name;
    }
}

TEST(CameraInfo, TheReplicaCarriesTheCamera) {
    ReplicaData r = testing::sampleReplica(6, true);
    const std::string session = r.session_id;
    r.camera = trueDepthCamera();
    r.camera.session_id = session;
    r.camera.every_frame = true;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeReplica(r, bytes).isOk());
    ReplicaData out;
    ASSERT_TRUE(decodeReplica(bytes.data(), bytes.size(), out).isOk());
    EXPECT_EQ(out.camera.sensor, r.camera.sensor);
    EXPECT_EQ(out.camera.colour_intrinsics, r.camera.colour_intrinsics);
    EXPECT_TRUE(out.camera.T_colour_depth.matrix().isApprox(r.camera.T_colour_depth.matrix()));
}

}  // namespace
}  // namespace facescan::wire
