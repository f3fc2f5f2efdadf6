// The error drawn on the model (eval/heat_map.hpp), after the thesis' Figure 5.2.
#include "eval/heat_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "eval/accuracy.hpp"

namespace facescan::eval {
namespace {

using Vec3 = Eigen::Vector3f;

// The colour of a value in [0, 1]: OpenCV's jet map (blue = no error, red = the top of the bar), as the thesis.
cv::Vec3b jet(float t) {
    static const cv::Mat lut = [] {
        cv::Mat ramp(256, 1, CV_8UC1);
        for (int i = 0; i < 256; ++i) ramp.at<uint8_t>(i) = static_cast<uint8_t>(i);
        cv::Mat colours;
        cv::applyColorMap(ramp, colours, cv::COLORMAP_JET);
        return colours;
    }();
    const int i = std::clamp(static_cast<int>(std::lround(t * 255.0f)), 0, 255);
    return lut.at<cv::Vec3b>(i);
}

struct View {
    const char* name;
    float yaw_deg;  // the head turned by this about +y before an orthographic look along -z
};

// Renders one view: per pixel, the nearest triangle's interpolated error, shaded by its facing.
void renderView(const recon::Mesh& mesh, const std::vector<float>& error_mm, const Vec3& centre, float scale_px_per_m,
                float yaw_deg, float max_error_mm, cv::Mat& image) {
    const Eigen::Matrix3f R = Eigen::AngleAxisf(yaw_deg * static_cast<float>(M_PI) / 180.0f, Vec3::UnitY()).matrix();
    const float cx = static_cast<float>(image.cols) / 2, cy = static_cast<float>(image.rows) / 2;
    cv::Mat depth(image.size(), CV_32FC1, cv::Scalar(-std::numeric_limits<float>::infinity()));
    for (const auto fh : mesh.faces()) {
        Vec3 p[3];
        float e[3];
        int k = 0;
        for (const auto vh : mesh.fv_range(fh)) {
            if (k == 3) break;
            const auto& q = mesh.point(vh);
            p[k] = R * (Vec3(q[0], q[1], q[2]) - centre);
            e[k] = error_mm[static_cast<size_t>(vh.idx())];
            ++k;
        }
        if (k != 3) continue;
        const Vec3 n = (p[1] - p[0]).cross(p[2] - p[0]);
        if (n.z() <= 0) continue;  // facing away (counter-clockwise seen from outside)
        const float shade = 0.35f + 0.65f * n.normalized().z();
        float u[3], v[3];
        for (int i = 0; i < 3; ++i) {
            u[i] = cx + p[i].x() * scale_px_per_m;
            v[i] = cy - p[i].y() * scale_px_per_m;
        }
        const int x0 = std::max(0, static_cast<int>(std::floor(std::min({u[0], u[1], u[2]}))));
        const int x1 = std::min(image.cols - 1, static_cast<int>(std::ceil(std::max({u[0], u[1], u[2]}))));
        const int y0 = std::max(0, static_cast<int>(std::floor(std::min({v[0], v[1], v[2]}))));
        const int y1 = std::min(image.rows - 1, static_cast<int>(std::ceil(std::max({v[0], v[1], v[2]}))));
        const float area = (u[1] - u[0]) * (v[2] - v[0]) - (u[2] - u[0]) * (v[1] - v[0]);
        if (std::abs(area) < 1e-12f) continue;
        for (int y = y0; y <= y1; ++y) {
            for (int x = x0; x <= x1; ++x) {
                const float px = static_cast<float>(x) + 0.5f, py = static_cast<float>(y) + 0.5f;
                const float w0 = ((u[1] - px) * (v[2] - py) - (u[2] - px) * (v[1] - py)) / area;
                const float w1 = ((u[2] - px) * (v[0] - py) - (u[0] - px) * (v[2] - py)) / area;
                const float w2 = 1.0f - w0 - w1;
                if (w0 < 0 || w1 < 0 || w2 < 0) continue;
                const float z = w0 * p[0].z() + w1 * p[1].z() + w2 * p[2].z();
                float& zb = depth.at<float>(y, x);
                if (z <= zb) continue;
                zb = z;
                cv::Vec3b colour(170, 170, 170);  // grey: not measured
                if (e[0] >= 0 && e[1] >= 0 && e[2] >= 0) {
                    colour = jet((w0 * e[0] + w1 * e[1] + w2 * e[2]) / max_error_mm);
                }
                image.at<cv::Vec3b>(y, x) =
                    cv::Vec3b(static_cast<uint8_t>(colour[0] * shade), static_cast<uint8_t>(colour[1] * shade),
                              static_cast<uint8_t>(colour[2] * shade));
            }
        }
    }
}

void drawColourBar(cv::Mat& image, cv::Rect bar, float max_error_mm) {
    for (int y = 0; y < bar.height; ++y) {
        const float t = 1.0f - static_cast<float>(y) / static_cast<float>(bar.height - 1);
        cv::line(image, {bar.x, bar.y + y}, {bar.x + bar.width - 1, bar.y + y}, cv::Scalar(jet(t)));
    }
    cv::rectangle(image, bar, cv::Scalar(0, 0, 0), 1);
    constexpr int kTicks = 5;
    for (int i = 0; i < kTicks; ++i) {
        const float t = static_cast<float>(i) / (kTicks - 1);
        const int y = bar.y + bar.height - 1 - static_cast<int>(std::lround(t * static_cast<float>(bar.height - 1)));
        cv::line(image, {bar.x + bar.width, y}, {bar.x + bar.width + 6, y}, cv::Scalar(0, 0, 0), 1);
        char label[32];
        std::snprintf(label, sizeof label, i == kTicks - 1 ? ">= %.2f mm" : "%.2f mm",
                      static_cast<double>(t * max_error_mm));
        cv::putText(image, label, {bar.x + bar.width + 10, y + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0),
                    1, cv::LINE_AA);
    }
}

}  // namespace

Status HeatMapParams::validate() const {
    if (!(max_error_mm >= 0 && max_error_mm <= 1000)) return invalidArgument("--heat-max-mm must be in [0, 1000] mm");
    if (!(region_radius_m > 0)) return invalidArgument("the heat map's region radius must be > 0 m");
    if (view_width_px < 64 || view_height_px < 64 || view_width_px > 4096 || view_height_px > 4096) {
        return invalidArgument("heat map views must be 64..4096 pixels wide and high");
    }
    return Status::ok();
}

std::vector<float> vertexErrorsMm(const recon::Mesh& mesh_in_gt, const recon::Mesh& gt) {
    const SurfaceDistance dist(gt);
    std::vector<float> out(mesh_in_gt.n_vertices(), -1.0f);
    cv::parallel_for_(cv::Range(0, static_cast<int>(out.size())), [&](const cv::Range& range) {
        for (int i = range.start; i < range.end; ++i) {
            const recon::Mesh::VertexHandle vh(i);
            const auto& q = mesh_in_gt.point(vh);
            const auto& n = mesh_in_gt.normal(vh);
            out[static_cast<size_t>(i)] = 1e3f * dist.query(Vec3(q[0], q[1], q[2]), Vec3(n[0], n[1], n[2])).distance_m;
        }
    });
    return out;
}

StatusOr<cv::Mat> renderErrorHeatMap(const recon::Mesh& mesh, const std::vector<float>& error_mm,
                                     const Eigen::Vector3f& nose_tip, const HeatMapParams& params) {
    RETURN_IF_ERROR(params.validate());
    if (mesh.n_faces() == 0) return invalidArgument("the heat map needs a mesh with triangles");
    if (error_mm.size() != mesh.n_vertices()) {
        return invalidArgument("the heat map needs one error per vertex (" + std::to_string(mesh.n_vertices()) +
                               "), got " + std::to_string(error_mm.size()));
    }
    // Vertices outside the face region are not measured: grey.
    std::vector<float> shown = error_mm;
    std::vector<float> measured;
    for (const auto vh : mesh.vertices()) {
        const auto& q = mesh.point(vh);
        float& e = shown[static_cast<size_t>(vh.idx())];
        if ((Vec3(q[0], q[1], q[2]) - nose_tip).norm() > params.region_radius_m || !std::isfinite(e)) e = -1;
        if (e >= 0) measured.push_back(e);
    }
    float max_error_mm = params.max_error_mm;
    if (max_error_mm <= 0) {
        max_error_mm = 1.0f;
        if (!measured.empty()) {
            const size_t k = std::min(measured.size() - 1, measured.size() * 99 / 100);
            std::nth_element(measured.begin(), measured.begin() + static_cast<long>(k), measured.end());
            max_error_mm = std::max(0.5f, std::ceil(measured[k] * 2.0f) / 2.0f);
        }
    }
    // One scale for the three views: the head within the region around the nose fills a view's height.
    const Vec3 centre = nose_tip - Vec3(0, 0, 0.09f);  // about the middle of the head, behind the nose
    const float scale = static_cast<float>(params.view_height_px) * 0.9f / (2.0f * params.region_radius_m + 0.02f);
    const View views[3] = {{"front", 0.0f}, {"subject's left", -90.0f}, {"subject's right", 90.0f}};
    constexpr int kTitle = 40, kBar = 170;
    cv::Mat out(params.view_height_px + kTitle + 30, 3 * params.view_width_px + kBar, CV_8UC3,
                cv::Scalar(255, 255, 255));
    for (int i = 0; i < 3; ++i) {
        cv::Mat view = out(cv::Rect(i * params.view_width_px, kTitle, params.view_width_px, params.view_height_px));
        renderView(mesh, shown, centre, scale, views[i].yaw_deg, max_error_mm, view);
        cv::putText(out, views[i].name, {i * params.view_width_px + 10, kTitle + params.view_height_px + 20},
                    cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    }
    cv::putText(out, params.title, {10, 26}, cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    const int bar_x = 3 * params.view_width_px + 20;
    cv::putText(out, "error (mm)", {bar_x - 5, kTitle + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1,
                cv::LINE_AA);
    drawColourBar(out, cv::Rect(bar_x, kTitle + 35, 28, params.view_height_px - 90), max_error_mm);
    cv::putText(out, "grey: not measured", {bar_x - 5, kTitle + params.view_height_px - 25}, cv::FONT_HERSHEY_SIMPLEX,
                0.4, cv::Scalar(90, 90, 90), 1, cv::LINE_AA);
    return out;
}

}  // namespace facescan::eval
