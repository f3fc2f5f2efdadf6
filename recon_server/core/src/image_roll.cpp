#include "recon/image_roll.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace facescan::recon {
namespace {

// R_z(90 q) applied to (x, y): the scene turned clockwise on screen (y down) by q quarter turns.
Eigen::Vector3f turn(const Eigen::Vector3f& p, int q) {
    switch (q & 3) {
        case 1: return {-p.y(), p.x(), p.z()};
        case 2: return {-p.x(), -p.y(), p.z()};
        case 3: return {p.y(), -p.x(), p.z()};
        default: return p;
    }
}

// Pixel (u, v) of a w x h image under cv::rotate's turn of the image by q clockwise quarters.
cv::Point2f turnPixel(float u, float v, int w, int h, int q) {
    switch (q & 3) {
        case 1: return {static_cast<float>(h - 1) - v, u};
        case 2: return {static_cast<float>(w - 1) - u, static_cast<float>(h - 1) - v};
        case 3: return {v, static_cast<float>(w - 1) - u};
        default: return {u, v};
    }
}

void rotateBy(const cv::Mat& src, cv::Mat& dst, int q) {
    switch (q & 3) {
        case 1: cv::rotate(src, dst, cv::ROTATE_90_CLOCKWISE); break;
        case 2: cv::rotate(src, dst, cv::ROTATE_180); break;
        case 3: cv::rotate(src, dst, cv::ROTATE_90_COUNTERCLOCKWISE); break;
        default: src.copyTo(dst);
    }
}

constexpr double kDegToRad = M_PI / 180.0;

// R_z(deg) applied to (x, y): the scene turned clockwise on screen (y down) by deg, a multiple of kStepDeg (negative
// too); quarter turns exactly.
Eigen::Vector3f turnDegrees(const Eigen::Vector3f& p, int deg) {
    if (deg % 90 == 0) return turn(p, deg / 90);
    const double a = deg * kDegToRad;
    const float c = static_cast<float>(std::cos(a)), s = static_cast<float>(std::sin(a));
    return {c * p.x() - s * p.y(), s * p.x() + c * p.y(), p.z()};
}

// The absolute difference of two angles (degrees), in [0, 180].
float angleApartDeg(float a, float b) {
    const float d = std::fmod(std::abs(a - b), 360.0f);
    return d > 180.0f ? 360.0f - d : d;
}

// A box's corners (pixel-edge coordinates) through a pixel map (pixel-centre coordinates), bounded and clipped.
cv::Rect mapRect(const cv::Rect& r, const cv::Matx23d& m, const cv::Size& bounds) {
    if (r.empty()) return r;
    double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
    for (const double x : {static_cast<double>(r.x), static_cast<double>(r.x + r.width)}) {
        for (const double y : {static_cast<double>(r.y), static_cast<double>(r.y + r.height)}) {
            const cv::Vec3d c(x - 0.5, y - 0.5, 1.0);
            const double u = m(0, 0) * c[0] + m(0, 1) * c[1] + m(0, 2) + 0.5;
            const double v = m(1, 0) * c[0] + m(1, 1) * c[1] + m(1, 2) + 0.5;
            x0 = std::min(x0, u), y0 = std::min(y0, v), x1 = std::max(x1, u), y1 = std::max(y1, v);
        }
    }
    const int ix0 = static_cast<int>(std::floor(x0)), iy0 = static_cast<int>(std::floor(y0));
    const cv::Rect box(ix0, iy0, static_cast<int>(std::ceil(x1)) - ix0, static_cast<int>(std::ceil(y1)) - iy0);
    return box & cv::Rect(0, 0, bounds.width, bounds.height);
}

}  // namespace

ImageRoll ImageRoll::fromDegrees(int roll_deg) {
    const long steps = std::lround(static_cast<double>(roll_deg) / kStepDeg);
    return ImageRoll(static_cast<int>(((steps % kSteps) + kSteps) % kSteps) * kStepDeg);
}

ImageRoll ImageRoll::fromDownDirection(const Eigen::Vector3f& down_camera, ImageRoll fallback) {
    const float x = down_camera.x(), y = down_camera.y();
    if (!(std::isfinite(x) && std::isfinite(y)) || x * x + y * y < 1e-4f * down_camera.squaredNorm()) return fallback;
    // Upright down is +y; rolled by a it is R_z(a) (0, 1) = (-sin a, cos a).
    const float deg = static_cast<float>(std::atan2(-x, y) / kDegToRad);
    if (angleApartDeg(deg, static_cast<float>(fallback.deg_)) <= kHoldDeg) return fallback;
    return fromDegrees(static_cast<int>(std::lround(deg)));
}

Eigen::Vector3f ImageRoll::downCamera() const { return fromUpright(Eigen::Vector3f::UnitY()); }

Eigen::Vector3f ImageRoll::toUpright(const Eigen::Vector3f& p_camera) const { return turnDegrees(p_camera, -deg_); }
Eigen::Vector3f ImageRoll::fromUpright(const Eigen::Vector3f& p_upright) const { return turnDegrees(p_upright, deg_); }

cv::Size ImageRoll::uprightSize(const cv::Size& size) const {
    if (quarterTurn()) return (deg_ / 90) % 2 == 1 ? cv::Size(size.height, size.width) : size;
    const double a = deg_ * kDegToRad, c = std::abs(std::cos(a)), s = std::abs(std::sin(a));
    return {static_cast<int>(std::ceil(size.width * c + size.height * s - 1e-6)),
            static_cast<int>(std::ceil(size.width * s + size.height * c - 1e-6))};
}

