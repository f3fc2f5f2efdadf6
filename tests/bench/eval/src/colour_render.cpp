// The colour ruler (eval/colour_render.hpp).
#include "eval/colour_render.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace facescan::eval {
namespace {

inline float edge(const Eigen::Vector2f& a, const Eigen::Vector2f& b, const Eigen::Vector2f& p) {
    return (b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x());
}

Eigen::Vector3f sampleBilinear(const cv::Mat& img, float x, float y) {
    x = std::clamp(x, 0.0f, float(img.cols - 1));
    y = std::clamp(y, 0.0f, float(img.rows - 1));
    const int x0 = std::min(static_cast<int>(x), img.cols - 2), y0 = std::min(static_cast<int>(y), img.rows - 2);
    const float fx = x - float(x0), fy = y - float(y0);
    Eigen::Vector3f out;
    for (int c = 0; c < 3; ++c) {
        const float top = img.at<cv::Vec3b>(y0, x0)[c] * (1 - fx) + img.at<cv::Vec3b>(y0, x0 + 1)[c] * fx;
        const float bottom = img.at<cv::Vec3b>(y0 + 1, x0)[c] * (1 - fx) + img.at<cv::Vec3b>(y0 + 1, x0 + 1)[c] * fx;
        out[c] = top * (1 - fy) + bottom * fy;
    }
    return out;
}

}  // namespace

ColourRender renderColour(const ColourMesh& mesh, const recon::Pose& T_camera_mesh, const recon::Intrinsics& k) {
    ColourRender r;
    r.bgr = cv::Mat(k.height_px, k.width_px, CV_8UC3, cv::Scalar::all(0));
    r.hit = cv::Mat(k.height_px, k.width_px, CV_8U, cv::Scalar(0));
    r.point_m = cv::Mat(k.height_px, k.width_px, CV_32FC3, cv::Scalar::all(0));
    cv::Mat z(k.height_px, k.width_px, CV_32F, cv::Scalar(1e9f));
    const auto& P = *mesh.positions_m;
    std::vector<Eigen::Vector3f> pc(P.size());
    std::vector<Eigen::Vector2f> px(P.size());
    for (size_t i = 0; i < P.size(); ++i) {
        pc[i] = T_camera_mesh * P[i];
        px[i] = pc[i].z() > 0.05f ? k.project(pc[i]) : Eigen::Vector2f(-1e9f, -1e9f);
    }
    const bool textured = mesh.uv && mesh.texture_bgr && !mesh.texture_bgr->empty();
    for (const recon::Triangle& t : *mesh.triangles) {
        if (pc[t[0]].z() <= 0.05f || pc[t[1]].z() <= 0.05f || pc[t[2]].z() <= 0.05f) continue;
        const Eigen::Vector2f &a = px[t[0]], &b = px[t[1]], &c = px[t[2]];
        const float area = edge(a, b, c);
        if (!(std::abs(area) > 1e-9f)) continue;
        const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({a.x(), b.x(), c.x()}))));
        const int x1 = std::min(k.width_px - 1, static_cast<int>(std::floor(std::max({a.x(), b.x(), c.x()}))));
        const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a.y(), b.y(), c.y()}))));
        const int y1 = std::min(k.height_px - 1, static_cast<int>(std::floor(std::max({a.y(), b.y(), c.y()}))));
        const float iz[3] = {1 / pc[t[0]].z(), 1 / pc[t[1]].z(), 1 / pc[t[2]].z()};
        for (int y = y0; y <= y1; ++y) {
            for (int x = x0; x <= x1; ++x) {
                const Eigen::Vector2f p(static_cast<float>(x), static_cast<float>(y));
                float w[3] = {edge(b, c, p) / area, edge(c, a, p) / area, edge(a, b, p) / area};
                if (w[0] < 0 || w[1] < 0 || w[2] < 0) continue;
                const float inv_z = w[0] * iz[0] + w[1] * iz[1] + w[2] * iz[2];
                const float depth = 1 / inv_z;
                float& zb = z.at<float>(y, x);
                if (depth >= zb) continue;
                zb = depth;
                for (int i = 0; i < 3; ++i) w[i] = w[i] * iz[i] * depth;  // perspective-correct
                Eigen::Vector3f bgr;
                if (textured) {
                    const Eigen::Vector2f uv =
                        w[0] * (*mesh.uv)[t[0]] + w[1] * (*mesh.uv)[t[1]] + w[2] * (*mesh.uv)[t[2]];
                    bgr = sampleBilinear(*mesh.texture_bgr, uv.x() * float(mesh.texture_bgr->cols) - 0.5f,
                                         uv.y() * float(mesh.texture_bgr->rows) - 0.5f);
                } else {
                    bgr.setZero();
                    for (int i = 0; i < 3; ++i) {
                        const recon::Rgb8& rgb = (*mesh.colours_rgb)[t[i]];
                        bgr += w[i] * Eigen::Vector3f(rgb[2], rgb[1], rgb[0]);
                    }
                }
                const Eigen::Vector3f q = w[0] * P[t[0]] + w[1] * P[t[1]] + w[2] * P[t[2]];
                if (mesh.normals) {
                    const auto& N = *mesh.normals;
                    const Eigen::Vector3f p_c = T_camera_mesh * q;
                    Eigen::Vector3f n =
                        (T_camera_mesh.linear() * (w[0] * N[t[0]] + w[1] * N[t[1]] + w[2] * N[t[2]])).normalized();
                    if (n.dot(-p_c) < 0) n = -n;  // the side seen
                    const float diffuse = std::max(0.0f, n.dot((mesh.lamp_camera_m - p_c).normalized()));
                    bgr *= 0.35f + 0.75f * diffuse;
                }
                r.bgr.at<cv::Vec3b>(y, x) =
                    cv::Vec3b(cv::saturate_cast<uint8_t>(bgr[0]), cv::saturate_cast<uint8_t>(bgr[1]),
                              cv::saturate_cast<uint8_t>(bgr[2]));
                r.hit.at<uint8_t>(y, x) = 255;
                r.point_m.at<cv::Vec3f>(y, x) = cv::Vec3f(q.x(), q.y(), q.z());
            }
        }
    }
    return r;
}

