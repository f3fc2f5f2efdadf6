// Depth-accelerated Viola-Jones face detection (thesis section 3.1.1, eq. 3.1-3.6).
//
// Depth tells us, at every pixel, how wide a face centred there would be (eq. 3.1) and whether the borders of
// such a window lie on depth discontinuities (eq. 3.2-3.6). Only windows that pass both tests reach the stock
// OpenCV cascade. OpenCV's own hook for this, BaseCascadeClassifier::MaskGenerator, is dead in OpenCV 4.x's CPU
// path (the invoker stores the mask and never reads it; an all-zero mask still returns every face, measured by
// `facescan-bench detect`), and it would not restrict scales anyway. So the cascade is driven per candidate
// region instead: detectMultiScale on the region's ROI only, with minSize/maxSize from the region's depth band.
// The integral images, the scale pyramid and the window scan then cover a few percent of the frame.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/objdetect.hpp>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/status.hpp"

namespace facescan::recon {

struct FaceDetectorParams {
    // W_min / W_max of eq. 3.1: the physical width of a Viola-Jones face box (not of the head). The default
    // cascade's box spans brow to chin and cheek to cheek: 0.173 m on the Biwi subject at 0.85 m (105 px at
    // f = 517.7 px). 0.13-0.23 m is that +-30%: small adults to large ones, plus the box's jitter between scales.
    // The lower bound matters most for speed: the smallest windows are the most numerous.
    float face_width_min_m = 0.13f;  // metres
    float face_width_max_m = 0.23f;  // metres
    // theta_max of eq. 3.2. A face is found against its background (a wall, a chair back: > 0.3 m behind); 0.10 m
    // keeps that edge and drops the smaller steps inside a body (arm in front of torso, chin over neck).
    float boundary_jump_m = 0.10f;  // metres
    // The sensor's range (metres): nothing closer is measured reliably, farther depth is ignored. A Kinect v1's
    // here; adaptToSensor (recon/sensor_adapt.hpp) sets the camera's own.
    float min_depth_m = 0.4f;  // metres
    float max_depth_m = 4.0f;  // metres
    // The candidate mask (eq. 3.2-3.6) is computed on every 2^level-th depth pixel: faces are >= 30 px wide at
    // 4 m, so level 1 loses nothing and quarters the cost.
    int candidate_level = 1;
    // Extra test beside eq. 3.6: the window centre must be at least w_avg/2 - (w_max - w_avg) from any boundary
    // (implied by the thesis' own geometry for a face on continuous surface; removes torso pixels near folds).
    bool centre_clearance = true;
    // Extra test beside eq. 3.6: the boundary near each border point must have background beyond it (no depth, or
    // farther than the centre by > theta_max). A head is the front-most surface at its silhouette; arm/torso folds
    // are not (they have nearer surface on one side), so the torso stops passing as a face.
    bool silhouette_test = true;
    // A window is tried at a centre whose eq. 3.1 range, widened by this fraction, contains it: the cascade's
    // ladder steps 10%, and the box jitters by as much. (ratio)
    float roi_margin = 0.10f;
    // A window is tried when its centre is within this fraction of its width of a candidate pixel: a face turned
    // by 25 deg has its box centre ~0.1 box widths off the silhouette's centre line. (ratio)
    float centre_slack = 0.15f;
    double scale_factor = 1.1;  // cascade pyramid step, identical to the stock baseline (ratio)
    int min_neighbours = 3;     // cascade grouping, identical to the stock baseline (count)
    std::string cascade_path = FACESCAN_HAAR_FRONTAL_DEFAULT;  // haarcascade_frontalface_default.xml

    Status validate() const;
};

// Where the colour camera is relative to the depth camera. Registered colour (OpenNI2 registration, synthetic
// frames) shares the depth pixel grid; otherwise (Biwi) colour pixels come from the extrinsics.
struct ColourCamera {
    Intrinsics intrinsics;                   // colour camera
    Pose T_colour_depth = Pose::Identity();  // maps depth-camera points (metres) into the colour camera
    bool registered = true;                  // colour pixel (u, v) is depth pixel (u, v)