cv::Matx23d ImageRoll::uprightMap(const cv::Size& size) const {
    // Pixels turn by R_z(-roll) about the image's centre onto the canvas's centre.
    const double a = deg_ * kDegToRad, c = std::cos(a), s = std::sin(a);
    const cv::Size up = uprightSize(size);
    const double cx = 0.5 * (size.width - 1), cy = 0.5 * (size.height - 1);
    const double ux = 0.5 * (up.width - 1), uy = 0.5 * (up.height - 1);
    return {c, s, ux - (c * cx + s * cy), -s, c, uy - (-s * cx + c * cy)};
}

// The scene appears turned clockwise, so turning the image counter-clockwise by as much stands it up.
void ImageRoll::toUpright(const cv::Mat& image, cv::Mat& upright) const {
    if (quarterTurn()) return rotateBy(image, upright, 4 - deg_ / 90);
    const int interpolation = image.channels() == 3 ? cv::INTER_LINEAR : cv::INTER_NEAREST;
    // Images (depth, colour) go on past the frame's border on the canvas, masks do not: a torso that leaves the
    // frame is cut by its border at the tilt's angle on the canvas, and its rows would be no wider than the head's
    // for the width criterion (eq. 3.7-3.13); upright, the border cuts it across and keeps its shoulders.
    const int border = image.type() == CV_8UC1 ? cv::BORDER_CONSTANT : cv::BORDER_REPLICATE;
    cv::warpAffine(image, upright, uprightMap(image.size()), uprightSize(image.size()), interpolation, border,
                   cv::Scalar::all(0));
}

void ImageRoll::fromUpright(const cv::Mat& upright, cv::Mat& image, const cv::Size& size) const {
    if (quarterTurn()) return rotateBy(upright, image, deg_ / 90);
    const int interpolation = upright.channels() == 3 ? cv::INTER_LINEAR : cv::INTER_NEAREST;
    cv::warpAffine(upright, image, uprightMap(size), size, interpolation | cv::WARP_INVERSE_MAP, cv::BORDER_CONSTANT,
                   cv::Scalar::all(0));
}

Intrinsics ImageRoll::toUpright(const Intrinsics& k) const {
    Intrinsics u = k;
    if (quarterTurn()) {
        // Pixels move as cv::rotate moves them; the principal point is a pixel position like any other, and a
        // quarter turn swaps the focal lengths with the axes (thesis eq. 4.8 with x, y exchanged).
        const int q = 4 - deg_ / 90;
        const cv::Point2f c = turnPixel(k.cx_px, k.cy_px, k.width_px, k.height_px, q);
        u.cx_px = c.x;
        u.cy_px = c.y;
        if ((deg_ / 90) % 2 == 1) {
            u.width_px = k.height_px;
            u.height_px = k.width_px;
            u.fx_px = k.fy_px;
            u.fy_px = k.fx_px;
        }
        return u;
    }
    const cv::Size size(k.width_px, k.height_px);
    const cv::Matx23d m = uprightMap(size);
    const cv::Size up = uprightSize(size);
    u.width_px = up.width;
    u.height_px = up.height;
    u.cx_px = static_cast<float>(m(0, 0) * k.cx_px + m(0, 1) * k.cy_px + m(0, 2));
    u.cy_px = static_cast<float>(m(1, 0) * k.cx_px + m(1, 1) * k.cy_px + m(1, 2));
    u.fx_px = u.fy_px = std::sqrt(k.fx_px * k.fy_px);
    return u;
}

ColourCamera ImageRoll::toUpright(const ColourCamera& colour) const {
    ColourCamera u = colour;
    u.intrinsics = toUpright(colour.intrinsics);
    // Both cameras roll together: T_colourU_depthU = R^-1 T_colour_depth R, R = R_z(roll).
    Pose r = Pose::Identity();
    r.linear().col(0) = fromUpright(Eigen::Vector3f::UnitX());
    r.linear().col(1) = fromUpright(Eigen::Vector3f::UnitY());
    r.linear().col(2) = Eigen::Vector3f::UnitZ();
    u.T_colour_depth = r.inverse() * colour.T_colour_depth * r;
    return u;
}

cv::Rect ImageRoll::rectFromUpright(const cv::Rect& r_upright, const cv::Size& size) const {
    if (r_upright.empty() || deg_ == 0) return r_upright;
    if (!quarterTurn()) {
        cv::Matx23d back;
        cv::invertAffineTransform(uprightMap(size), back);
        return mapRect(r_upright, back, size);
    }
    const int quarters = deg_ / 90;
    // The upright image's size, and its corners (pixel-edge coordinates) turned back by q quarters.
    const bool swap = quarters % 2 == 1;
    const int uw = swap ? size.height : size.width, uh = swap ? size.width : size.height;
    const cv::Point2f a = turnPixel(static_cast<float>(r_upright.x), static_cast<float>(r_upright.y), uw, uh, quarters);
    const cv::Point2f b =
        turnPixel(static_cast<float>(r_upright.br().x - 1), static_cast<float>(r_upright.br().y - 1), uw, uh, quarters);
    const int x0 = static_cast<int>(std::min(a.x, b.x)), y0 = static_cast<int>(std::min(a.y, b.y));
    const int x1 = static_cast<int>(std::max(a.x, b.x)), y1 = static_cast<int>(std::max(a.y, b.y));
    return {x0, y0, x1 - x0 + 1, y1 - y0 + 1};
}

cv::Rect ImageRoll::rectToUpright(const cv::Rect& r, const cv::Size& size) const {
    if (r.empty() || deg_ == 0) return r;
    if (!quarterTurn()) return mapRect(r, uprightMap(size), uprightSize(size));
    // The inverse quarter turn takes the upright image back to this one.
    return fromDegrees(-deg_).rectFromUpright(r, uprightSize(size));
}

}  // namespace facescan::recon
