// facescan-bench recon: the reconstruction core on every frame of a sequence, as fast as it runs (docs/design.md s6).
// Frames are loaded (or rendered) before timing, so only recon_core is on the clock: filter, ICP, integration and
// ray casting together, wall clock over the whole loop. With --gt-accuracy on synthetic input the final mesh is
// measured against the ground-truth head with the accuracy ruler, next to a single-frame baseline; completeness
// is reported over the whole face region and over its observable part (eval/observed_region.hpp).
#include <sys/resource.h>

#include <Eigen/Core>
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

#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>  // instruction counts of the loop alone: see loopInstrumentation()
#endif

#include "allocation_counter.hpp"  // counts heap allocations: the frame loop must make none after warm-up
#include "bench_command.hpp"
#include "eval/accuracy.hpp"
#include "eval/mesh_io.hpp"
#include "eval/observed_region.hpp"
#include "eval/scenario_figures.hpp"
#include "pose_errors.hpp"
#include "recon/face_pipeline.hpp"
#include "recon/parallel.hpp"
#include "recon/reconstructor.hpp"
#include "recon/scan_step.hpp"
#include "recon/sensor_adapt.hpp"
#include "recon_input.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

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
    int cast_every = -1;     // --cast-every: ReconParams::model_cast_every (-1 = the preset's)
    int fuse_every = -1;     // --fuse-every: ReconParams::fuse_every (-1 = the preset's)
    int unfused_level = -1;  // --unfused-level: ReconParams::unfused_finest_level (-1 = the preset's)
    int model_level = -1;    // --model-level: ReconParams::model_level (-1 = the preset's)
    std::string misses_out;  // --gt-misses: GT face vertices coloured by why they are not covered
    float observed_tol_m = eval::ObservedRegionParams().surface_tolerance_m;  // metres, see observed_region.hpp
    // --mask pipeline: the head mask comes from the server's own FacePipeline (Viola-Jones + depth, segmentation,
    // tracked-box seeding), run inside the timed loop as facescan-server does; default: the input's own mask.
    bool pipeline_mask = false;
    // --mask none: every pixel of every frame (the core's empty mask), also for inputs that carry a head mask.
    bool no_mask = false;
    bool twin = false;  // --twin: also scan the scenario's twin without its event (scenario_figures.hpp)
    // --serial: the recon core's parallel loops run on the loop's own thread (recon::setParallelSerial), as a busy
    // server's sessions do: the per-stage times are then the serial CPU cost of a frame, without the pool's
    // hand-offs (which on one core, e.g. under taskset, cost more than the small loops they share).
    bool serial = false;
    // --roll: FacePipelineParams::roll_deg (how the camera is held; auto finds it from the frames).
    int roll_deg = recon::FacePipelineParams::kRollAuto;
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

