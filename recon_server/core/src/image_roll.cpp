#include "recon/image_roll.hpp"

#include <cmath>

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

}  // namespace

ImageRoll ImageRoll::fromDegrees(int roll_deg) {
    const int q = static_cast<int>(std::lround(static_cast<double>(roll_deg) / 90.0));
    return ImageRoll(((q % 4) + 4) % 4);
}

ImageRoll ImageRoll::fromDownDirection(const Eigen::Vector3f& down_camera, ImageRoll fallback) {
    const float x = down_camera.x(), y = down_camera.y();
    if (!(std::isfinite(x) && std::isfinite(y)) || x * x + y * y < 1e-4f * down_camera.squaredNorm()) return fallback;
    // Upright down is +y; rolled by q quarters it is R_z(90 q) (0, 1) = (-sin, cos) of 90 q.
    if (std::abs(y) >= std::abs(x)) return ImageRoll(y > 0 ? 0 : 2);
    return ImageRoll(x < 0 ? 1 : 3);
}

Eigen::Vector3f ImageRoll::downCamera() const { return turn(Eigen::Vector3f::UnitY(), quarters_); }
Eigen::Vector3f ImageRoll::toUpright(const Eigen::Vector3f& p_camera) const { return turn(p_camera, 4 - quarters_); }
Eigen::Vector3f ImageRoll::fromUpright(const Eigen::Vector3f& p_upright) const { return turn(p_upright, quarters_); }

// The scene appears turned clockwise by q quarters, so turning the image counter-clockwise by as much stands it up.
void ImageRoll::toUpright(const cv::Mat& image, cv::Mat& upright) const { rotateBy(image, upright, 4 - quarters_); }
void ImageRoll::fromUpright(const cv::Mat& upright, cv::Mat& image) const { rotateBy(upright, image, quarters_); }

Intrinsics ImageRoll::toUpright(const Intrinsics& k) const {
    // Pixels move as cv::rotate moves them; the principal point is a pixel position like any other, and a quarter
    // turn swaps the focal lengths with the axes (thesis eq. 4.8 with x, y exchanged).
    const int q = 4 - quarters_;
    Intrinsics u = k;
    const cv::Point2f c = turnPixel(k.cx_px, k.cy_px, k.width_px, k.height_px, q);
    u.cx_px = c.x;
    u.cy_px = c.y;
    if (quarters_ % 2 == 1) {
        u.width_px = k.height_px;
        u.height_px = k.width_px;
        u.fx_px = k.fy_px;
        u.fy_px = k.fx_px;
    }
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
    if (r_upright.empty() || quarters_ == 0) return r_upright;
    // The upright image's size, and its corners (pixel-edge coordinates) turned back by q quarters.
    const bool swap = quarters_ % 2 == 1;
    const int uw = swap ? size.height : size.width, uh = swap ? size.width : size.height;
    const cv::Point2f a =
        turnPixel(static_cast<float>(r_upright.x), static_cast<float>(r_upright.y), uw, uh, quarters_);
    const cv::Point2f b = turnPixel(static_cast<float>(r_upright.br().x - 1), static_cast<float>(r_upright.br().y - 1),
                                    uw, uh, quarters_);
    const int x0 = static_cast<int>(std::min(a.x, b.x)), y0 = static_cast<int>(std::min(a.y, b.y));
    const int x1 = static_cast<int>(std::max(a.x, b.x)), y1 = static_cast<int>(std::max(a.y, b.y));
    return {x0, y0, x1 - x0 + 1, y1 - y0 + 1};
}

}  // namespace facescan::recon
