// Writes a RealSense recording for tests: a ROS 1 bag in librealsense's layout (the topics bag_source.cpp reads),
// written with ROS's own rosbag storage library from any frame source (the synthetic Kinect), with the depth
// units, the colour camera and the depth-to-colour extrinsics a test chooses.
#pragma once

#include <cmath>
#include <cstring>
#include <functional>
#include <string>

#include "capture/frame_source.hpp"
#include "capture/ros_messages.hpp"

namespace facescan::testing {

struct RealSenseBagSpec {
    float depth_units_m = 0.001f;  // the Depth Units option written
    float raw_per_mm = 1.0f;       // the recorded raw depth = the source's millimetres times this
    bool colour = true;
    std::string colour_encoding = "rgb8";  // written as the encoding's name; the pixels are rgb8's either way
    bool depth_camera_info = true;
    bool depth_stream = true;
    recon::Pose T_colour_depth = recon::Pose::Identity();
};

inline void writeRealSenseBag(const std::string& path, capture::FrameSource& source, const RealSenseBagSpec& spec) {
    namespace ros1 = capture::ros1;
    rosbag::Bag bag;
    bag.open(path, rosbag::bagmode::Write);
    const recon::Intrinsics& k = source.info().intrinsics;
    const ros::Time info_time(0, 1);  // librealsense writes the static streams' info at the file's start
    const std::string depth = "/device_0/sensor_0/Depth_0", colour = "/device_0/sensor_1/Color_0";
    auto cameraInfo = [&](const recon::Intrinsics& c) {
        ros1::CameraInfo info;
        info.width = static_cast<uint32_t>(c.width_px);
        info.height = static_cast<uint32_t>(c.height_px);
        info.distortion_model = "Brown Conrady";
        info.D.assign(5, 0.0);
        info.K = {c.fx_px, 0, c.cx_px, 0, c.fy_px, c.cy_px, 0, 0, 1};
        return info;
    };
    if (spec.depth_camera_info) bag.write(depth + "/info/camera_info", info_time, cameraInfo(k));
    ros1::Transform identity;
    identity.rotation.w = 1;
    bag.write(depth + "/tf/0", info_time, identity);
    ros1::Float32 units;
    units.data = spec.depth_units_m;
    bag.write("/device_0/sensor_0/option/Depth Units/value", info_time, units);
    if (spec.colour) {
        bag.write(colour + "/info/camera_info", info_time, cameraInfo(k));
        ros1::Transform tf;
        const Eigen::Quaternionf q(spec.T_colour_depth.linear());
        tf.rotation.w = q.w();
        tf.rotation.x = q.x();
        tf.rotation.y = q.y();
        tf.rotation.z = q.z();
        tf.translation.x = spec.T_colour_depth.translation().x();
        tf.translation.y = spec.T_colour_depth.translation().y();
        tf.translation.z = spec.T_colour_depth.translation().z();
        bag.write(colour + "/tf/0", info_time, tf);
    }
    capture::CapturedFrame frame;
    for (uint32_t n = 0;; ++n) {
        auto got = source.next(frame);
        if (!got.isOk() || !*got) break;
        // 30 Hz device time, starting a second into the recording.
        const ros::Time stamp(1, 0);
        const ros::Time t = stamp + ros::Duration(0, static_cast<int32_t>(n * 33333333));
        ros1::Image d;
        d.header.stamp = t;
        d.header.seq = n;
        d.width = static_cast<uint32_t>(frame.depth_raw.cols);
        d.height = static_cast<uint32_t>(frame.depth_raw.rows);
        d.encoding = "16UC1";
        d.step = d.width * 2;
        d.data.resize(static_cast<size_t>(d.step) * d.height);
        for (int v = 0; v < frame.depth_raw.rows; ++v) {
            for (int u = 0; u < frame.depth_raw.cols; ++u) {
                const float mm = frame.depth_raw.at<uint16_t>(v, u) * source.info().depth_units_m * 1000.0f;
                const auto raw = static_cast<uint16_t>(std::min(65535.0f, std::round(mm * spec.raw_per_mm)));
                std::memcpy(&d.data[static_cast<size_t>(v) * d.step + static_cast<size_t>(u) * 2], &raw, 2);
            }
        }
        if (spec.depth_stream) bag.write(depth + "/image/data", t, d);
        if (spec.colour && !frame.colour_bgr.empty()) {
            ros1::Image c;
            c.header.stamp = t;
            c.width = static_cast<uint32_t>(frame.colour_bgr.cols);
            c.height = static_cast<uint32_t>(frame.colour_bgr.rows);
            c.encoding = spec.colour_encoding;
            c.step = c.width * 3;
            c.data.resize(static_cast<size_t>(c.step) * c.height);
            for (int v = 0; v < frame.colour_bgr.rows; ++v) {
                for (int u = 0; u < frame.colour_bgr.cols; ++u) {
                    const cv::Vec3b bgr = frame.colour_bgr.at<cv::Vec3b>(v, u);
                    uint8_t* px = &c.data[static_cast<size_t>(v) * c.step + static_cast<size_t>(u) * 3];
                    px[0] = bgr[2];
                    px[1] = bgr[1];
                    px[2] = bgr[0];
                }
            }
            bag.write(colour + "/image/data", t, c);
        }
    }
    bag.close();
}

}  // namespace facescan::testing