// Under `valgrind --tool=callgrind --instr-atstart=no`, only the timed loop is instrumented, so callgrind's
// instruction count is the frame loop's alone (all threads): a figure that does not move with the machine's load,
// for comparing variants on a busy machine. Without valgrind (or its header) these do nothing.
void loopInstrumentation(bool on) {
#ifdef CALLGRIND_START_INSTRUMENTATION
    if (on) {
        CALLGRIND_START_INSTRUMENTATION;
    } else {
        CALLGRIND_STOP_INSTRUMENTATION;
    }
#else
    (void)on;
#endif
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

void printFrame(int i, const Sequence& seq, const recon::FrameResult& r, const recon::HeadObservation* head,
                const char* advice) {
    const float err_mm =
        seq.T_ref_camera[i]
            ? 1000.0f * (r.tracking.T_world_camera.translation() - seq.T_ref_camera[i]->translation()).norm()
            : -1.0f;
    std::printf("frame %3d %-18s inliers %6d rmse %.3f mm it %2d fail %d pose err %.2f mm %s", i,
                recon::trackingStatusName(r.tracking.status), r.tracking.inliers, 1000 * r.tracking.rmse_m,
                r.tracking.iterations, r.consecutive_failures, err_mm, r.reason);
    if (head && !head->found) std::printf(" [%s]", head->reason.c_str());
    if (r.verified) {
        std::printf(" verify: inliers %.2f conflicts %.3f rmse %.2f mm%s", r.check.agreeShare(),
                    r.check.conflictShare(), 1000 * r.check.rmse_m, r.reacquired ? " (re-acquired)" : "");
    }
    if (r.hypotheses > 0) std::printf(" %d hypotheses %.0f ms", r.hypotheses, r.reacquire_ms);
    if (r.occluding_pixels > 0) std::printf(" occluder px %d", r.occluding_pixels);
    if (*advice) std::printf(" -> \"%s\"", advice);
    // The frame's stage times: the averages hide where a scan's costly first frame goes.
    std::printf(" | ms detect %.2f segment %.2f filter %.2f icp %.2f integrate %.2f raycast %.2f",
                head ? head->detect_ms : 0.0f, head ? head->segment_ms : 0.0f, r.ms.filter, r.ms.icp, r.ms.integrate,
                r.ms.raycast);
    std::printf("\n");
}

struct LoopResult {
    std::vector<std::optional<Pose>> estimate;  // per frame, when tracked (fused or not)
    recon::StageTimesMs sum;                    // summed over frames
    int rejected = 0, warmup = 0;
    long allocations_after_warmup = 0;
    std::map<std::string, int> reasons;
    double loop_s = 0;         // wall clock over the loop
    int reacquisitions = 0;    // frames re-acquired by the hypothesis search
    int model_casts = 0;       // frames after which the model was ray cast (ReconParams::model_cast_every)
    int fused = 0;             // frames fused into the model (ReconParams::fuse_every)
    int coarse = 0;            // frames registered on the coarser levels only (ReconParams::unfused_finest_level)
    double search_ms_max = 0;  // slowest verification/search of a frame
};

// Every frame through the reconstructor, timed: with the server's FacePipeline (recon/scan_step.hpp, as the
// session worker runs it) when `pipeline` is given, else with the input's own masks.
LoopResult runLoop(const Sequence& seq, recon::Reconstructor& rec, recon::FacePipeline* pipeline, bool verbose,
                   const recon::AdviceParams& advice_params = {}) {
    const int n = static_cast<int>(seq.frames.size());
    LoopResult out;
    out.estimate.resize(static_cast<size_t>(n));
    out.warmup = std::min(n, 5);
    recon::StageTimesMs& sum = out.sum;
    recon::ScanStep step;
    long allocations_at_warmup = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) {
        if (i == out.warmup) {
            allocations_at_warmup = testing::heapAllocations();
            loopInstrumentation(true);
        }
        recon::FrameResult r;
        const char* advice = "";
        if (pipeline) {
            recon::scanFrame(*pipeline, rec, seq.frames[i], step, advice_params);
            sum.detect += step.head.detect_ms;
            sum.segment += step.head.segment_ms;
            r = step.frame;
            advice = step.advice;
        } else {
            r = rec.processFrame(seq.frames[i], seq.masks[i]);
        }
        sum.filter += r.ms.filter;
        sum.icp += r.ms.icp;
        sum.integrate += r.ms.integrate;
        sum.raycast += r.ms.raycast;
        out.reacquisitions += r.reacquired;
        out.model_casts += r.model_cast;
        out.search_ms_max = std::max(out.search_ms_max, static_cast<double>(r.reacquire_ms));
        if (verbose) printFrame(i, seq, r, pipeline ? &step.head : nullptr, advice);
        out.fused += r.integrated;
        out.coarse += r.finest_level > 0;
        if (r.tracked) {
            out.estimate[static_cast<size_t>(i)] = r.tracking.T_world_camera;
        } else {
            ++out.rejected;
            ++out.reasons[r.reason];
        }
    }
    out.loop_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    loopInstrumentation(false);
    out.allocations_after_warmup = n > out.warmup ? testing::heapAllocations() - allocations_at_warmup : 0;
    return out;
}

