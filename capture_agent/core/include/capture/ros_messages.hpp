// The ROS 1 messages of RealSense bags (sensor_msgs, geometry_msgs, std_msgs, as Debian ships them) in C++20.
// Their generated headers name `ContainerAllocator::rebind<T>::other`, which std::allocator no longer has in C++20;
// every message is a template over its allocator, so they are used with an allocator that still offers it. The
// serialisation, MD5 sums and data types are ROS's own (they are templates over the allocator too).
#pragma once

#include <memory>

namespace facescan::capture::ros1 {

template <typename T>
struct Allocator : std::allocator<T> {
    using value_type = T;
    Allocator() noexcept = default;
    template <typename U>
    Allocator(const Allocator<U>&) noexcept {}  // NOLINT: converting, as allocators are
    template <typename U>
    struct rebind {
        using other = Allocator<U>;
    };
};

}  // namespace facescan::capture::ros1

#include <geometry_msgs/Transform.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/Float32.h>

namespace facescan::capture::ros1 {

using Image = sensor_msgs::Image_<Allocator<void>>;
using CameraInfo = sensor_msgs::CameraInfo_<Allocator<void>>;
using Transform = geometry_msgs::Transform_<Allocator<void>>;
using Float32 = std_msgs::Float32_<Allocator<void>>;

}  // namespace facescan::capture::ros1
