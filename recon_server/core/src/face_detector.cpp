#include "recon/face_detector.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "recon/parallel.hpp"

namespace facescan::recon {
namespace {

using Clock = std::chrono::steady_clock;
float msSince(Clock::time_point t0) { return std::chrono::duration<float, std::milli>(Clock::now() - t0).count(); }

// A region of candidate window centres and the cascade settings that cover it.
struct CascadeRoi {
    cv::Rect roi_colour_px;
    int min_window_px = 0;
    int max_window_px = 0;
    float depth_near_m = 0;
    float depth_far_m = 0;
};

// Median of the valid depth inside `box` (depth pixels), or 0 when nothing is valid.
float medianDepth(const cv::Mat& depth_m, cv::Rect box, float min_m, float max_m, std::vector<float>& scratch) {
    box &= cv::Rect(0, 0, depth_m.cols, depth_m.rows);
    scratch.clear();
    for (int v = box.y; v < box.y + box.height; ++v) {
        const float* row = depth_m.ptr<float>(v);
        for (int u = box.x; u < box.x + box.width; ++u) {
            if (row[u] >= min_m && row[u] <= max_m) scratch.push_back(row[u]);
        }
    }
    if (scratch.empty()) return 0.0f;
    auto mid = scratch.begin() + static_cast<std::ptrdiff_t>(scratch.size() / 2);
    std::nth_element(scratch.begin(), mid, scratch.end());
    return *mid;
}

// Isolated dropouts (Kinect speckle, single-pixel cracks) would each be a depth "boundary" of eq. 3.2 and put a
// boundary next to every pixel. An invalid pixel with at least 4 valid 8-neighbours takes the farthest of them;
// real no-data regions (shadow bands, background) are wider than that and stay invalid.
void fillSpeckles(cv::Mat& depth_m, cv::Mat& valid_count, cv::Mat& farthest) {
    cv::Mat valid = depth_m > 0;
    cv::boxFilter(valid / 255, valid_count, CV_8U, cv::Size(3, 3), cv::Point(-1, -1), false);
    cv::dilate(depth_m, farthest, cv::Mat());
    for (int v = 0; v < depth_m.rows; ++v) {
        float* z = depth_m.ptr<float>(v);
        const uchar* n = valid_count.ptr<uchar>(v);
        const float* f = farthest.ptr<float>(v);
        for (int u = 0; u < depth_m.cols; ++u) {
            if (z[u] <= 0 && n[u] >= 4) z[u] = f[u];
        }
    }
}

class FixedMask : public cv::BaseCascadeClassifier::MaskGenerator {
 public:
    explicit FixedMask(cv::Mat mask) : mask_(std::move(mask)) {}
    cv::Mat generateMask(const cv::Mat& /*src*/) override { return mask_; }