// The twin of a scenario: the same motion without its event (the gap's subject turns in view instead of leaving;
// the occluder is removed). Empty when the sequence has no event.
std::string twinInput(const Sequence& seq, const std::string& input) {
    if (!seq.sim) return "";
    const synth::SequenceParams& p = seq.sim->params();
    const std::string sep = input.find(':') == std::string::npos ? ":" : ",";
    if (p.gap_start_frame >= 0 && p.gap_leave) return input + sep + "gap_leave=0";
    if (p.occluder_start_frame >= 0) return input + sep + "occluder_start=-1";
    return "";
}

// --mask none: the input's own masks are dropped, so the core fuses whole frames.
void dropMasksIfAsked(const Options& o, Sequence& seq) {
    if (!o.no_mask) return;
    for (cv::Mat& m : seq.masks) m = cv::Mat();
    seq.mask_source = "none (--mask none: whole frames)";
}

// The mean accuracy of the scan of `input` (the twin of a scenario), run as the main sequence was.
StatusOr<double> twinMean(const Options& o, const recon::ReconParams& params, const std::string& input) {
    Sequence seq;
    RETURN_IF_ERROR(loadSequence(input, o.frames, seq));
    recon::Reconstructor rec(seq.k, params);
    RETURN_IF_ERROR(rec.initStatus());
    std::optional<recon::FacePipeline> pipeline;
    if (o.pipeline_mask) {
        recon::ReconParams unused = params;  // params are the main sequence's, already adapted to the camera
        recon::FacePipelineParams face_params;
        recon::AdviceParams advice;
        recon::adaptToSensor(seq.sensor, seq.k, unused, face_params, advice);
        face_params.roll_deg = o.roll_deg;
        ASSIGN_OR_RETURN(recon::FacePipeline created,
                         recon::FacePipeline::create(face_params, seq.k, recon::ColourCamera::registeredTo(seq.k)));
        pipeline.emplace(std::move(created));
    }
    dropMasksIfAsked(o, seq);
    (void)runLoop(seq, rec, pipeline ? &*pipeline : nullptr, false);
    const recon::Mesh& gt = seq.sim->head().mesh;
    ASSIGN_OR_RETURN(const eval::AccuracyReport acc, eval::measureAccuracy(rec.extractMesh(), gt, eval::findNoseTip(gt),
                                                                           {}, seq.sim->poseAt(0).inverse()));
    return acc.mean_mm;
}

