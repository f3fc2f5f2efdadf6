#include "recon_input.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "capture/frame_source.hpp"

namespace facescan::bench {
namespace {

namespace fs = std::filesystem;
using recon::Pose;

// synthetic[:OPTIONS]: synth/sequence_options.hpp (scenario=..., frames=, distance=, yaw=, ...).
Status loadSynthetic(const std::string& opts, int frames, Sequence& seq) {
    ASSIGN_OR_RETURN(synth::SyntheticSpec spec, synth::parseSyntheticOptions(opts));
    synth::SequenceParams& sp = spec.sequence;
    if (frames > 0) sp.frames = frames;
    RETURN_IF_ERROR(sp.validate());
    ASSIGN_OR_RETURN(synth::HeadModel head, synth::loadSubject(spec.subject));
    seq.sim.emplace(std::move(head), sp, spec.intrinsics);
    seq.k = seq.sim->intrinsics();
    seq.sensor = spec.sensor_model;
    seq.frames.resize(static_cast<size_t>(sp.frames));
    seq.masks.resize(seq.frames.size());
    seq.T_ref_camera.resize(seq.frames.size());
    seq.head_pixels.assign(seq.frames.size(), 0);
    seq.spec = spec;
    const Pose T_c0_head = seq.sim->poseAt(0);
    cv::parallel_for_(cv::Range(0, sp.frames), [&](const cv::Range& r) {
        for (int i = r.start; i < r.end; ++i) {
            synth::FrameTruth truth;
            seq.sim->render(i, seq.frames[i], &truth);
            seq.masks[i] = truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead);
            // The head is static in the world (= first camera); the camera moves: T_c0_ci = T_c0_h T_ci_h^-1.
            seq.T_ref_camera[i] = T_c0_head * truth.T_camera_head.inverse();
            seq.head_pixels[i] = truth.head_pixels;
        }
    });
    seq.mask_source = "renderer head label (ground truth)";
    return Status::ok();
}

Pose readMatrix4(std::istream& in) {
    Eigen::Matrix4f m;
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) in >> m(r, c);
    Pose p;
    p.matrix() = m;
    // 7-Scenes rotations are not exactly orthonormal (the trace-based angle of frame 150->151 reads 1.38 deg
    // for a 0.75 deg rotation); project onto the nearest rotation before comparing.
    const Eigen::JacobiSVD<Eigen::Matrix3f> svd(m.topLeftCorner<3, 3>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
    p.linear() = svd.matrixU() * svd.matrixV().transpose();
    return p;
}

// 7scenes:DIR — frame-XXXXXX.{color.png, depth.png (mm), pose.txt (camera to world)}, fx=fy=585, cx=320, cy=240.
Status load7Scenes(const fs::path& dir_in, int frames, Sequence& seq) {
    const fs::path dir = fs::is_directory(dir_in / "rgbd-frames") ? dir_in / "rgbd-frames" : dir_in;
    std::vector<fs::path> depth_files;
    for (const auto& e : fs::directory_iterator(dir)) {
        const std::string n = e.path().filename().string();
        if (n.size() > 10 && n.substr(n.size() - 10) == ".depth.png") depth_files.push_back(e.path());
    }
    std::sort(depth_files.begin(), depth_files.end());
    if (depth_files.empty()) return notFound("no frame-*.depth.png in " + dir.string());
    if (frames > 0 && static_cast<size_t>(frames) < depth_files.size()) depth_files.resize(frames);
    seq.k = recon::Intrinsics{640, 480, 585.0f, 585.0f, 320.0f, 240.0f};
    std::optional<Pose> T_w_c0;
    for (size_t i = 0; i < depth_files.size(); ++i) {
        const std::string stem = depth_files[i].string().substr(0, depth_files[i].string().size() - 10);
        const cv::Mat raw = cv::imread(depth_files[i].string(), cv::IMREAD_UNCHANGED);
        if (raw.type() != CV_16UC1) return dataLoss("not a 16-bit depth PNG: " + depth_files[i].string());
        recon::RgbdFrame f;
        cv::Mat raw_clean = raw.clone();
        raw_clean.setTo(0, raw == 65535);
        recon::depthRawToMetres(raw_clean, 0.001f, f.depth_m);
        f.timestamp_ns = static_cast<int64_t>(i) * 33'333'333;  // 7-Scenes is 30 Hz; frames carry no time
        // Colour is not registered to depth in 7-Scenes: left out rather than painted on the wrong voxels.
        seq.frames.push_back(std::move(f));
        seq.masks.emplace_back();
        std::ifstream pose_in(stem + ".pose.txt");
        std::optional<Pose> ref;
        if (pose_in) {
            const Pose T_w_ci = readMatrix4(pose_in);
            if (!T_w_c0) T_w_c0 = T_w_ci;
            ref = T_w_c0->inverse() * T_w_ci;
        }
        seq.T_ref_camera.push_back(ref);
    }
    return Status::ok();
}

// tum:DIR — rgb.txt / depth.txt (timestamp path), 16-bit depth with 5000 units per metre, optional intrinsics.txt
// and groundtruth.txt (re-expressed relative to the first frame's pose).
Status loadTum(const fs::path& dir, int frames, Sequence& seq) {
    std::ifstream depth_list(dir / "depth.txt");
    if (!depth_list) return notFound("no depth.txt in " + dir.string());
    std::ifstream intr(dir / "intrinsics.txt");
    if (intr) intr >> seq.k.fx_px >> seq.k.fy_px >> seq.k.cx_px >> seq.k.cy_px;
    std::vector<std::pair<double, std::string>> rgb;
    std::ifstream rgb_list(dir / "rgb.txt");
    std::string line;
    while (rgb_list && std::getline(rgb_list, line)) {
        if (line.empty() || line[0] == '#') continue;
        std::stringstream ss(line);
        double t;
        std::string p;
        if (ss >> t >> p) rgb.emplace_back(t, p);
    }
    std::map<double, Pose> gt;
    std::ifstream gt_in(dir / "groundtruth.txt");
    while (gt_in && std::getline(gt_in, line)) {
        if (line.empty() || line[0] == '#') continue;
        std::stringstream ss(line);
        double t;
        float tx, ty, tz, qx, qy, qz, qw;
        if (!(ss >> t >> tx >> ty >> tz >> qx >> qy >> qz >> qw)) continue;
        Pose p = Pose::Identity();
        p.linear() = Eigen::Quaternionf(qw, qx, qy, qz).normalized().toRotationMatrix();
        p.translation() = Eigen::Vector3f(tx, ty, tz);
        gt[t] = p;
    }
    std::optional<Pose> T_w_c0;
    while (std::getline(depth_list, line)) {
        if (line.empty() || line[0] == '#') continue;
        if (frames > 0 && static_cast<int>(seq.frames.size()) >= frames) break;
        std::stringstream ss(line);
        double t;
        std::string path;
        if (!(ss >> t >> path)) continue;
        const cv::Mat raw = cv::imread((dir / path).string(), cv::IMREAD_UNCHANGED);
        if (raw.type() != CV_16UC1) return dataLoss("not a 16-bit depth PNG: " + (dir / path).string());
        recon::RgbdFrame f;
        recon::depthRawToMetres(raw, 1.0f / 5000.0f, f.depth_m);
        f.timestamp_ns = static_cast<int64_t>(std::llround(t * 1e9));
        if (!rgb.empty()) {
            const auto best = std::min_element(rgb.begin(), rgb.end(), [&](const auto& a, const auto& b) {
                return std::fabs(a.first - t) < std::fabs(b.first - t);
            });
            f.colour_bgr = cv::imread((dir / best->second).string(), cv::IMREAD_COLOR);
            if (f.colour_bgr.size() != f.depth_m.size()) f.colour_bgr.release();
        }
        seq.k.width_px = raw.cols;
        seq.k.height_px = raw.rows;
        std::optional<Pose> ref;
        if (!gt.empty()) {
            auto it = gt.lower_bound(t - 0.02);
            if (it != gt.end() && std::fabs(it->first - t) < 0.02) {
                if (!T_w_c0) T_w_c0 = it->second;
                ref = T_w_c0->inverse() * it->second;
            }
        }
        seq.frames.push_back(std::move(f));
        seq.masks.emplace_back();
        seq.T_ref_camera.push_back(ref);
    }
    if (seq.frames.empty()) return notFound("no frames listed in depth.txt");
    return Status::ok();
}

// mkv:FILE / bag:FILE -- a depth camera's own recording, read by the agent's source for it (the same reader, the
// same calibration and undistortion). Colour that is not registered to depth is left out: the bench measures
// geometry, and frames carry registered colour only.
Status loadRecording(const std::string& spec, int frames, Sequence& seq) {
    capture::SourceOptions options;
    options.max_frames = frames;
    ASSIGN_OR_RETURN(std::unique_ptr<capture::FrameSource> source, capture::openSource(spec, options));
    const capture::SourceInfo& info = source->info();
    seq.k = info.intrinsics;
    if (info.sensor_known) seq.sensor = info.sensor;
    capture::CapturedFrame captured;
    for (;;) {
        ASSIGN_OR_RETURN(const bool got, source->next(captured));
        if (!got) break;
        recon::RgbdFrame f;
        recon::depthRawToMetres(captured.depth_raw, info.depth_units_m, f.depth_m);
        if (info.colour_registered && captured.colour_bgr.size() == captured.depth_raw.size()) {
            f.colour_bgr = captured.colour_bgr.clone();
        }
        f.timestamp_ns = captured.timestamp_ns;
        seq.frames.push_back(std::move(f));
        seq.masks.emplace_back();
        seq.T_ref_camera.emplace_back();
    }
    if (seq.frames.empty()) return notFound(spec + " holds no frame");
    return Status::ok();
}

}  // namespace

Status loadSequence(const std::string& in, int frames, Sequence& seq) {
    if (in.rfind("synthetic", 0) == 0) return loadSynthetic(in.size() > 10 ? in.substr(10) : "", frames, seq);
    if (in.rfind("tum:", 0) == 0) return loadTum(in.substr(4), frames, seq);
    if (in.rfind("7scenes:", 0) == 0) return load7Scenes(in.substr(8), frames, seq);
    if (in.rfind("mkv:", 0) == 0 || in.rfind("bag:", 0) == 0) return loadRecording(in, frames, seq);
    return invalidArgument("unknown --input '" + in +
                           "' (synthetic[:k=v,...], tum:DIR, 7scenes:DIR, mkv:FILE, bag:FILE)");
}

}  // namespace facescan::bench
