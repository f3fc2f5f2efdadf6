// Recordings of today's depth cameras, replayed without the hardware: Azure Kinect / Orbbec Femto Matroska files
// (mkv:FILE) and Intel RealSense ROS 1 bags (bag:FILE). The parts that parse file bytes are exposed for the tests
// and fuzzers (tests/fuzz).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "capture/frame_source.hpp"

namespace facescan::capture {

// mkv:FILE -- an Azure Kinect (or Orbbec Femto, same layout) recording: depth from the 'DEPTH' track (b16g,
// 16-bit big-endian millimetres), MJPEG colour from 'COLOR', both cameras' intrinsics and the depth-to-colour
// extrinsics from the calibration.json attachment. Both images are undistorted to the pinhole model the rest of
// the pipeline uses (Brown-Conrady, see AzureKinectCalibration); colour is paired with the depth frame nearest in
// time.
StatusOr<std::unique_ptr<FrameSource>> openMkvSource(const std::string& path, const SourceOptions& options);

// bag:FILE -- an Intel RealSense recording (ROS 1 bag in librealsense's layout): depth (16UC1) and colour
// (rgb8/bgr8) images, their camera_info, the depth units and the depth-to-colour extrinsics.
StatusOr<std::unique_ptr<FrameSource>> openBagSource(const std::string& path, const SourceOptions& options);

// One camera of an Azure Kinect calibration at the resolution it was recorded in: pinhole intrinsics (OpenCV
// convention, pixel centres at integers) and the Brown-Conrady distortion in OpenCV's rational-model order
// (k1, k2, p1, p2, k3, k4, k5, k6).
struct AzureKinectCamera {
    recon::Intrinsics intrinsics;
    std::vector<double> distortion;  // 8 coefficients, OpenCV order
};

struct AzureKinectCalibration {
    AzureKinectCamera depth;
    AzureKinectCamera colour;    // width 0 when the recording has no colour
    recon::Pose T_colour_depth;  // p_colour = T_colour_depth * p_depth (metres)
};

// Parses the Azure Kinect SDK's calibration.json for a recording whose depth images are depth_width x depth_height
// and colour images colour_width x colour_height (0 x 0: no colour): the SDK's normalised, corner-origin
// parameters of the full sensor become pixel intrinsics of that mode (the SDK's binning and crop of each mode).
// DataLoss with one line saying what is wrong for JSON that is not such a calibration or a mode it does not know.
StatusOr<AzureKinectCalibration> parseAzureKinectCalibration(const std::string& json, int depth_width, int depth_height,
                                                             int colour_width, int colour_height);

}  // namespace facescan::capture
