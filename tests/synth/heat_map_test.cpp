// The error drawn on the model (eval/heat_map.hpp) against known answers: the head moved 1 mm out along its normals
// reads 1 mm everywhere on the face, so the face's pixels carry the bar's colour for 1 mm; an unmoved head reads 0;
// grey outside the measured region; bad input is refused.
#include "eval/heat_map.hpp"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "eval/accuracy.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::eval {
namespace {

const synth::HeadModel& head() {
    static const synth::HeadModel h = synth::builtinHead();
    return h;
}

// The jet colour of t in [0, 1], as the heat map's bar draws it.
cv::Vec3b jetOf(float t) {
    cv::Mat one(1, 1, CV_8UC1, cv::Scalar(static_cast<int>(std::lround(t * 255))));
    cv::Mat colour;
    cv::applyColorMap(one, colour, cv::COLORMAP_JET);
    return colour.at<cv::Vec3b>(0, 0);
}

// The hue of a BGR pixel (shading scales a colour, the hue stays).
float hueOf(const cv::Vec3b& bgr) {
    cv::Mat px(1, 1, CV_8UC3, cv::Scalar(bgr[0], bgr[1], bgr[2])), hsv;
    cv::cvtColor(px, hsv, cv::COLOR_BGR2HSV_FULL);
    return hsv.at<cv::Vec3b>(0, 0)[0];
}

// The front view's pixels at the nose tip's height, around the centre column (the cheek beside the nose).
cv::Vec3b frontPixel(const cv::Mat& image, const HeatMapParams& p, int dx, int dy) {
    return image.at<cv::Vec3b>(40 + p.view_height_px / 2 + dy, p.view_width_px / 2 + dx);
}

TEST(HeatMap, OneMillimetreOutReadsOneMillimetreOnTheFace) {
    const recon::Mesh moved = offsetAlongNormals(head().mesh, 1e-3f);
    const std::vector<float> errors = vertexErrorsMm(moved, head().mesh);
    ASSERT_EQ(errors.size(), moved.n_vertices());
    int near_one = 0, measured = 0;
    for (const float e : errors) {
        measured += e >= 0;
        near_one += std::abs(e - 1.0f) < 0.05f;
    }
    EXPECT_GT(near_one, measured * 9 / 10);
    HeatMapParams p;
    p.max_error_mm = 2.0f;  // 1 mm is the middle of the bar: jet's green
    auto image = renderErrorHeatMap(moved, errors, head().nose_tip_head, p);
    ASSERT_TRUE(image.isOk()) << image.status().toString();
    const float want = hueOf(jetOf(0.5f));
    int checked = 0;
    for (const int dx : {-60, -40, 40, 60}) {
        const cv::Vec3b px = frontPixel(*image, p, dx, -20);
        if (px == cv::Vec3b(255, 255, 255)) continue;  // background
        EXPECT_NEAR(hueOf(px), want, 8) << "dx " << dx;
        ++checked;
    }
    EXPECT_GE(checked, 3);
    // Unmoved: the bottom of the bar (jet's blue) there instead.
    const recon::Mesh& same = head().mesh;
    auto zero = renderErrorHeatMap(same, vertexErrorsMm(same, head().mesh), head().nose_tip_head, p);
    ASSERT_TRUE(zero.isOk());
    EXPECT_NEAR(hueOf(frontPixel(*zero, p, -50, -20)), hueOf(jetOf(0.0f)), 8);
    // Outside the region around the nose tip: grey (equal channels).
    HeatMapParams small = p;
    small.region_radius_m = 0.01f;
    auto grey = renderErrorHeatMap(moved, errors, head().nose_tip_head, small);
    ASSERT_TRUE(grey.isOk());
    const cv::Vec3b g = frontPixel(*grey, small, -60, -20);
    EXPECT_EQ(g[0], g[1]);
    EXPECT_EQ(g[1], g[2]);
}

TEST(HeatMap, BadInputIsRefused) {
    const std::vector<float> too_few(10, 0.0f);
    EXPECT_EQ(renderErrorHeatMap(head().mesh, too_few, head().nose_tip_head).status().code(),
              StatusCode::kInvalidArgument);
    EXPECT_FALSE(renderErrorHeatMap(recon::Mesh{}, {}, head().nose_tip_head).isOk());
    HeatMapParams p;
    p.max_error_mm = -1;
    const std::vector<float> errors(head().mesh.n_vertices(), 0.0f);
    EXPECT_FALSE(renderErrorHeatMap(head().mesh, errors, head().nose_tip_head, p).isOk());
}

}  // namespace
}  // namespace facescan::eval