double psnrDb(const cv::Mat& a_bgr, const cv::Mat& b_bgr, const cv::Mat& mask) {
    double sum = 0;
    size_t n = 0;
    for (int y = 0; y < a_bgr.rows; ++y) {
        for (int x = 0; x < a_bgr.cols; ++x) {
            if (!mask.at<uint8_t>(y, x)) continue;
            for (int c = 0; c < 3; ++c) {
                const double d = double(a_bgr.at<cv::Vec3b>(y, x)[c]) - double(b_bgr.at<cv::Vec3b>(y, x)[c]);
                sum += d * d;
            }
            n += 3;
        }
    }
    if (n == 0) return 0;
    const double mse = sum / double(n);
    return mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : 99.0;
}

double ssim(const cv::Mat& a_bgr, const cv::Mat& b_bgr, const cv::Mat& mask) {
    cv::Mat a, b;
    cv::cvtColor(a_bgr, a, cv::COLOR_BGR2GRAY);
    cv::cvtColor(b_bgr, b, cv::COLOR_BGR2GRAY);
    a.convertTo(a, CV_64F);
    b.convertTo(b, CV_64F);
    const double c1 = std::pow(0.01 * 255, 2), c2 = std::pow(0.03 * 255, 2);
    auto blur = [](const cv::Mat& m) {
        cv::Mat out;
        cv::GaussianBlur(m, out, cv::Size(11, 11), 1.5);
        return out;
    };
    const cv::Mat mu_a = blur(a), mu_b = blur(b);
    const cv::Mat aa = blur(a.mul(a)) - mu_a.mul(mu_a), bb = blur(b.mul(b)) - mu_b.mul(mu_b);
    const cv::Mat ab = blur(a.mul(b)) - mu_a.mul(mu_b);
    cv::Mat num = (2 * mu_a.mul(mu_b) + c1).mul(2 * ab + c2);
    cv::Mat den = (mu_a.mul(mu_a) + mu_b.mul(mu_b) + c1).mul(aa + bb + c2);
    cv::Mat map;
    cv::divide(num, den, map);
    return cv::mean(map, mask)[0];
}

}  // namespace facescan::eval
