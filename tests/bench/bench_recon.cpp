// facescan-bench recon: the reconstruction core on every frame of a sequence, as fast as it runs (DESIGN.md s6).
// Frames are loaded (or rendered) before timing, so only recon_core is on the clock: filter, ICP, integration and
// ray casting together, wall clock over the whole loop. With --gt-accuracy on synthetic input the final mesh is
// measured against the ground-truth head with the accuracy ruler, next to a single-frame baseline; completeness
// is reported over the whole face region and over its observable part (eval/observed_region.hpp).
#include <sys/resource.h>

#include <Eigen/SVD>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <new>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "allocation_counter.hpp"  // counts heap allocations: the frame loop must make none after warm-up
#include "bench_command.hpp"
#include "eval/accuracy.hpp"
#include "eval/mesh_io.hpp"
#include "eval/observed_region.hpp"
#include "recon/face_pipeline.hpp"
#include "recon/reconstructor.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::bench {
namespace {

namespace fs = std::filesystem;
using recon::Pose;

struct Options {
    std::string input = "synthetic";
    int frames = 0;  // 0 = all
    std::string preset = "face";
    std::string mesh_out, trajectory_out;
    bool gt_accuracy = false;
    bool json = false;
    bool verbose = false;
    float volume_m = 0;  // 0 = preset
    float trunc_m = 0;
    std::string misses_out;  // --gt-misses: GT face vertices coloured by why they are not covered
    float observed_tol_m = eval::ObservedRegionParams().surface_tolerance_m;  // metres, see observed_region.hpp
    // --mask pipeline: the head mask comes from the server's own FacePipeline (Viola-Jones + depth, segmentation,
    // tracked-box seeding), run inside the timed loop as facescan-server does; default: the input's own mask.
    bool pipeline_mask = false;
};

struct Sequence {
    recon::Intrinsics k;
    std::vector<recon::RgbdFrame> frames;
    std::vector<cv::Mat> masks;                     // per frame, empty = whole frame
    std::vector<std::optional<Pose>> T_ref_camera;  // reference poses (first camera = identity), when known
    std::string mask_source = "none";
    std::optional<synth::KinectSimulator> sim;  // synthetic input only
};

double peakRssMb() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return static_cast<double>(u.ru_maxrss) / 1024.0;
}

double currentRssMb() {
    std::ifstream f("/proc/self/statm");
    long pages = 0, resident = 0;
    f >> pages >> resident;
    return static_cast<double>(resident) * 4096.0 / (1024.0 * 1024.0);
}

std::map<std::string, std::string> parseKv(const std::string& s) {
    std::map<std::string, std::string> kv;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) {
        const auto eq = item.find('=');
        if (eq != std::string::npos) kv[item.substr(0, eq)] = item.substr(eq + 1);
    }
    return kv;
}

