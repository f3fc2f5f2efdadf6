#include "recon/face_pipeline.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <vector>

namespace facescan::recon {
namespace {

using Clock = std::chrono::steady_clock;
float msSince(Clock::time_point t0) { return std::chrono::duration<float, std::milli>(Clock::now() - t0).count(); }

// The observation of a segmentation (masks shared, not copied).
void adopt(const HeadSegmentation& seg, HeadObservation& obs) {
    obs.found = seg.found;
    obs.mask = seg.mask;
    obs.depth_m = seg.depth_m;
    obs.mask_box = seg.written_px;
    obs.centroid_m = seg.centroid_m;
    obs.extent_m = seg.extent_m;
    if (!seg.found) obs.reason = seg.reason;
}

// The roll that puts the body below the head, from depth alone: a person seen from the front leaves the image
// through the side their torso is on (the head is the part that ends inside it). The near surface (within
// body_depth_m of the nearest depth) is counted along each image border; the border with the most gives the quarter
// turn. Upright when no border holds enough of it (no torso in view). A tilted camera is seen in where the body
// leaves: the direction from the crown (below) to the mean of the border samples on that side and the two beside it
// (not the opposite one, which a head close to the camera may touch) is the person's down: a wide image tilted by
// 60 degrees still has most of the torso on its bottom border.
ImageRoll rollFromBody(const cv::Mat& depth_m, float min_m, float max_m, ImageRoll fallback) {
    constexpr int kStep = 4;              // every 4th pixel
    constexpr float kBodyDepthM = 0.5f;   // metres behind the nearest surface that still belong to the person
    constexpr int kMinBorderSamples = 8;  // border samples needed to call a side "down"
    std::vector<float> near;
    for (int v = 0; v < depth_m.rows; v += kStep) {
        const float* row = depth_m.ptr<float>(v);
        for (int u = 0; u < depth_m.cols; u += kStep) {
            if (row[u] >= min_m && row[u] <= max_m) near.push_back(row[u]);
        }
    }
    if (near.size() < 20) return fallback;
    auto pct = near.begin() + static_cast<std::ptrdiff_t>(near.size() / 50);  // 2nd percentile: not a stray pixel
    std::nth_element(near.begin(), pct, near.end());
    const float limit = *pct + kBodyDepthM;
    const auto body = [&](int u, int v) {
        const float z = depth_m.ptr<float>(v)[u];
        return z >= min_m && z <= limit;
    };
    // Border samples on the person, per side (bottom, left, top, right: the person's down at 0, 90, 180, 270).
    struct Side {
        int n = 0;
        double sum_u = 0, sum_v = 0;
        void add(int u, int v) { ++n, sum_u += u, sum_v += v; }
    };
    std::array<Side, 4> side;
    const int last_row = depth_m.rows - 1, last_col = depth_m.cols - 1;
    for (int u = 0; u < depth_m.cols; u += kStep) {
        if (body(u, last_row)) side[0].add(u, last_row);
        if (body(u, 0)) side[2].add(u, 0);
    }
    for (int v = 0; v < depth_m.rows; v += kStep) {
        if (body(0, v)) side[1].add(0, v);
        if (body(last_col, v)) side[3].add(last_col, v);
    }
    int down = 0;
    for (int s = 1; s < 4; ++s) {
        if (side[s].n > side[down].n) down = s;
    }
    if (side[down].n < kMinBorderSamples) return fallback;
    const ImageRoll quarter = ImageRoll::fromDegrees(90 * down);
    Side exit;
    for (const int s : {down, (down + 1) % 4, (down + 3) % 4}) {
        exit.n += side[s].n, exit.sum_u += side[s].sum_u, exit.sum_v += side[s].sum_v;
    }
    const float exit_u = static_cast<float>(exit.sum_u / exit.n), exit_v = static_cast<float>(exit.sum_v / exit.n);
    // The crown: the seventh of the person's samples farthest from where the body leaves the image. It lies on the
    // person's axis (a head is symmetric about it) where the centroid of all samples does not: the image's border
    // cuts the shoulders unevenly once the camera is tilted (30 degrees read as 21 from the centroid).
    std::vector<std::pair<float, cv::Point>> far;  // distance from the exit (pixels), sample
    far.reserve(near.size());
    for (int v = 0; v < depth_m.rows; v += kStep) {
        for (int u = 0; u < depth_m.cols; u += kStep) {
            if (body(u, v)) far.emplace_back(std::hypot(u - exit_u, v - exit_v), cv::Point(u, v));
        }
    }
    const size_t crown_n = std::max<size_t>(1, far.size() / 7);
    std::nth_element(far.begin(), far.begin() + static_cast<std::ptrdiff_t>(crown_n - 1), far.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    double crown_u = 0, crown_v = 0;
    for (size_t i = 0; i < crown_n; ++i) crown_u += far[i].second.x, crown_v += far[i].second.y;
    const Eigen::Vector3f to_exit(exit_u - static_cast<float>(crown_u / crown_n),
                                  exit_v - static_cast<float>(crown_v / crown_n), 0.0f);
    return ImageRoll::fromDownDirection(to_exit, quarter);
}

}  // namespace

Status FacePipelineParams::validate() const {
    RETURN_IF_ERROR(detector.validate());
    RETURN_IF_ERROR(segmenter.validate());
    RETURN_IF_ERROR(finder.validate());
    RETURN_IF_ERROR(model.validate());
    if (redetect_every_frames < 0) return invalidArgument("redetect_every_frames must be >= 0");
    if (roll_deg != kRollAuto && !isRollStepDeg(roll_deg)) {
        return invalidArgument("roll_deg must be auto or 0 to 345 degrees in steps of " + std::to_string(kRollStepDeg) +
                               ", got " + std::to_string(roll_deg));
    }
    if (roll_recheck_misses < 0) return invalidArgument("roll_recheck_misses must be >= 0");
    return Status::ok();
}

StatusOr<int> parseRoll(const std::string& text) {
    if (text == "auto") return FacePipelineParams::kRollAuto;
    // Plain decimal degrees only ("030" or "+30" would pass a looser parse and mean the same; they are refused so
    // that a config value reads as it is used).
    int deg = -1;
    if (!text.empty() && text.size() <= 3 && text.find_first_not_of("0123456789") == std::string::npos &&
        (text.size() == 1 || text[0] != '0')) {
        deg = std::stoi(text);
    }
    if (isRollStepDeg(deg)) return deg;
    return invalidArgument("roll '" + text + "' must be auto or 0 to 345 degrees in steps of " +
                           std::to_string(kRollStepDeg) +
                           ": how far the person appears turned clockwise in the image (a phone held in portrait: "
                           "90 or 270, upside down: 180, at a slant: the nearest step, e.g. 30)");
}

StatusOr<FacePipeline> FacePipeline::create(const FacePipelineParams& params, const Intrinsics& depth,
                                            const ColourCamera& colour) {
    RETURN_IF_ERROR(params.validate());
    if (!depth.valid()) return invalidArgument("invalid depth intrinsics");
    if (!colour.registered && !colour.intrinsics.valid()) return invalidArgument("invalid colour intrinsics");
    ASSIGN_OR_RETURN(FaceDetector detector, FaceDetector::create(params.detector));
    return FacePipeline(params, depth, colour, std::move(detector));
}

const FacePipeline::UprightFrame& FacePipeline::upright(ImageRoll roll, const cv::Mat& depth, const cv::Mat* colour) {
    UprightFrame& f = upright_[static_cast<size_t>(roll.index())];
    f.roll = roll;
    if (!f.have_depth) {
        roll.toUpright(depth, f.depth_m);
        f.k = roll.toUpright(depth_);
        f.colour_camera = roll.toUpright(colour_);
        if (colour_.registered) f.colour_camera.intrinsics = f.k;
        f.have_depth = true;
    }
    if (colour && !f.have_colour) {
        roll.toUpright(*colour, f.colour);
        f.have_colour = true;
    }
    return f;
}

void FacePipeline::turnBack(ImageRoll roll, const HeadSegmentation& up, const cv::Mat& depth, HeadSegmentation& out) {
    out.found = up.found;
    out.reason = up.reason;
    const cv::Size size = depth.size();
    roll.fromUpright(up.mask, out.mask, size);
    if (roll.quarterTurn()) {
        roll.fromUpright(up.depth_m, out.depth_m, size);
        // What the upright pass wrote, turned back; the whole frame when that is unknown (cv::rotate wrote it all).
        out.written_px = up.written_px.empty() ? cv::Rect() : roll.rectFromUpright(up.written_px, size);
    } else {
        // A tilt resamples: a pixel of this frame takes the nearest upright pixel's verdict, which at the head's
        // silhouette may be a head pixel beside this background one. Only pixels whose own depth continues the
        // upright head's there (within the growth's step, Algorithm 1) are head, and they keep their own depth.
        roll.fromUpright(up.depth_m, tilt_depth_, size);
        cv::absdiff(depth, tilt_depth_, tilt_diff_);
        out.mask &= (tilt_depth_ > 0.0f) & (tilt_diff_ <= params_.model.grow_jump_m);
        out.depth_m.create(size, CV_32FC1);
        out.depth_m.setTo(0.0f);
        depth.copyTo(out.depth_m, out.mask);
        out.written_px = cv::Rect(0, 0, size.width, size.height);
    }
    out.head_box_px = roll.rectFromUpright(up.head_box_px, size);
    out.centroid_m = roll.fromUpright(up.centroid_m);
    out.extent_m = up.extent_m;  // width and height as the person stands
    out.depth_median_m = up.depth_median_m;
    out.pixels = roll.quarterTurn() ? up.pixels : cv::countNonZero(out.mask);
    out.split_row = -1;  // a row of the upright image, not of this one
    // The tilted canvas repeats the frame's border pixels outwards (so that a torso leaving the frame keeps its
    // width). A "head" measured there mostly on repeated pixels is no head this camera saw: a sliver of shoulder
    // at the frame's edge, smeared into a head-sized blob. Kept, it reached the reconstructor as the head.
    if (!roll.quarterTurn() && out.found && 2 * out.pixels < up.pixels) {
        out.found = false;
        out.reason = "the head found on the frame turned upright lies mostly past this frame's border (" +
                     std::to_string(out.pixels) + " of its " + std::to_string(up.pixels) + " pixels in the frame)";
    }
}

void FacePipeline::segmentAt(ImageRoll roll, const cv::Mat& depth, const cv::Rect& seed_box_px, HeadSegmentation& out,
                             const cv::Rect* seed_box_upright) {
    if (roll.upright()) return segmenter_.segment(depth, depth_, seed_box_px, out);
    const UprightFrame& f = upright(roll, depth, nullptr);
    // A box turned to a tilt and back grows (its bounding box's bounding box: 1.9 times as wide at 30 degrees), and
    // the segmenter seeds from all of it; a face found on the upright frame seeds from its own box.
    const cv::Rect seed_up = seed_box_upright ? *seed_box_upright : roll.rectToUpright(seed_box_px, depth.size());
    segmenter_.segment(f.depth_m, f.k, seed_up, upright_segmentation_);
    turnBack(roll, upright_segmentation_, depth, out);
}

StatusOr<FaceDetections> FacePipeline::detectAt(ImageRoll roll, const cv::Mat& depth, const cv::Mat& colour) {
    if (roll.upright()) return detector_.detect(depth, colour, depth_, colour_);
    const UprightFrame& f = upright(roll, depth, &colour);
    StatusOr<FaceDetections> faces = detector_.detect(f.depth_m, f.colour, f.k, f.colour_camera);
    if (!faces.isOk()) return faces;
    const cv::Size colour_size = colour.size();
    detected_upright_boxes_.clear();
    for (FaceDetection& face : faces->faces) {
        detected_upright_boxes_.push_back(face.box_depth_px);
        face.box_depth_px = roll.rectFromUpright(face.box_depth_px, depth.size());
        face.box_colour_px = roll.rectFromUpright(face.box_colour_px, colour_size);
    }
    return faces;
}

void FacePipeline::findAt(ImageRoll roll, const cv::Mat& depth, HeadSegmentation& out) {
    if (roll.upright()) return finder_.find(depth, depth_, out);
    const UprightFrame& f = upright(roll, depth, nullptr);
    finder_.find(f.depth_m, f.k, upright_segmentation_);
    turnBack(roll, upright_segmentation_, depth, out);
}

HeadObservation FacePipeline::process(const RgbdFrame& frame, const cv::Rect* predicted_head_box) {
    HeadObservation obs;
    const cv::Mat& depth = frame.depth_m;
    if (depth.empty()) return obs.reason = "depth image is empty", obs;
    if (depth.type() != CV_32FC1) return obs.reason = "depth must be CV_32FC1 metres", obs;
    if (depth.cols != depth_.width_px || depth.rows != depth_.height_px) {
        return obs.reason = "depth size differs from the camera's intrinsics", obs;
    }
    for (UprightFrame& f : upright_) f.have_depth = f.have_colour = false;  // a new frame
    obs.roll_deg = roll_.degrees();

    // 1. Tracking: the predicted head box seeds the segmenter; no detection.
    const bool redetect_due =
        params_.redetect_every_frames > 0 && frames_since_detection_ >= params_.redetect_every_frames;
    if (predicted_head_box && !redetect_due) {
        const auto t0 = Clock::now();
        segmentAt(roll_, depth, *predicted_head_box, segmentation_);
        obs.segment_ms = msSince(t0);
        ++frames_since_detection_;
        if (segmentation_.found) {
            adopt(segmentation_, obs);
            obs.face_box = segmentation_.head_box_px;
            return obs;
        }
        // The prediction no longer holds a head: fall through to detection.
    }

    // 2. Detection with colour: the nearest accepted face is scanned, the others counted. The roll in use first;
    // the other quarter turns while the roll is unknown, or once the cascade has missed at it for a while (the
    // camera was turned), unless the roll is fixed.
    obs.detection_ran = true;
    frames_since_detection_ = 0;
    std::string detect_reason = "no colour image";
    const auto t_colour = Clock::now();
    const cv::Mat& colour = frameColour(frame, cv::Rect(0, 0, depth.cols, depth.rows));  // decoded now, if on demand
    obs.detect_ms += msSince(t_colour);
    if (!colour.empty()) {
        const bool search_rolls = params_.roll_deg == FacePipelineParams::kRollAuto &&
                                  (!roll_known_ || misses_at_roll_ >= params_.roll_recheck_misses);
        // The current roll, then a quarter turn either way, then upside down; while the roll is unknown, first
        // the tilt of the body when it is not a quarter turn, and a step either side of it (the cascade finds
        // faces only up to about a step from upright, and the ladder of its window sizes meets a face's width
        // at one tilt and misses it by a step at the next).
        std::array<ImageRoll, 7> rolls;
        int tries = 0;
        const auto add = [&](ImageRoll r) {
            if (std::find(rolls.begin(), rolls.begin() + tries, r) == rolls.begin() + tries) rolls[tries++] = r;
        };
        if (search_rolls && !roll_known_) {
            const ImageRoll body =
                rollFromBody(depth, params_.segmenter.min_depth_m, params_.segmenter.max_depth_m, roll_);
            if (!body.quarterTurn()) {
                for (const int step : {0, -ImageRoll::kStepDeg, ImageRoll::kStepDeg}) {
                    add(ImageRoll::fromDegrees(body.degrees() + step));
                }
            }
        }
        for (const int turn : {0, 90, 270, 180}) {
            add(ImageRoll::fromDegrees(roll_.degrees() + turn));
            if (!search_rolls) break;
        }
        bool cascade_found = false;
        for (int t = 0; t < tries && !cascade_found; ++t) {
            const ImageRoll roll = rolls[t];
            const auto t0 = Clock::now();
            StatusOr<FaceDetections> faces = detectAt(roll, depth, colour);
            obs.detect_ms += msSince(t0);
            if (!faces.isOk()) {
                detect_reason = faces.status().message();
                break;
            }
            if (faces->faces.empty()) {
                detect_reason = "no face found by the cascade";
                continue;
            }
            cascade_found = true;
            const FaceDetection& face = faces->faces.front();
            obs.other_faces = static_cast<int>(faces->faces.size()) - 1;
            obs.face_box = face.box_depth_px;
            const auto t1 = Clock::now();
            segmentAt(roll, depth, face.box_depth_px, segmentation_,
                      roll.upright() ? nullptr : &detected_upright_boxes_.front());
            obs.segment_ms += msSince(t1);
            adopt(segmentation_, obs);
            if (obs.found) {
                roll_ = roll;
                roll_known_ = true;
                misses_at_roll_ = 0;
                obs.roll_deg = roll.degrees();
                return obs;
            }
            detect_reason = "face found but " + segmentation_.reason;
        }
        if (!cascade_found) ++misses_at_roll_;
    }

    // 3. Depth only: the nearest head-sized blob, at the roll in use (from the body's direction while unknown).
    if (params_.depth_only_fallback) {
        const ImageRoll roll =
            roll_known_ ? roll_
                        : rollFromBody(depth, params_.segmenter.min_depth_m, params_.segmenter.max_depth_m, roll_);
        const auto t0 = Clock::now();
        findAt(roll, depth, segmentation_);
        obs.detect_ms += msSince(t0);
        if (segmentation_.found) {
            adopt(segmentation_, obs);
            obs.depth_only = true;
            obs.face_box = segmentation_.head_box_px;
            obs.reason.clear();
            obs.roll_deg = roll.degrees();
            roll_ = roll;
            return obs;
        }
        obs.found = false;
        obs.mask = segmentation_.mask;
        obs.depth_m = segmentation_.depth_m;
        obs.reason = detect_reason + "; depth-only: " + segmentation_.reason;
        return obs;
    }
    obs.found = false;
    obs.reason = detect_reason;
    return obs;
}

HeadObservation FacePipeline::process(const RgbdFrame& frame, const HeadPrediction& prediction) {
    const bool redetect_due =
        params_.redetect_every_frames > 0 && frames_since_detection_ >= params_.redetect_every_frames;
    if (prediction.model != nullptr && prediction.region.valid && params_.roll_deg == FacePipelineParams::kRollAuto) {
        // The model's down axis seen from the predicted camera: the roll of this frame (follows a turning camera).
        roll_ = ImageRoll::fromDownDirection(
            prediction.T_world_camera.linear().transpose() * prediction.region.down_world, roll_);
        roll_known_ = true;
    }
    if (redetect_due || prediction.model == nullptr) return process(frame, nullptr);
    const auto t0 = Clock::now();
    model_segmenter_.segment(frame.depth_m, depth_, prediction, params_.segmenter, model_segmentation_);
    const float ms = msSince(t0);
    if (!model_segmentation_.found) {
        // Not confirmed: find the head afresh (detection, width criterion, depth-only finder).
        HeadObservation obs = process(frame, nullptr);
        obs.segment_ms += ms;
        return obs;
    }
    ++frames_since_detection_;
    HeadObservation obs;
    adopt(model_segmentation_, obs);
    obs.from_model = true;
    obs.roll_deg = roll_.degrees();
    obs.segment_ms = ms;
    obs.face_box = model_segmentation_.head_box_px;
    return obs;
}

}  // namespace facescan::recon
