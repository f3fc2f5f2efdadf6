// The Azure Kinect SDK's calibration.json (the attachment of every Azure Kinect and Orbbec Femto recording) to
// pixel intrinsics of the recorded modes and the depth-to-colour extrinsics. Parsed with OpenCV's JSON reader.
#include <array>
#include <cmath>
#include <opencv2/core/persistence.hpp>

#include "capture/recording_sources.hpp"

namespace facescan::capture {
namespace {

// How the SDK derives a mode from the full sensor: the sensor image binned to `binned`, then `crop` pixels cut
// from the top-left corner (the SDK's mode table for the depth camera; colour modes are the 4:3 sensor scaled to
// the mode's width and cropped to its height symmetrically).
struct ModeGeometry {
    int binned_w = 0, binned_h = 0, crop_x = 0, crop_y = 0;
};

StatusOr<ModeGeometry> depthMode(int w, int h) {
    if (w == 640 && h == 576) return ModeGeometry{1024, 1024, 192, 180};  // NFOV unbinned
    if (w == 320 && h == 288) return ModeGeometry{512, 512, 96, 90};      // NFOV 2x2 binned
    if (w == 512 && h == 512) return ModeGeometry{512, 512, 0, 0};        // WFOV 2x2 binned
    if (w == 1024 && h == 1024) return ModeGeometry{1024, 1024, 0, 0};    // WFOV unbinned
    return dataLoss("depth images of " + std::to_string(w) + "x" + std::to_string(h) +
                    " are no Azure Kinect depth mode (640x576, 320x288, 512x512 or 1024x1024)");
}

struct RawCamera {
    std::array<double, 14> params{};  // cx cy fx fy k1..k6 codx cody p2 p1, normalised by the sensor size
    int sensor_w = 0, sensor_h = 0;
    Eigen::Matrix3f R = Eigen::Matrix3f::Identity();
    Eigen::Vector3f t = Eigen::Vector3f::Zero();  // metres
};

StatusOr<RawCamera> readCamera(const cv::FileNode& cam, const std::string& purpose) {
    RawCamera raw;
    const cv::FileNode model = cam["Intrinsics"]["ModelParameters"];
    const std::string type = cam["Intrinsics"]["ModelType"].isString() ? cam["Intrinsics"]["ModelType"].string() : "";
    if (type != "CALIBRATION_LensDistortionModelBrownConrady") {
        return dataLoss("the " + purpose + " camera's lens model is '" + type +
                        "', not the Brown-Conrady model of Azure Kinect and Femto recordings");
    }
    if (!model.isSeq() || model.size() < 14) return dataLoss("the " + purpose + " camera has no 14 model parameters");
    for (size_t i = 0; i < 14; ++i) {
        if (!model[static_cast<int>(i)].isReal() && !model[static_cast<int>(i)].isInt()) {
            return dataLoss("the " + purpose + " camera's model parameters are not numbers");
        }
        raw.params[i] = static_cast<double>(model[static_cast<int>(i)]);
        if (!std::isfinite(raw.params[i])) return dataLoss("the " + purpose + " camera's parameters are not finite");
    }
    if (!cam["SensorWidth"].isInt() || !cam["SensorHeight"].isInt()) {
        return dataLoss("the " + purpose + " camera has no SensorWidth/SensorHeight");
    }
    raw.sensor_w = static_cast<int>(cam["SensorWidth"]);
    raw.sensor_h = static_cast<int>(cam["SensorHeight"]);
    if (raw.sensor_w < 16 || raw.sensor_h < 16 || raw.sensor_w > 8192 || raw.sensor_h > 8192) {
        return dataLoss("the " + purpose + " camera's sensor size is implausible");
    }
    const cv::FileNode rot = cam["Rt"]["Rotation"];
    const cv::FileNode trans = cam["Rt"]["Translation"];
    if (!rot.isSeq() || rot.size() != 9 || !trans.isSeq() || trans.size() != 3) {
        return dataLoss("the " + purpose + " camera has no Rt (9 rotation and 3 translation values)");
    }
    for (int i = 0; i < 9; ++i) raw.R(i / 3, i % 3) = static_cast<float>(static_cast<double>(rot[i]));
    for (int i = 0; i < 3; ++i) raw.t[i] = static_cast<float>(static_cast<double>(trans[i]));
    if (!raw.R.allFinite() || !raw.t.allFinite()) return dataLoss("the " + purpose + " camera's Rt is not finite");
    // A rotation has orthonormal rows and determinant 1; anything else (a scale of 1e30, a mirror) would turn the
    // depth-to-colour transform into garbage or infinities. Camera rigs are centimetres apart, never kilometres.
    if ((raw.R * raw.R.transpose() - Eigen::Matrix3f::Identity()).cwiseAbs().maxCoeff() > 1e-2f ||
        raw.R.determinant() < 0.0f) {
        return dataLoss("the " + purpose + " camera's Rt rotation is not a rotation");
    }
    if (raw.t.norm() > 10.0f) return dataLoss("the " + purpose + " camera's Rt translation is over 10 m");
    return raw;
}

// The SDK's mode-specific calibration: normalised, corner-origin parameters times the binned size, minus the crop,
// minus half a pixel for OpenCV's centre-origin convention. Finite normalised parameters can still overflow a float
// pixel value (1e300 times the width), and a zero or negative focal length is no pinhole, so the result is checked.
StatusOr<AzureKinectCamera> toMode(const RawCamera& raw, const ModeGeometry& g, int w, int h,
                                   const std::string& purpose) {
    AzureKinectCamera cam;
    const auto& p = raw.params;
    cam.intrinsics.width_px = w;
    cam.intrinsics.height_px = h;
    cam.intrinsics.cx_px = static_cast<float>(p[0] * g.binned_w - g.crop_x - 0.5);
    cam.intrinsics.cy_px = static_cast<float>(p[1] * g.binned_h - g.crop_y - 0.5);
    cam.intrinsics.fx_px = static_cast<float>(p[2] * g.binned_w);
    cam.intrinsics.fy_px = static_cast<float>(p[3] * g.binned_h);
    // OpenCV's rational model (k1 k2 p1 p2 k3 k4 k5 k6); the SDK stores p2 before p1. The centre of distortion
    // (codx, cody) is zero in the Brown-Conrady calibrations the devices ship, so it is not modelled.
    cam.distortion = {p[4], p[5], p[13], p[12], p[6], p[7], p[8], p[9]};
    const auto& k = cam.intrinsics;
    if (!std::isfinite(k.cx_px) || !std::isfinite(k.cy_px) || !std::isfinite(k.fx_px) || !std::isfinite(k.fy_px) ||
        !(k.fx_px > 0.0f) || !(k.fy_px > 0.0f)) {
        return dataLoss("the " + purpose + " camera's pinhole in the " + std::to_string(w) + "x" + std::to_string(h) +
                        " mode is not usable (a focal length that is not positive, or a value out of range)");
    }
    return cam;
}

}  // namespace

StatusOr<AzureKinectCalibration> parseAzureKinectCalibration(const std::string& json, int depth_width, int depth_height,
                                                             int colour_width, int colour_height) {
    cv::FileStorage fs;
    try {
        if (!fs.open(json, cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_JSON)) {
            return dataLoss("the calibration attachment is not JSON");
        }
    } catch (const cv::Exception& e) {
        return dataLoss("the calibration attachment is not valid JSON (" + std::string(e.err) + ")");
    }
    try {
        const cv::FileNode cameras = fs["CalibrationInformation"]["Cameras"];
        if (!cameras.isSeq()) {
            return dataLoss(
                "the calibration attachment has no CalibrationInformation.Cameras: not an Azure Kinect "
                "calibration");
        }
        StatusOr<RawCamera> depth = dataLoss("the calibration attachment describes no depth camera");
        StatusOr<RawCamera> colour = dataLoss("the calibration attachment describes no colour camera");
        for (const cv::FileNode& cam : cameras) {
            const std::string purpose = cam["Purpose"].isString() ? cam["Purpose"].string() : "";
            if (purpose == "CALIBRATION_CameraPurposeDepth") depth = readCamera(cam, "depth");
            if (purpose == "CALIBRATION_CameraPurposePhotoVideo") colour = readCamera(cam, "colour");
        }
        if (!depth.isOk()) return depth.status();
        AzureKinectCalibration out;
        ASSIGN_OR_RETURN(const ModeGeometry depth_mode, depthMode(depth_width, depth_height));
        ASSIGN_OR_RETURN(out.depth, toMode(*depth, depth_mode, depth_width, depth_height, "depth"));
        out.colour.intrinsics = recon::Intrinsics{0, 0, 0.0f, 0.0f, 0.0f, 0.0f};
        out.T_colour_depth = recon::Pose::Identity();
        if (colour_width == 0 && colour_height == 0) return out;
        if (!colour.isOk()) return colour.status();
        if (colour->sensor_w * 3 != colour->sensor_h * 4) {
            return dataLoss("the colour camera's calibration is for a " + std::to_string(colour->sensor_w) + "x" +
                            std::to_string(colour->sensor_h) + " sensor, not the 4:3 sensor of Azure Kinect");
        }
        const int binned_h = colour_width * 3 / 4;
        if (colour_width < 16 || colour_height < 16 || colour_height > binned_h) {
            return dataLoss("colour images of " + std::to_string(colour_width) + "x" + std::to_string(colour_height) +
                            " are no Azure Kinect colour mode");
        }
        ASSIGN_OR_RETURN(out.colour,
                         toMode(*colour, ModeGeometry{colour_width, binned_h, 0, (binned_h - colour_height) / 2},
                                colour_width, colour_height, "colour"));
        // Each camera's Rt maps the calibration's reference frame (the depth camera) into that camera.
        recon::Pose T_depth_ref = recon::Pose::Identity(), T_colour_ref = recon::Pose::Identity();
        T_depth_ref.linear() = depth->R;
        T_depth_ref.translation() = depth->t;
        T_colour_ref.linear() = colour->R;
        T_colour_ref.translation() = colour->t;
        out.T_colour_depth = T_colour_ref * T_depth_ref.inverse();
        return out;
    } catch (const cv::Exception& e) {
        return dataLoss("the calibration attachment is not an Azure Kinect calibration (" + std::string(e.err) + ")");
    }
}

}  // namespace facescan::capture