 private:
    cv::Mat mask_;
};

}  // namespace

Status FaceDetectorParams::validate() const {
    if (!(face_width_min_m > 0 && face_width_max_m > face_width_min_m)) {
        return invalidArgument("face width range must satisfy 0 < face_width_min_m < face_width_max_m");
    }
    if (!(boundary_jump_m > 0)) return invalidArgument("boundary_jump_m must be > 0");
    if (!(min_depth_m > 0 && max_depth_m > min_depth_m)) return invalidArgument("need 0 < min_depth_m < max_depth_m");
    if (candidate_level < 0 || candidate_level > 3) return invalidArgument("candidate_level must be 0..3");
    if (!(roi_margin >= 0 && roi_margin <= 1)) return invalidArgument("roi_margin must be in [0, 1]");
    if (!(scale_factor > 1.0)) return invalidArgument("scale_factor must be > 1");
    if (min_neighbours < 0) return invalidArgument("min_neighbours must be >= 0");
    if (cascade_path.empty()) return invalidArgument("cascade_path is empty");
    return Status::ok();
}

Eigen::Vector2f ColourCamera::depthToColour(const Intrinsics& depth, float u_px, float v_px, float z_m) const {
    if (registered) return {u_px, v_px};
    return intrinsics.project(T_colour_depth * depth.backProject(u_px, v_px, z_m));
}

Eigen::Vector2f ColourCamera::colourToDepth(const Intrinsics& depth, float u_px, float v_px, float z_m) const {
    if (registered) return {u_px, v_px};
    return depth.project(T_colour_depth.inverse() * intrinsics.backProject(u_px, v_px, z_m));
}

FaceWidthRangePx faceWidthRange(float focal_px, float depth_m, const FaceDetectorParams& params) {
    if (!(depth_m > 0)) return {};
    return {focal_px * params.face_width_min_m / depth_m, focal_px * params.face_width_max_m / depth_m};
}

void depthBoundaryMap(const cv::Mat& depth_m, float jump_m, cv::Mat& boundary_u8) {
    CV_Assert(depth_m.type() == CV_32FC1);
    boundary_u8.create(depth_m.size(), CV_8UC1);
    boundary_u8.setTo(0);
    for (int v = 0; v < depth_m.rows; ++v) {
        const float* z = depth_m.ptr<float>(v);
        const float* z_up = v > 0 ? depth_m.ptr<float>(v - 1) : nullptr;
        uchar* b = boundary_u8.ptr<uchar>(v);
        uchar* b_up = v > 0 ? boundary_u8.ptr<uchar>(v - 1) : nullptr;
        for (int u = 0; u < depth_m.cols; ++u) {
            if (u > 0 && std::fabs(z[u] - z[u - 1]) > jump_m) b[u] = b[u - 1] = 255;
            if (z_up && std::fabs(z[u] - z_up[u]) > jump_m) b[u] = b_up[u] = 255;
        }
    }
}

void distanceToBoundary(const cv::Mat& boundary_u8, cv::Mat& distance_px) {
    CV_Assert(boundary_u8.type() == CV_8UC1);
    // distanceTransform measures the distance to the nearest ZERO pixel: boundaries must be 0 (eq. 3.3).
    cv::Mat seeds;
    cv::compare(boundary_u8, 0, seeds, cv::CMP_EQ);
    if (static_cast<size_t>(cv::countNonZero(seeds)) ==
        seeds.total()) {  // no boundary at all: every distance is "infinite"
        distance_px.create(boundary_u8.size(), CV_32FC1);
        distance_px.setTo(std::numeric_limits<float>::max());
        return;
    }
    cv::distanceTransform(seeds, distance_px, cv::DIST_L2, cv::DIST_MASK_3, CV_32F);
}

void faceCandidateMask(const cv::Mat& depth_m, const cv::Mat& distance_px, float focal_px,
                       const FaceDetectorParams& params, cv::Mat& mask_u8) {
    CV_Assert(depth_m.type() == CV_32FC1 && distance_px.type() == CV_32FC1 && depth_m.size() == distance_px.size());
    mask_u8.create(depth_m.size(), CV_8UC1);
    const int cols = depth_m.cols;
    const int rows = depth_m.rows;
    parallelFor(0, rows, [&](int v_lo, int v_hi) {
        for (int v = v_lo; v < v_hi; ++v) {
            const float* z = depth_m.ptr<float>(v);
            uchar* m = mask_u8.ptr<uchar>(v);
            for (int u = 0; u < cols; ++u) {
                m[u] = 0;
                if (!(z[u] >= params.min_depth_m && z[u] <= params.max_depth_m)) continue;
                const FaceWidthRangePx w = faceWidthRange(focal_px, z[u], params);  // eq. 3.1
                const float w_avg = 0.5f * (w.min_px + w.max_px);                   // eq. 3.6
                const float tolerance = w.max_px - w_avg;
                const int half = static_cast<int>(std::lround(0.5f * w_avg));
                const int left = u - half, right = u + half, top = v - half;
                // A border point outside the image cannot be judged: the window would not fit, so no face here.
                if (left < 0 || right >= cols || top < 0) continue;
                // The centre of a face lies on continuous surface: if its border points are within `tolerance`
                // of a boundary at w_avg/2, the centre itself is at least w_avg/2 - tolerance from any boundary.
                if (params.centre_clearance && distance_px.at<float>(v, u) < 0.5f * w_avg - tolerance) continue;
                if (!(distance_px.at<float>(v, left) < tolerance && distance_px.at<float>(v, right) < tolerance &&
                      distance_px.at<float>(top, u) < tolerance)) {
                    continue;
                }
                if (params.silhouette_test) {
                    // The boundaries near the three points must be the head's silhouette: beyond them, outward,
                    // lies background (no depth, or farther than the centre by more than theta_max).
                    const float z_bg = z[u] + params.boundary_jump_m;
                    const int tol = static_cast<int>(tolerance) + 1;
                    auto background = [&](int uu, int vv) {
                        const float zz = depth_m.at<float>(vv, uu);
                        return zz <= 0.0f || zz > z_bg;
                    };
                    auto rowHasBackground = [&](int from, int to) {
                        for (int x = std::max(from, 0); x <= std::min(to, cols - 1); ++x) {
                            if (background(x, v)) return true;
                        }
                        return false;
                    };
                    bool top_ok = false;
                    for (int y = std::max(top - tol, 0); y <= top + tol && y < rows && !top_ok; ++y) {
                        top_ok = background(u, y);
                    }
                    if (!top_ok || !rowHasBackground(left - tol, left + tol) ||
                        !rowHasBackground(right - tol, right + tol)) {
                        continue;
                    }
                }
                m[u] = 255;
            }
        }
    });
}

StatusOr<FaceDetector> FaceDetector::create(const FaceDetectorParams& params) {
    RETURN_IF_ERROR(params.validate());
    cv::CascadeClassifier cascade;
    if (!cascade.load(params.cascade_path) || cascade.empty()) {
        return notFound("cannot load the Viola-Jones cascade '" + params.cascade_path +
                        "' (Debian package opencv-data installs haarcascade_frontalface_default.xml)");
    }
    return FaceDetector(params, std::move(cascade));
}

std::vector<cv::Rect> FaceDetector::detectStock(const cv::Mat& grey) {
    std::vector<cv::Rect> faces;
    if (grey.empty() || grey.type() != CV_8UC1) return faces;
    cascade_.detectMultiScale(grey, faces, params_.scale_factor, params_.min_neighbours);
    return faces;
}

std::vector<cv::Rect> FaceDetector::detectWithMaskGenerator(const cv::Mat& grey, const cv::Mat& mask_u8) {
    std::vector<cv::Rect> faces;
    if (grey.empty() || grey.type() != CV_8UC1) return faces;
    cascade_.setMaskGenerator(cv::makePtr<FixedMask>(mask_u8));
    cascade_.detectMultiScale(grey, faces, params_.scale_factor, params_.min_neighbours);
    cascade_.setMaskGenerator(cv::Ptr<cv::BaseCascadeClassifier::MaskGenerator>());
    return faces;
}

StatusOr<FaceDetections> FaceDetector::detect(const cv::Mat& depth_m, const cv::Mat& colour, const Intrinsics& depth,
                                              const ColourCamera& colour_camera) {
    if (depth_m.empty()) return invalidArgument("depth image is empty");
    if (depth_m.type() != CV_32FC1) return invalidArgument("depth must be CV_32FC1 metres");
    if (depth_m.cols != depth.width_px || depth_m.rows != depth.height_px) {
        return invalidArgument("depth size differs from the depth intrinsics");
    }
    if (colour.empty()) return invalidArgument("colour image is empty");
    if (colour.type() != CV_8UC3 && colour.type() != CV_8UC1) return invalidArgument("colour must be CV_8UC3 or 8UC1");
    const Intrinsics& k_colour = colour_camera.registered ? depth : colour_camera.intrinsics;
    if (colour.cols != k_colour.width_px || colour.rows != k_colour.height_px) {
        return invalidArgument("colour size differs from the colour intrinsics");
    }

    FaceDetections out;
    const auto t0 = Clock::now();
    const int level = params_.candidate_level;
    const int step = 1 << level;
    const Intrinsics k_level = depth.scaled(level);
    if (level == 0) {
        depth_m.copyTo(depth_level_);
    } else {
        // Nearest neighbour keeps depth steps sharp (an average would smear them into ramps).
        cv::resize(depth_m, depth_level_, cv::Size(k_level.width_px, k_level.height_px), 0, 0, cv::INTER_NEAREST);
    }
    fillSpeckles(depth_level_, valid_count_, filled_);
    depthBoundaryMap(depth_level_, params_.boundary_jump_m, boundary_);         // eq. 3.2
    distanceToBoundary(boundary_, distance_);                                   // eq. 3.3-3.5
    faceCandidateMask(depth_level_, distance_, k_level.fx_px, params_, mask_);  // eq. 3.1, 3.6
    const int n_labels = cv::connectedComponentsWithStats(mask_, labels_, stats_, centroids_, 8, CV_32S);

    // The cascade's own scale ladder, exactly as detectMultiScale builds it: window = round(24 * 1.1^j).
    const cv::Size base = cascade_.getOriginalWindowSize();
    const cv::Rect colour_bounds(0, 0, colour.cols, colour.rows);
    const float f_colour = k_colour.fx_px;
    std::vector<int> windows;
    for (double factor = 1;; factor *= params_.scale_factor) {
        const int win = static_cast<int>(std::lround(base.width * factor));
        if (win > colour.cols || std::lround(base.height * factor) > colour.rows) break;
        windows.push_back(win);
    }
    // For every (candidate region, scale): the bounding box of the centres whose depth admits that window (eq. 3.1
    // with a margin for the ladder's 10% steps). Scales no centre admits are never run.
    const size_t n_scales = windows.size();
    std::vector<cv::Rect> centres(static_cast<size_t>(n_labels) * n_scales);
    const float lo = 1.0f - params_.roi_margin, hi = 1.0f + params_.roi_margin;
    for (int v = 0; v < labels_.rows; ++v) {
        const int* l = labels_.ptr<int>(v);
        const float* z = depth_level_.ptr<float>(v);
        for (int u = 0; u < labels_.cols; ++u) {
            if (l[u] == 0) continue;
            ++out.candidate_pixels;
            const float w_min = f_colour * params_.face_width_min_m / z[u] * lo;
            const float w_max = f_colour * params_.face_width_max_m / z[u] * hi;
            for (size_t j = 0; j < n_scales; ++j) {
                const float win = static_cast<float>(windows[j]);
                if (win < w_min) continue;
                if (win > w_max) break;
                cv::Rect& r = centres[static_cast<size_t>(l[u]) * n_scales + j];
                r = r.area() == 0 ? cv::Rect(u, v, 1, 1) : (r | cv::Rect(u, v, 1, 1));
            }
        }
    }
    out.candidates_ms = msSince(t0);

    // Drive the cascade one scale and one region at a time (minSize = maxSize = that window; no grouping), then
    // group all raw hits together exactly as detectMultiScale does (groupRectangles, eps 0.2).
    const auto t1 = Clock::now();
    std::vector<cv::Rect> raw, hits;
    std::vector<float> scratch;
    std::vector<cv::Rect> rois;
    for (size_t j = 0; j < n_scales; ++j) {
        const int win = windows[j];
        rois.clear();
        for (int label = 1; label < n_labels; ++label) {
            const cv::Rect c = centres[static_cast<size_t>(label) * n_scales + j];
            if (c.area() == 0) continue;
            // Centre box (level pixels) -> colour pixels at the depths this window stands for, grown by half a window.
            const float z_near = f_colour * params_.face_width_min_m / static_cast<float>(win) * lo;
            const float z_far = f_colour * params_.face_width_max_m / static_cast<float>(win) * hi;
            float cu0 = 1e9f, cv0 = 1e9f, cu1 = -1e9f, cv1 = -1e9f;
            const float u0 = static_cast<float>(c.x * step), v0 = static_cast<float>(c.y * step);
            const float u1 = static_cast<float>(c.br().x * step), v1 = static_cast<float>(c.br().y * step);
            for (float zz : {z_near, z_far}) {
                for (const auto& [u, v] : {std::pair{u0, v0}, {u1, v0}, {u0, v1}, {u1, v1}}) {
                    const Eigen::Vector2f p = colour_camera.depthToColour(depth, u, v, zz);
                    cu0 = std::min(cu0, p.x()), cv0 = std::min(cv0, p.y());
                    cu1 = std::max(cu1, p.x()), cv1 = std::max(cv1, p.y());
                }
                if (colour_camera.registered) break;
            }
            // Half a window so every window centred in the box fits, plus the slack a turned face's box has
            // against the silhouette's centre.
            const float half = (0.5f + params_.centre_slack) * static_cast<float>(win) + 1.0f;
            const cv::Rect roi =
                cv::Rect(cv::Point(static_cast<int>(cu0 - half), static_cast<int>(cv0 - half)),
                         cv::Point(static_cast<int>(cu1 + half) + 1, static_cast<int>(cv1 + half) + 1)) &
                colour_bounds;
            if (roi.width < win || roi.height < win) continue;
            // Overlapping regions of one scale share a pass.
            bool merged = false;
            for (cv::Rect& r : rois) {
                if ((r & roi).area() > 0) {
                    r |= roi;
                    merged = true;
                    break;
                }
            }
            if (!merged) rois.push_back(roi);
        }
        for (const cv::Rect& roi : rois) {
            const cv::Mat colour_roi = colour(roi);
            if (colour.channels() == 3) {
                cv::cvtColor(colour_roi, grey_, cv::COLOR_BGR2GRAY);
            } else {
                grey_ = colour_roi;
            }
            hits.clear();
            cascade_.detectMultiScale(grey_, hits, params_.scale_factor, 0, 0, cv::Size(win, win), cv::Size(win, win));
            for (const cv::Rect& hit : hits) raw.push_back(hit + roi.tl());
            ++out.rois;
        }
    }
    cv::groupRectangles(raw, params_.min_neighbours, 0.2);

    // Depth check of every grouped hit: the face's own depth must make the box a face-sized width (eq. 3.1), and
    // its centre must be near a candidate pixel (eq. 3.6). This is what removes most false positives.
    for (const cv::Rect& hit : raw) {
        auto toDepthBox = [&](float z) {
            const Eigen::Vector2f a =
                colour_camera.colourToDepth(depth, static_cast<float>(hit.x), static_cast<float>(hit.y), z);
            const Eigen::Vector2f b =
                colour_camera.colourToDepth(depth, static_cast<float>(hit.br().x), static_cast<float>(hit.br().y), z);
            return cv::Rect(cv::Point(static_cast<int>(std::lround(a.x())), static_cast<int>(std::lround(a.y()))),
                            cv::Point(static_cast<int>(std::lround(b.x())), static_cast<int>(std::lround(b.y()))));
        };
        // First guess of the depth: the one at which the box would be an average face.
        const float z_guess =
            f_colour * 0.5f * (params_.face_width_min_m + params_.face_width_max_m) / static_cast<float>(hit.width);
        cv::Rect box_depth = toDepthBox(z_guess);
        const cv::Rect core(box_depth.x + box_depth.width / 4, box_depth.y + box_depth.height / 4,
                            std::max(1, box_depth.width / 2), std::max(1, box_depth.height / 2));
        const float z_face = medianDepth(depth_m, core, params_.min_depth_m, params_.max_depth_m, scratch);
        FaceDetection face;
        bool accept = z_face > 0;
        if (accept) {
            box_depth = toDepthBox(z_face);
            face.width_m = static_cast<float>(hit.width) * z_face / f_colour;
            accept = face.width_m >= params_.face_width_min_m * lo && face.width_m <= params_.face_width_max_m * hi;
        }
        if (accept) {
            const int cu = (box_depth.x + box_depth.width / 2) >> level;
            const int cv_ = (box_depth.y + box_depth.height / 2) >> level;
            const int r =
                std::max(1, static_cast<int>(params_.centre_slack * static_cast<float>(box_depth.width)) >> level);
            const cv::Rect probe =
                cv::Rect(cu - r, cv_ - r, 2 * r + 1, 2 * r + 1) & cv::Rect(0, 0, mask_.cols, mask_.rows);
            accept = probe.area() > 0 && cv::countNonZero(mask_(probe)) > 0;
        }
        if (!accept) {
            ++out.rejected;
            continue;
        }
        face.box_colour_px = hit;
        face.box_depth_px = box_depth;
        face.depth_m = z_face;
        out.faces.push_back(face);
    }
    std::sort(out.faces.begin(), out.faces.end(),
              [](const FaceDetection& a, const FaceDetection& b) { return a.depth_m < b.depth_m; });
    out.cascade_ms = msSince(t1);
    return out;
}

}  // namespace facescan::recon
