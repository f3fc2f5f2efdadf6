// A camera's roll about its optical axis in quarter turns: a camera held in portrait or upside down shows the head
// turned in the image. Detection (the Viola-Jones cascade) and the head/torso split (eq. 3.7-3.13, "the torso is
// below the head") assume an upright person, so they run on the frame turned upright (cv::rotate, exact for
// quarter turns) with the intrinsics turned to match, and their results are turned back. Tracking and fusion
// need nothing: they are roll-agnostic.
//
// Convention: roll_deg is how far the scene appears turned clockwise in the image (y points down), which is the
// synthetic camera's roll= option. Camera-frame points: p_rolled = R_z(roll) p_upright.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "recon/camera.hpp"
#include "recon/face_detector.hpp"

namespace facescan::recon {

class ImageRoll {
 public:
    ImageRoll() = default;
    // Any multiple of 90 degrees (negative too); other angles round to the nearest quarter turn.
    static ImageRoll fromDegrees(int roll_deg);
    // The quarter turn nearest to the person's "down" direction seen in the camera frame (x right, y down): the
    // roll that makes it point down the image. A direction along the optical axis keeps `fallback`.
    static ImageRoll fromDownDirection(const Eigen::Vector3f& down_camera, ImageRoll fallback);

    int quarterTurns() const { return quarters_; }
    int degrees() const { return 90 * quarters_; }
    bool upright() const { return quarters_ == 0; }
    bool operator==(const ImageRoll&) const = default;

    // The person's down direction (the upright camera's +y) in this camera's frame.
    Eigen::Vector3f downCamera() const;
    // Camera-frame points between the upright view and this camera.
    Eigen::Vector3f toUpright(const Eigen::Vector3f& p_camera) const;
    Eigen::Vector3f fromUpright(const Eigen::Vector3f& p_upright) const;

    // Images: `image` as this camera sees it, turned upright, and back (any type; dst must not alias src).
    void toUpright(const cv::Mat& image, cv::Mat& upright) const;
    void fromUpright(const cv::Mat& upright, cv::Mat& image) const;
    // The intrinsics of the upright image of a camera with intrinsics k (exact: fx, fy swap and the principal
    // point moves with the pixels).
    Intrinsics toUpright(const Intrinsics& k) const;
    ColourCamera toUpright(const ColourCamera& colour) const;
    // A box in the upright image of a camera of size `size` (this camera's) back in this camera's pixels.
    cv::Rect rectFromUpright(const cv::Rect& r_upright, const cv::Size& size) const;

 private:
    explicit ImageRoll(int quarters) : quarters_(quarters) {}
    int quarters_ = 0;  // 0..3 clockwise quarter turns of the scene in the image
};

}  // namespace facescan::recon