    static ColourCamera registeredTo(const Intrinsics& depth) { return {depth, Pose::Identity(), true}; }
    // Colour pixel of depth pixel (u, v) at depth z (thesis eq. 4.9, then 4.8 in the colour camera).
    Eigen::Vector2f depthToColour(const Intrinsics& depth, float u_px, float v_px, float z_m) const;
    // Depth pixel of colour pixel (u, v), assuming the point lies at depth z_m in the colour camera.
    Eigen::Vector2f colourToDepth(const Intrinsics& depth, float u_px, float v_px, float z_m) const;
};

// Eq. 3.1: window widths (pixels) of a face at depth z for focal length f.
struct FaceWidthRangePx {
    float min_px = 0;
    float max_px = 0;
};
FaceWidthRangePx faceWidthRange(float focal_px, float depth_m, const FaceDetectorParams& params);

// Eq. 3.2: boundary_u8(i, j) = 255 where |Z(i,j) - Z(k,l)| > jump for (k, l) the left or upper neighbour; both
// pixels of a step are marked. Invalid depth (0) is a value like any other, so object/no-data edges are boundaries.
void depthBoundaryMap(const cv::Mat& depth_m, float jump_m, cv::Mat& boundary_u8);

// Eq. 3.3-3.5: distance (pixels, CV_32F) from each pixel to the nearest boundary pixel by the two-pass 3x3
// chamfer transform. This is cv::distanceTransform(DIST_L2, DIST_MASK_3): the same forward (N1) and backward
// (N2) passes over the same neighbourhoods; OpenCV's weights are Borgefors' 0.955/1.3693 instead of the thesis'
// 1/sqrt(2), which halves the worst-case error against true Euclidean distance (4.5% vs 8%).
void distanceToBoundary(const cv::Mat& boundary_u8, cv::Mat& distance_px);

// Eq. 3.6: 255 where a face centred at the pixel has the three border points of its mean window (left, right, top
// at w_avg/2) within w_max - w_avg of a depth boundary.
void faceCandidateMask(const cv::Mat& depth_m, const cv::Mat& distance_px, float focal_px,
                       const FaceDetectorParams& params, cv::Mat& mask_u8);

struct FaceDetection {
    cv::Rect box_colour_px;  // the cascade's box in the colour image
    cv::Rect box_depth_px;   // the same face in depth pixels
    float depth_m = 0;       // median depth over the face (metres)
    float width_m = 0;       // the box's physical width (metres)
};

struct FaceDetections {
    std::vector<FaceDetection> faces;  // accepted faces, nearest first
    int rejected = 0;                  // cascade hits removed because their size or position disagrees with depth
    int rois = 0;                      // candidate regions given to the cascade
    int candidate_pixels = 0;          // pixels of the eq. 3.6 mask (at candidate_level)
    float candidates_ms = 0;           // eq. 3.1-3.6
    float cascade_ms = 0;              // Viola-Jones on the ROIs
};

class FaceDetector {
 public:
    static StatusOr<FaceDetector> create(const FaceDetectorParams& params);

    // depth_m: CV_32FC1 metres (0 invalid) with intrinsics `depth`; colour: CV_8UC3 BGR or CV_8UC1 grey.
    StatusOr<FaceDetections> detect(const cv::Mat& depth_m, const cv::Mat& colour, const Intrinsics& depth,
                                    const ColourCamera& colour_camera);

    // The stock baseline: detectMultiScale over the whole grey image with the same cascade and settings.
    std::vector<cv::Rect> detectStock(const cv::Mat& grey);
    // The MaskGenerator hook with `mask_u8` (grey-image sized); kept to measure it against detect().
    std::vector<cv::Rect> detectWithMaskGenerator(const cv::Mat& grey, const cv::Mat& mask_u8);

    const FaceDetectorParams& params() const { return params_; }
    const cv::Mat& candidateMask() const { return mask_; }  // last detect()'s eq. 3.6 mask (candidate_level)

 private:
    FaceDetector(const FaceDetectorParams& params, cv::CascadeClassifier cascade)
        : params_(params), cascade_(std::move(cascade)) {}

    FaceDetectorParams params_;
    cv::CascadeClassifier cascade_;
    // Scratch reused between frames: no allocation after the first frame of a given size.
    cv::Mat depth_level_, valid_count_, filled_, boundary_, distance_, mask_, labels_, stats_, centroids_, grey_;
};

}  // namespace facescan::recon
