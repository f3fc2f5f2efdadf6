// A camera's roll about its optical axis: a camera held in portrait, upside down or tilted shows the head turned in
// the image. Detection (the Viola-Jones cascade) and the head/torso split (eq. 3.7-3.13, "the torso is below the
// head") assume an upright person, so they run on the frame turned upright with the intrinsics turned to match, and
// their results are turned back. Tracking and fusion need nothing: they are roll-agnostic.
//
// Quarter turns are exact (cv::rotate). A tilt between them (steps of kStepDeg) turns the image about its centre
// onto a canvas that holds all of it (cv::warpAffine: nearest neighbour for depth and masks, so no depth is mixed
// across an edge; bilinear for colour). Turning an image about any point is a roll of the camera about its optical
// axis when the pixels are square (eq. 4.8: p - c = f (x, y) / z), so the canvas's intrinsics are the camera's
// with the principal point turned with the pixels and one focal length, the geometric mean of fx and fy.
//
// Convention: degrees() is how far the scene appears turned clockwise in the image (y points down), which is the
// synthetic camera's roll= option. Camera-frame points: p_rolled = R_z(roll) p_upright.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "recon/camera.hpp"
#include "recon/face_detector.hpp"
#include "recon/sensor.hpp"

namespace facescan::recon {

class ImageRoll {
 public:
    // Tilts are handled in steps of this many degrees: the cascade finds faces up to about half a step either way.
    static constexpr int kStepDeg = kRollStepDeg;
    static constexpr int kSteps = 360 / kStepDeg;

    ImageRoll() = default;
    // Any angle (negative too), rounded to the nearest step.
    static ImageRoll fromDegrees(int roll_deg);
    // The roll that makes the person's "down" direction seen in the camera frame (x right, y down) point down the
    // image: the nearest step, but `fallback` while it lies within kHoldDeg of the direction, so that a roll near
    // half a step does not flicker between two. A direction along the optical axis keeps `fallback`. Steps finer
    // than quarter turns matter beyond the cascade: the head region's chin plane lies across the person's down,
    // and 15 degrees off it across a 15 cm head lets 4 cm of neck into the model on one side.
    static ImageRoll fromDownDirection(const Eigen::Vector3f& down_camera, ImageRoll fallback);
    static constexpr float kHoldDeg = 0.75f * kStepDeg;

    int degrees() const { return deg_; }
    int index() const { return deg_ / kStepDeg; }  // 0 .. kSteps - 1
    bool upright() const { return deg_ == 0; }
    bool quarterTurn() const { return deg_ % 90 == 0; }
    bool operator==(const ImageRoll&) const = default;

    // The person's down direction (the upright camera's +y) in this camera's frame.
    Eigen::Vector3f downCamera() const;
    // Camera-frame points between the upright view and this camera.
    Eigen::Vector3f toUpright(const Eigen::Vector3f& p_camera) const;
    Eigen::Vector3f fromUpright(const Eigen::Vector3f& p_upright) const;

    // The size of the upright image of an image of `size` (this camera's).
    cv::Size uprightSize(const cv::Size& size) const;
    // Images: `image` as this camera sees it, turned upright, and an upright image back to this camera's `size`
    // (any type; dst must not alias src; 3-channel images are interpolated, others take the nearest pixel).
    void toUpright(const cv::Mat& image, cv::Mat& upright) const;
    void fromUpright(const cv::Mat& upright, cv::Mat& image, const cv::Size& size) const;
    // The intrinsics of the upright image of a camera with intrinsics k (exact for quarter turns: fx, fy swap and
    // the principal point moves with the pixels).
    Intrinsics toUpright(const Intrinsics& k) const;
    ColourCamera toUpright(const ColourCamera& colour) const;
    // Boxes between this camera's image of `size` and its upright image: the bounding box of the turned box,
    // clipped to the target image (exact for quarter turns).
    cv::Rect rectFromUpright(const cv::Rect& r_upright, const cv::Size& size) const;
    cv::Rect rectToUpright(const cv::Rect& r, const cv::Size& size) const;

 private:
    explicit ImageRoll(int deg) : deg_(deg) {}
    // The tilt's map from this camera's pixels to the upright canvas (2x3, for cv::warpAffine).
    cv::Matx23d uprightMap(const cv::Size& size) const;
    int deg_ = 0;  // 0 .. 345, a multiple of kStepDeg: the scene's clockwise turn in the image
};

}  // namespace facescan::recon