// synthetic[:distance=0.9,yaw=35,yaw_period=150,pitch_period=75,frames=300,seed=1,noise=1,head=lps|builtin]
Status loadSynthetic(const std::string& opts, int frames, Sequence& seq) {
    auto kv = parseKv(opts);
    synth::SequenceParams sp;
    auto num = [&](const char* key, float def) { return kv.count(key) ? std::stof(kv[key]) : def; };
    sp.frames = frames > 0 ? frames : static_cast<int>(num("frames", 300));
    sp.distance_m = num("distance", sp.distance_m);
    sp.yaw_amplitude_deg = num("yaw", sp.yaw_amplitude_deg);
    sp.pitch_amplitude_deg = num("pitch", sp.pitch_amplitude_deg);
    sp.yaw_period_frames = num("yaw_period", sp.yaw_period_frames);
    sp.pitch_period_frames = num("pitch_period", sp.pitch_period_frames);
    sp.seed = static_cast<uint64_t>(num("seed", 1));
    sp.noise = num("noise", 1) != 0;
    RETURN_IF_ERROR(sp.validate());
    synth::HeadModel head;
    if (kv.count("head") && kv["head"] == "builtin") {
        head = synth::builtinHead();
    } else {
        const auto dir = synth::findLeePerrySmith();
        if (!dir) return notFound("leeperrysmith data not found (use head=builtin)");
        ASSIGN_OR_RETURN(head, synth::loadHeadScan(*dir));
    }
    seq.sim.emplace(std::move(head), sp);
    seq.k = seq.sim->intrinsics();
    seq.frames.resize(static_cast<size_t>(sp.frames));
    seq.masks.resize(seq.frames.size());
    seq.T_ref_camera.resize(seq.frames.size());
    const Pose T_c0_head = seq.sim->poseAt(0);
    cv::parallel_for_(cv::Range(0, sp.frames), [&](const cv::Range& r) {
        for (int i = r.start; i < r.end; ++i) {
            synth::FrameTruth truth;
            seq.sim->render(i, seq.frames[i], &truth);
            seq.masks[i] = truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead);
            // The head is static in the world (= first camera); the camera moves: T_c0_ci = T_c0_h T_ci_h^-1.
            seq.T_ref_camera[i] = T_c0_head * truth.T_camera_head.inverse();
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

Status loadSequence(const Options& o, Sequence& seq) {
    const std::string& in = o.input;
    if (in.rfind("synthetic", 0) == 0) {
        return loadSynthetic(in.size() > 10 ? in.substr(10) : "", o.frames, seq);
    }
    if (in.rfind("tum:", 0) == 0) return loadTum(in.substr(4), o.frames, seq);
    if (in.rfind("7scenes:", 0) == 0) return load7Scenes(in.substr(8), o.frames, seq);
    return invalidArgument("unknown --input '" + in + "' (synthetic[:k=v,...], tum:DIR, 7scenes:DIR)");
}

// Via the quaternion: acos of the trace loses everything below ~0.03 deg in float.
float rotationDeg(const Pose& t) { return Eigen::AngleAxisf(t.linear()).angle() * 57.2957795f; }

struct PoseErrors {
    int frames = 0;
    double ate_rmse_mm = 0, ate_max_mm = 0, rpe_mm = 0, rpe_deg = 0, rpe_max_mm = 0, rpe_max_deg = 0;
};

// ATE: the estimate and the reference share the first camera's frame, so no alignment is applied (an honest
// figure that includes drift). RPE: per consecutive pair of tracked frames.
PoseErrors poseErrors(const Sequence& seq, const std::vector<std::optional<Pose>>& estimate) {
    PoseErrors e;
    double ate2 = 0;
    int pairs = 0;
    for (size_t i = 0; i < estimate.size(); ++i) {
        if (!estimate[i] || !seq.T_ref_camera[i]) continue;
        const double d = (estimate[i]->translation() - seq.T_ref_camera[i]->translation()).norm() * 1000.0;
        ate2 += d * d;
        e.ate_max_mm = std::max(e.ate_max_mm, d);
        ++e.frames;
        if (i == 0 || !estimate[i - 1] || !seq.T_ref_camera[i - 1]) continue;
        const Pose rel_est = estimate[i - 1]->inverse() * *estimate[i];
        const Pose rel_ref = seq.T_ref_camera[i - 1]->inverse() * *seq.T_ref_camera[i];
        const Pose err = rel_ref.inverse() * rel_est;
        const double mm = err.translation().norm() * 1000.0, deg = rotationDeg(err);
        e.rpe_mm += mm;
        e.rpe_deg += deg;
        e.rpe_max_mm = std::max(e.rpe_max_mm, mm);
        e.rpe_max_deg = std::max(e.rpe_max_deg, deg);
        ++pairs;
    }
    if (e.frames > 0) e.ate_rmse_mm = std::sqrt(ate2 / e.frames);
    if (pairs > 0) {
        e.rpe_mm /= pairs;
        e.rpe_deg /= pairs;
    }
    return e;
}

void printAccuracy(const char* what, const eval::AccuracyReport& r) {
    std::printf(
        "%-22s mean %.3f mm  rms %.3f mm  median %.3f mm  p90 %.3f mm  completeness(2 mm) %.1f %% of the face, "
        "%.1f %% of its observable part  outliers(5 mm) %.2f %%  (%d samples)\n",
        what, r.mean_mm, r.rms_mm, r.median_mm, r.p90_mm, 100.0 * r.completeness, 100.0 * r.completeness_observed,
        100.0 * r.outliers, r.mesh_vertices_used);
    // The same surface at the true first pose, without any alignment, and the inflation the alignment found.
    std::printf(
        "%-22s mean %.3f mm  rms %.3f mm  median %.3f mm  p90 %.3f mm  (unaligned: true first pose)  "
        "uniform offset %+.3f mm\n",
        "", r.unaligned.mean_mm, r.unaligned.rms_mm, r.unaligned.median_mm, r.unaligned.p90_mm, r.offset_mm);
}

int runRecon(const std::vector<std::string>& args) {
    Options o;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto next = [&]() -> std::string { return i + 1 < args.size() ? args[++i] : std::string(); };
        if (a == "--input")
            o.input = next();
        else if (a == "--frames")
            o.frames = std::atoi(next().c_str());
        else if (a == "--preset")
            o.preset = next();
        else if (a == "--mesh")
            o.mesh_out = next();
        else if (a == "--trajectory")
            o.trajectory_out = next();
        else if (a == "--gt-accuracy")
            o.gt_accuracy = true;
        else if (a == "--gt-misses")
            o.misses_out = next(), o.gt_accuracy = true;
        else if (a == "--observed-tol-m")
            o.observed_tol_m = std::strtof(next().c_str(), nullptr);  // junk reads 0, which validate() refuses
        else if (a == "--mask" && i + 1 < args.size() && (args[i + 1] == "pipeline" || args[i + 1] == "input"))
            o.pipeline_mask = next() == "pipeline";
        else if (a == "--json")
            o.json = true;
        else if (a == "--verbose")
            o.verbose = true;
        else if (a == "--volume-m")
            o.volume_m = std::stof(next());
        else if (a == "--trunc-m")
            o.trunc_m = std::stof(next());
        else {
            std::printf(
                "usage: facescan-bench recon [--input SRC] [--frames N] [--preset face|fast] [--mesh OUT.ply]\n"
                "       [--trajectory OUT.txt] [--gt-accuracy] [--gt-misses OUT.ply] [--observed-tol-m M]\n"
                "       [--volume-m M] [--trunc-m M] [--mask input|pipeline] [--verbose] [--json]\n"
                "SRC: synthetic[:distance=0.7,yaw=35,pitch=12,yaw_period=300,pitch_period=150,frames=300,seed=1,\n"
                "     noise=1,head=lps|builtin] | tum:DIR | 7scenes:DIR\n"
                "--mask pipeline: find the head per frame with the server's FacePipeline (timed in the loop)\n"
                "     instead of the input's mask (synthetic: the renderer's head label; tum/7scenes: none).\n");
            return a == "--help" ? 0 : 2;
        }
    }
    eval::ObservedRegionParams observed_params;
    observed_params.surface_tolerance_m = o.observed_tol_m;
    if (const Status s = observed_params.validate(); !s.isOk()) {
        std::fprintf(stderr, "recon: --observed-tol-m: %s\n", s.toString().c_str());
        return 2;
    }
    const double rss_start_mb = currentRssMb();
    Sequence seq;
    if (const Status s = loadSequence(o, seq); !s.isOk()) {
        std::fprintf(stderr, "recon: %s\n", s.toString().c_str());
        return 1;
    }
    recon::ReconParams params = o.preset == "fast" ? recon::ReconParams::fast() : recon::ReconParams::faceDefaults();
    if (o.volume_m > 0) params.tsdf.volume_size_m = o.volume_m;
    if (o.trunc_m > 0) params.tsdf.trunc_dist_m = o.trunc_m;
    if (o.volume_m > 1.0f) {
        // A room-sized volume (7-Scenes): everything in range is "the head", the cube sits mid-scene.
        params.tsdf.centre_behind_surface_m = 0.0f;
        params.tsdf.max_blocks = 32768;
        params.filter.max_depth_m = 4.0f;
        params.icp.max_rmse_m = 0.03f;
        params.raycast.start_before_hint_m = 3.0f * params.tsdf.trunc_dist_m;  // rays must span a few voxels
        params.raycast.search_after_hint_m = 4.0f * params.tsdf.trunc_dist_m;
    }
    const double rss_frames_mb = currentRssMb();
    recon::Reconstructor rec(seq.k, params);
    if (!rec.initStatus().isOk()) {
        std::fprintf(stderr, "recon: %s\n", rec.initStatus().toString().c_str());
        return 1;
    }

    std::optional<recon::FacePipeline> pipeline;
    if (o.pipeline_mask) {
        auto created = recon::FacePipeline::create({}, seq.k, recon::ColourCamera::registeredTo(seq.k));
        if (!created.isOk()) {
            std::fprintf(stderr, "recon: %s\n", created.status().toString().c_str());
            return 1;
        }
        pipeline.emplace(std::move(created).value());
        seq.mask_source = "facescan-server's FacePipeline (detection + segmentation, in the loop)";
    }

    const int n = static_cast<int>(seq.frames.size());
    std::vector<std::optional<Pose>> estimate(static_cast<size_t>(n));
    recon::StageTimesMs sum;
    int rejected = 0;
    const int warmup = std::min(n, 5);
    long allocations_after_warmup = 0;
    std::map<std::string, int> reasons;
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) {
        if (i == warmup) allocations_after_warmup = testing::heapAllocations();
        recon::FrameResult r;
        std::string head_reason;  // outlives r.reason's use below
        if (pipeline) {
            // As the server's session worker does: the tracked pose seeds the segmenter; detection otherwise.
            cv::Rect box;
            const bool tracked = rec.predictedHeadBox(box);
            const recon::HeadObservation head = pipeline->process(seq.frames[i], tracked ? &box : nullptr);
            sum.detect += head.detect_ms;
            sum.segment += head.segment_ms;
            if (head.found) {
                r = rec.processFrame(seq.frames[i], head.mask);
            } else {
                head_reason = head.reason;
                r.reason = head_reason.c_str();
            }
        } else {
            r = rec.processFrame(seq.frames[i], seq.masks[i]);
        }
        sum.filter += r.ms.filter;
        sum.icp += r.ms.icp;
        sum.integrate += r.ms.integrate;
        sum.raycast += r.ms.raycast;
        if (o.verbose) {
            const float err_mm =
                seq.T_ref_camera[i]
                    ? 1000.0f * (r.tracking.T_world_camera.translation() - seq.T_ref_camera[i]->translation()).norm()
                    : -1.0f;
            std::printf("frame %3d %-18s inliers %6d rmse %.3f mm it %2d fail %d pose err %.2f mm %s\n", i,
                        recon::trackingStatusName(r.tracking.status), r.tracking.inliers, 1000 * r.tracking.rmse_m,
                        r.tracking.iterations, r.consecutive_failures, err_mm, r.reason);
        }
        if (r.integrated) {
            estimate[i] = r.tracking.T_world_camera;
        } else {
            ++rejected;
            ++reasons[r.reason];
        }
    }
    const double loop_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    allocations_after_warmup = n > warmup ? testing::heapAllocations() - allocations_after_warmup : 0;
    const double rss_recon_mb = currentRssMb() - rss_frames_mb;

    const auto tm = std::chrono::steady_clock::now();
    const recon::Mesh mesh = rec.extractMesh();
    const double mesh_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - tm).count();
    const double fps = n / loop_s;

    std::printf("facescan-bench recon: %s, %d frames, preset %s, mask: %s\n", o.input.c_str(), n, o.preset.c_str(),
                seq.mask_source.c_str());
    std::printf("volume %d^3 voxels of %.2f mm, %d blocks allocated (%.1f MB of voxels)\n", params.tsdf.resolution_vox,
                1000.0 * params.tsdf.voxelSizeM(), rec.volume().grid().allocated_blocks,
                rec.volume().grid().allocated_blocks * recon::kBlockVoxels * sizeof(recon::Voxel) / 1048576.0);
    std::printf("%-10s %10s\n", "stage", "ms/frame");
    if (pipeline) {
        std::printf("%-10s %10.3f\n%-10s %10.3f\n", "detect", sum.detect / n, "segment", sum.segment / n);
    }
    std::printf("%-10s %10.3f\n%-10s %10.3f\n%-10s %10.3f\n%-10s %10.3f\n", "filter", sum.filter / n, "icp",
                sum.icp / n, "integrate", sum.integrate / n, "raycast", sum.raycast / n);
    std::printf("%-10s %10.3f   (wall clock over the whole loop)\n", "total", 1000.0 * loop_s / n);
    std::printf("fps %.1f (wall clock, every frame processed), rejected %d, mesh %zu vertices %zu faces in %.1f ms\n",
                fps, rejected, mesh.n_vertices(), mesh.n_faces(), mesh_ms);
    for (const auto& [why, count] : reasons) std::printf("  rejected %d x: %s\n", count, why.c_str());
    std::printf("heap allocations in the loop after %d warm-up frames: %ld\n", warmup, allocations_after_warmup);
    std::printf("memory: peak RSS %.1f MB (frames held in memory %.1f MB, reconstructor %.1f MB)\n", peakRssMb(),
                rss_frames_mb - rss_start_mb, rss_recon_mb);

    const PoseErrors pe = poseErrors(seq, estimate);
    if (pe.frames > 0) {
        std::printf(
            "pose vs reference (%d frames): ATE rmse %.2f mm (max %.2f), RPE mean %.3f mm %.4f deg "
            "(max %.3f mm %.4f deg)\n",
            pe.frames, pe.ate_rmse_mm, pe.ate_max_mm, pe.rpe_mm, pe.rpe_deg, pe.rpe_max_mm, pe.rpe_max_deg);
    }
    if (!o.trajectory_out.empty()) {
        std::ofstream out(o.trajectory_out);
        out << "# timestamp tx ty tz qx qy qz qw (camera to first camera), facescan recon\n";
        for (const auto& [t, pose] : rec.trajectory()) out << recon::toTumLine(t, pose) << "\n";
    }
    if (!o.mesh_out.empty()) {
        if (const Status s = eval::writeMesh(mesh, o.mesh_out); !s.isOk())
            std::fprintf(stderr, "recon: %s\n", s.toString().c_str());
    }

    std::string acc_json, base_json;
    if (o.gt_accuracy && seq.sim) {
        const recon::Mesh& gt = seq.sim->head().mesh;
        const Eigen::Vector3f nose = eval::findNoseTip(gt);
        const Pose guess = seq.sim->poseAt(0).inverse();  // mesh is in the first camera: T_head_camera0
        // The observable face region: GT vertices the sensor measured in at least one frame of the sequence
        // (eval/observed_region.hpp: facing the camera, no surface of G more than --observed-tol-m in front of it
        // on its ray, a depth in the noisy frame at its pixel). Every frame counts. The baseline is measured over
        // the same region, so both share one denominator.
        observed_params.min_cos_angle = params.tsdf.min_cos_angle;
        std::vector<eval::SensorView> views(seq.frames.size());
        for (size_t i = 0; i < views.size(); ++i)
            views[i] = {seq.sim->poseAt(static_cast<int>(i)), seq.frames[i].depth_m, seq.masks[i]};
        const auto ts = std::chrono::steady_clock::now();
        const auto sightings = eval::countSightings(gt, seq.k, views, observed_params);
        const double sight_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
        eval::AccuracyParams acc_params;
        if (sightings.isOk()) {
            acc_params.observed = eval::observedMask(*sightings);
        } else {
            std::printf("observable region: %s (completeness_observed = completeness)\n",
                        sightings.status().toString().c_str());
        }
        const auto acc = eval::measureAccuracy(mesh, gt, nose, acc_params, guess);
        // Single-frame baseline: the first frame alone, through the same filter and integration.
        recon::Reconstructor single(seq.k, params);
        (void)single.processFrame(seq.frames[0], seq.masks[0]);
        const auto base = eval::measureAccuracy(single.extractMesh(), gt, nose, acc_params, guess);
        if (acc.isOk()) {
            std::printf(
                "observable face region: %d of %d GT face vertices (%.1f %%) measured by the sensor in at least one "
                "of %zu frames (%.1f s to find)\n",
                acc->gt_observed_vertices, acc->gt_face_vertices,
                100.0 * acc->gt_observed_vertices / acc->gt_face_vertices, seq.frames.size(), sight_s);
            printAccuracy("accuracy (all frames)", *acc);
            acc_json = eval::accuracyJson(*acc);
            if (!o.misses_out.empty() && sightings.isOk()) {
                if (const Status s = eval::writeMisses(gt, *sightings, mesh, *acc, nose, acc_params, o.misses_out);
                    !s.isOk())
                    std::fprintf(stderr, "recon: %s\n", s.toString().c_str());
            }
        } else {
            std::printf("accuracy: %s\n", acc.status().toString().c_str());
        }
        if (base.isOk()) {
            printAccuracy("baseline (1 frame)", *base);
            base_json = eval::accuracyJson(*base);
        }
    }
    if (o.json) {
        std::printf(
            "{\"frames\":%d,\"fps\":%.2f,\"ms\":{\"detect\":%.3f,\"segment\":%.3f,\"filter\":%.3f,\"icp\":%.3f,"
            "\"integrate\":%.3f,\"raycast\":%.3f,\"mesh\":%.1f},\"rejected\":%d,\"peak_rss_mb\":%.1f,"
            "\"recon_rss_mb\":%.1f,\"allocations_after_warmup\":%ld,\"mask\":\"%s\"",
            n, fps, sum.detect / n, sum.segment / n, sum.filter / n, sum.icp / n, sum.integrate / n, sum.raycast / n,
            mesh_ms, rejected, peakRssMb(), rss_recon_mb, allocations_after_warmup, seq.mask_source.c_str());
        if (pe.frames > 0)
            std::printf(",\"ate_rmse_mm\":%.3f,\"rpe_mm\":%.4f,\"rpe_deg\":%.5f", pe.ate_rmse_mm, pe.rpe_mm,
                        pe.rpe_deg);
        if (!acc_json.empty()) std::printf(",\"accuracy\":%s", acc_json.c_str());
        if (!base_json.empty()) std::printf(",\"baseline\":%s", base_json.c_str());
        std::printf("}\n");
    }
    return 0;
}

}  // namespace

FACESCAN_BENCH_COMMAND("recon", "the reconstruction core over a sequence: fps, per-stage ms, pose error, accuracy",
                       runRecon);

}  // namespace facescan::bench