// Without masks the whole frame is fused (recon::Reconstructor's contract). The volume is centred on the first
// frame's centroid, so a scene much deeper than the volume (a head 1 m in front of a wall) leaves the head outside
// it: the model is a sliver of background and registration fails frame after frame (299 of 300 on a synthetic TUM
// head recording). Returns the first frame's depth spread when that is the case.
std::optional<float> wholeFrameDepthSpreadM(const Sequence& seq, const recon::ReconParams& p, bool pipeline_mask) {
    if (pipeline_mask || seq.frames.empty() || (!seq.masks.empty() && !seq.masks.front().empty())) return std::nullopt;
    std::vector<float> z;
    const cv::Mat& d = seq.frames.front().depth_m;
    for (int v = 0; v < d.rows; v += 2)
        for (int u = 0; u < d.cols; u += 2) {
            const float m = d.at<float>(v, u);
            if (m >= p.filter.min_depth_m && m <= p.filter.max_depth_m) z.push_back(m);
        }
    if (z.size() < 100) return std::nullopt;
    const auto at = [&](double q) {
        auto it = z.begin() + static_cast<std::ptrdiff_t>(q * static_cast<double>(z.size() - 1));
        std::nth_element(z.begin(), it, z.end());
        return *it;
    };
    const float spread = at(0.98) - at(0.02);
    if (spread <= p.tsdf.volume_size_m) return std::nullopt;
    return spread;
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
        else if (a == "--mask" && i + 1 < args.size() &&
                 (args[i + 1] == "pipeline" || args[i + 1] == "input" || args[i + 1] == "none")) {
            const std::string mode = next();
            o.pipeline_mask = mode == "pipeline";
            o.no_mask = mode == "none";
        } else if (a == "--json")
            o.json = true;
        else if (a == "--verbose")
            o.verbose = true;
        else if (a == "--roll" && i + 1 < args.size() && recon::parseRoll(args[i + 1]).isOk())
            o.roll_deg = *recon::parseRoll(next());
        else if (a == "--twin")
            o.twin = o.gt_accuracy = true;
        else if (a == "--serial")
            o.serial = true;
        else if (a == "--volume-m")
            o.volume_m = std::stof(next());
        else if (a == "--trunc-m")
            o.trunc_m = std::stof(next());
        else if (a == "--cast-every")
            o.cast_every = std::atoi(next().c_str());  // junk reads 0: refused by ReconParams::validate
        else if (a == "--fuse-every")
            o.fuse_every = std::atoi(next().c_str());  // junk reads 0: refused by ReconParams::validate
        else if (a == "--unfused-level")
            o.unfused_level = std::atoi(next().c_str());  // junk reads 0: every level
        else if (a == "--model-level")
            o.model_level = std::atoi(next().c_str());  // junk reads 0: the full-resolution model
        else {
            std::printf(
                "usage: facescan-bench recon [--input SRC] [--frames N] [--preset face|fast] [--mesh OUT.ply]\n"
                "       [--trajectory OUT.txt] [--gt-accuracy] [--gt-misses OUT.ply] [--observed-tol-m M]\n"
                "       [--volume-m M] [--trunc-m M] [--mask input|pipeline|none] [--twin] [--serial] [--verbose]\n"
                "       [--model-level L] [--cast-every N] [--fuse-every N] [--unfused-level L] [--json]\n"
                "       [--roll auto|DEG]\n"
                "SRC: synthetic[:OPTIONS] | tum:DIR | 7scenes:DIR | mkv:FILE (Azure Kinect, Femto) | bag:FILE "
                "(RealSense)\n"
                "Synthetic input also reports robustness figures (tracked share, re-acquisition,\n"
                "wrong poses, foreign surface). --twin (implies --gt-accuracy) also scans the same motion without the\n"
                "scenario's event (the gap's subject turns in view; no occluder) and prints the difference of means.\n"
                "--mask pipeline: find the head per frame with the server's FacePipeline (timed in the loop)\n"
                "     instead of the input's mask (synthetic: the renderer's head label; tum/7scenes: none).\n"
                "--mask none: fuse whole frames (the core's empty mask); refused when the first frame is much deeper\n"
                "     than the volume (a head in front of a wall).\n"
                "--roll: how the camera is held for --mask pipeline (degrees the person appears turned clockwise,\n"
                "     0 to 345 in steps of 15; auto, the default, finds it from the frames). synthetic:roll=DEG rolls\n"
                "     the synthetic camera.\n"
                "--serial: run the recon core's parallel loops on the loop's thread alone (as a loaded server's\n"
                "     sessions do): the stage times are the serial CPU cost of a frame.\n"
                "--model-level L: ray cast the model at pyramid level L (0 = full resolution, the default; 1 = half).\n"
                "--cast-every N: ray cast the model after one frame in N (1, the default, to 4); the frames between\n"
                "     register against the last cast.\n"
                "--fuse-every N: fuse one tracked frame in N (1, the default, to 4); the frames between are tracked\n"
                "     only (their poses count in the ATE), and --cast-every counts fused frames.\n"
                "--unfused-level L: register the frames that are not fused down to pyramid level L only (default\n"
                "     1; 0 = every level, as fused frames are).\n"
                "%s\n",
                synth::syntheticOptionsHelp());
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
    if (const Status s = loadSequence(o.input, o.frames, seq); !s.isOk()) {
        std::fprintf(stderr, "recon: %s\n", s.toString().c_str());
        return 1;
    }
    dropMasksIfAsked(o, seq);
    recon::ReconParams params = o.preset == "fast" ? recon::ReconParams::fast() : recon::ReconParams::faceDefaults();
    // The camera's own limits, as the server sets them from its CameraInfo (a Kinect v1 keeps the defaults).
    recon::FacePipelineParams face_params;
    recon::AdviceParams advice;
    recon::adaptToSensor(seq.sensor, seq.k, params, face_params, advice);
    face_params.roll_deg = o.roll_deg;
    if (o.volume_m > 0) params.tsdf.volume_size_m = o.volume_m;
    if (o.trunc_m > 0) params.tsdf.trunc_dist_m = o.trunc_m;
    if (o.model_level >= 0) params.model_level = o.model_level;
    if (o.cast_every >= 0) params.model_cast_every = o.cast_every;
    if (o.fuse_every >= 0) params.fuse_every = o.fuse_every;
    if (o.unfused_level >= 0) params.unfused_finest_level = o.unfused_level;
    if (o.volume_m > 1.0f) {
        // A room-sized volume (7-Scenes): everything in range is "the head", the cube sits mid-scene.
        params.tsdf.centre_behind_surface_m = 0.0f;
        params.tsdf.max_blocks = 32768;
        params.filter.max_depth_m = 4.0f;
        params.icp.max_rmse_m = 0.03f;
        params.raycast.start_before_hint_m = 3.0f * params.tsdf.trunc_dist_m;  // rays must span a few voxels
        params.raycast.search_after_hint_m = 4.0f * params.tsdf.trunc_dist_m;
    }
    if (const std::optional<float> spread = wholeFrameDepthSpreadM(seq, params, o.pipeline_mask)) {
        std::fprintf(stderr,
                     "recon: %s is fused without head masks (none in the input, or --mask none), so every pixel counts "
                     "(the core's empty mask = whole frame), but "
                     "its first frame spans %.2f m in depth (2nd-98th percentile) and the volume is %.2f m: placed on "
                     "the centroid of head and background, it holds neither and nearly every frame is rejected.\n"
                     "  For a head recording use --mask pipeline (the server's own detection and segmentation); for "
                     "a room, a volume that holds it (--volume-m 3).\n",
                     o.input.c_str(), static_cast<double>(*spread), static_cast<double>(params.tsdf.volume_size_m));
        return 2;
    }
    const double rss_frames_mb = currentRssMb();
    recon::Reconstructor rec(seq.k, params);
    if (!rec.initStatus().isOk()) {
        std::fprintf(stderr, "recon: %s\n", rec.initStatus().toString().c_str());
        return 1;
    }

    std::optional<recon::FacePipeline> pipeline;
    if (o.pipeline_mask) {
        auto created = recon::FacePipeline::create(face_params, seq.k, recon::ColourCamera::registeredTo(seq.k));
        if (!created.isOk()) {
            std::fprintf(stderr, "recon: %s\n", created.status().toString().c_str());
            return 1;
        }
        pipeline.emplace(std::move(created).value());
        seq.mask_source = "facescan-server's FacePipeline (detection + segmentation, in the loop)";
    }

    const int n = static_cast<int>(seq.frames.size());
    recon::setParallelSerial(o.serial);
    const LoopResult loop = runLoop(seq, rec, pipeline ? &*pipeline : nullptr, o.verbose, advice);
    recon::setParallelSerial(false);
    const std::vector<std::optional<Pose>>& estimate = loop.estimate;
    const recon::StageTimesMs& sum = loop.sum;
    const int rejected = loop.rejected, warmup = loop.warmup;
    const long allocations_after_warmup = loop.allocations_after_warmup;
    const double loop_s = loop.loop_s;
    const double rss_recon_mb = currentRssMb() - rss_frames_mb;

    const auto tm = std::chrono::steady_clock::now();
    const recon::Mesh mesh = rec.extractMesh();
    const double mesh_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - tm).count();
    const double fps = n / loop_s;

    std::printf("facescan-bench recon: %s, %d frames, preset %s, mask: %s%s\n", o.input.c_str(), n, o.preset.c_str(),
                seq.mask_source.c_str(), o.serial ? "; serial (the core's loops on one thread)" : "");
    std::printf("camera %s\n", recon::describeSensor(seq.sensor, advice, params.tsdf).c_str());
    std::printf("volume %d^3 voxels of %.2f mm, %d blocks allocated (%.1f MB of voxels)\n", params.tsdf.resolution_vox,
                1000.0 * params.tsdf.voxelSizeM(), rec.volume().grid().allocated_blocks,
                rec.volume().grid().allocated_blocks * recon::kBlockVoxels * sizeof(recon::Voxel) / 1048576.0);
    std::printf("%-10s %10s\n", "stage", "ms/frame");
    if (pipeline) {
        std::printf("%-10s %10.3f\n%-10s %10.3f\n", "detect", sum.detect / n, "segment", sum.segment / n);
    }
    std::printf("%-10s %10.3f\n%-10s %10.3f\n%-10s %10.3f\n%-10s %10.3f\n", "filter", sum.filter / n, "icp",
                sum.icp / n, "integrate", sum.integrate / n, "raycast", sum.raycast / n);
    if (params.model_cast_every > 1)
        std::printf("           (the model cast after %d of %d frames)\n", loop.model_casts, n);
    if (params.fuse_every > 1) {
        std::printf("           (%d of %d frames fused, %d registered down to level %d only)\n", loop.fused, n,
                    loop.coarse, params.unfused_finest_level);
    }
    std::printf("%-10s %10.3f   (wall clock over the whole loop)\n", "total", 1000.0 * loop_s / n);
    std::printf("fps %.1f (wall clock, every frame processed), rejected %d, mesh %zu vertices %zu faces in %.1f ms\n",
                fps, rejected, mesh.n_vertices(), mesh.n_faces(), mesh_ms);
    for (const auto& [why, count] : loop.reasons) std::printf("  rejected %d x: %s\n", count, why.c_str());
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
    double own_accuracy_mean = -1.0;
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
            own_accuracy_mean = acc->mean_mm;
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
    // Robustness figures and, with --twin, the same motion without the scenario's event.
    std::string scenario_json, twin_json;
    if (seq.sim) {
        const eval::ScenarioFigures figures =
            eval::scenarioFigures(*seq.sim, seq.head_pixels, seq.T_ref_camera, estimate, mesh);
        eval::printScenario(figures);
        std::printf("re-acquisitions: %d frames fitted by the hypothesis search; slowest verification/search %.1f ms\n",
                    loop.reacquisitions, loop.search_ms_max);
        scenario_json = eval::scenarioJson(figures);
    }
    if (o.twin && seq.sim) {
        const std::string twin = twinInput(seq, o.input);
        const double own_mean = acc_json.empty() ? -1.0 : own_accuracy_mean;
        seq.frames.clear();  // the twin renders its own frames
        seq.masks.clear();
        if (twin.empty()) {
            std::printf("twin: %s has no event (gap, occluder) to leave out\n", o.input.c_str());
        } else if (const auto twin_mean = twinMean(o, params, twin); !twin_mean.isOk()) {
            std::printf("twin: %s\n", twin_mean.status().toString().c_str());
        } else {
            std::printf("twin (%s): mean %.4f mm; this run %.4f mm; difference %+.4f mm\n", twin.c_str(), *twin_mean,
                        own_mean, own_mean - *twin_mean);
            char buf[256];
            std::snprintf(buf, sizeof(buf), "{\"mean_mm\":%.4f,\"mean_diff_mm\":%.4f}", *twin_mean,
                          own_mean - *twin_mean);
            twin_json = buf;
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
        if (!scenario_json.empty()) std::printf(",\"scenario\":%s", scenario_json.c_str());
        if (!twin_json.empty()) std::printf(",\"twin\":%s", twin_json.c_str());
        std::printf("}\n");
    }
    return 0;
}

}  // namespace

FACESCAN_BENCH_COMMAND("recon", "the reconstruction core over a sequence: fps, per-stage ms, pose error, accuracy",
                       runRecon);

}  // namespace facescan::bench
