// facescan-bench synth: how fast the synthetic Kinect renders (it must feed the pipeline live, >= 30 frames/s on
// 2 cores) and how often OpenCV's stock frontal-face cascade finds the rendered face (realism of the colour).
#include <chrono>
#include <cstdio>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "bench_command.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace {

using facescan::synth::HeadModel;

int usage(std::FILE* out) {
    std::fprintf(
        out,
        "usage: facescan-bench synth [--sequence OPTIONS] [--frames N] [--head builtin|scan|FILE] [--distance M]\n"
        "                            [--no-detect] [--dump DIR] [--dump-frames A,B,...] [--tum DIR] [--json]\n"
        "  Renders a synthetic sequence (default: 300 frames, 0.7 m, yaw +-35, pitch +-12 deg) and reports\n"
        "  render frames/s and the stock Viola-Jones detection rate (a hit: IoU >= 0.3 with the true face box).\n"
        "  --sequence takes the options of `synthetic:` sources (e.g. scenario=chin); --frames, --head and\n"
        "  --distance override them. --dump DIR writes every 25th frame (or --dump-frames) as PNG: colour, depth,\n"
        "  labels; --tum DIR writes the sequence as a TUM folder.\n%s\n",
        facescan::synth::syntheticOptionsHelp());
    return out == stdout ? 0 : 2;
}

double iou(const cv::Rect& a, const cv::Rect& b) {
    const double inter = (a & b).area();
    const double uni = a.area() + b.area() - inter;
    return uni > 0 ? inter / uni : 0.0;
}

int runSynth(const std::vector<std::string>& args) {
    std::string sequence_text, head_arg, dump_dir, tum_dir;
    int frames = 0;
    float distance_m = 0;
    std::set<int> dump_frames;
    bool json = false, detect = true;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const bool has_value = i + 1 < args.size();
        if (a == "--json") {
            json = true;
        } else if (a == "--no-detect") {
            detect = false;
        } else if (a == "--sequence" && has_value) {
            sequence_text = args[++i];
        } else if (a == "--frames" && has_value) {
            frames = std::atoi(args[++i].c_str());
        } else if (a == "--distance" && has_value) {
            distance_m = std::strtof(args[++i].c_str(), nullptr);
        } else if (a == "--head" && has_value) {
            head_arg = args[++i];
        } else if (a == "--dump" && has_value) {
            dump_dir = args[++i];
        } else if (a == "--dump-frames" && has_value) {
            std::stringstream list(args[++i]);
            for (std::string item; std::getline(list, item, ',');) dump_frames.insert(std::atoi(item.c_str()));
        } else if (a == "--tum" && has_value) {
            tum_dir = args[++i];
        } else if (a == "--help" || a == "-h") {
            return usage(stdout);
        } else {
            std::fprintf(stderr, "synth: unknown or incomplete option '%s'\n", a.c_str());
            return usage(stderr);
        }
    }
    auto spec = facescan::synth::parseSyntheticOptions(sequence_text);
    if (spec.isOk()) {
        if (frames > 0) spec->sequence.frames = frames;
        if (distance_m > 0) spec->sequence.distance_m = distance_m;
        if (!head_arg.empty()) spec->subject = head_arg == "default" ? "auto" : head_arg;
    }
    const auto valid = spec.isOk() ? spec->sequence.validate() : spec.status();
    if (!valid.isOk()) {
        std::fprintf(stderr, "synth: %s\n", valid.toString().c_str());
        return 2;
    }
    const facescan::synth::SequenceParams params = spec->sequence;
    auto loaded = facescan::synth::loadSubject(spec->subject);
    if (!loaded.isOk()) {
        std::fprintf(stderr, "synth: %s\n", loaded.status().toString().c_str());
        return 1;
    }
    HeadModel head = std::move(loaded).value();
    const std::string head_name = head.name;
    const facescan::synth::KinectSimulator sim(std::move(head), params, spec->intrinsics);
    if (!tum_dir.empty()) {
        if (const auto st = facescan::synth::writeTumSequence(sim, tum_dir); !st.isOk()) {
            std::fprintf(stderr, "synth: %s\n", st.toString().c_str());
            return 1;
        }
    }

    // Render speed: every frame in order, as the agent's synthetic source does, with the ground truth on.
    facescan::recon::RgbdFrame frame;
    facescan::synth::FrameTruth truth;
    sim.render(0, frame, &truth);  // warm-up (tables, thread pool)
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < sim.frameCount(); ++i) sim.render(i, frame, &truth);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double fps = sim.frameCount() / seconds;

    int hits = 0, frontal = 0, frontal_hits = 0, false_positives = 0, visible = 0;
    if (detect || !dump_dir.empty()) {
        cv::CascadeClassifier cascade;
        if (detect && !cascade.load(FACESCAN_HAAR_FRONTAL_DEFAULT)) {
            std::fprintf(stderr, "synth: cannot load %s\n", FACESCAN_HAAR_FRONTAL_DEFAULT);
            return 1;
        }
        cv::Mat grey;
        for (int i = 0; i < sim.frameCount(); ++i) {
            sim.render(i, frame, &truth);
            if (!dump_dir.empty() && (dump_frames.empty() ? i % 25 == 0 : dump_frames.count(i) > 0)) {
                std::filesystem::create_directories(dump_dir);
                cv::imwrite(dump_dir + "/colour_" + std::to_string(i) + ".png", frame.colour_bgr);
                cv::Mat d8;
                frame.depth_m.convertTo(d8, CV_8U, 255.0 / 2.0);
                cv::imwrite(dump_dir + "/depth_" + std::to_string(i) + ".png", d8);
                cv::imwrite(dump_dir + "/label_" + std::to_string(i) + ".png", truth.label * 100);
            }
            if (!detect) continue;
            cv::cvtColor(frame.colour_bgr, grey, cv::COLOR_BGR2GRAY);
            std::vector<cv::Rect> faces;
            cascade.detectMultiScale(grey, faces, 1.1, 3, 0, cv::Size(40, 40));
            const bool has_face = !truth.face_box_px.empty();
            const bool is_frontal = std::abs(truth.yaw_deg) < 15 && std::abs(truth.pitch_deg) < 10;
            bool hit = false;
            for (const auto& f : faces) {
                if (has_face && iou(f, truth.face_box_px) >= 0.3) {
                    hit = true;
                } else {
                    ++false_positives;
                }
            }
            visible += has_face;
            hits += hit;
            frontal += is_frontal;
            frontal_hits += is_frontal && hit;
        }
    }
    const double rate = sim.frameCount() > 0 ? static_cast<double>(hits) / sim.frameCount() : 0;
    const double frontal_rate = frontal > 0 ? static_cast<double>(frontal_hits) / frontal : 0;
    std::printf("synthetic Kinect: head %s, %d frames at %.2f m, %d threads\n", head_name.c_str(), sim.frameCount(),
                params.distance_m, cv::getNumThreads());
    std::printf("  %-28s %8.1f\n", "render frames/s", fps);
    std::printf("  %-28s %8.2f\n", "render ms/frame", 1000.0 / fps);
    if (detect) {
        std::printf("  %-28s %8.3f (%d of %d frames; face visible in %d)\n", "Viola-Jones detection rate", rate, hits,
                    sim.frameCount(), visible);
        std::printf("  %-28s %8.3f (%d of %d frames, |yaw| < 15, |pitch| < 10)\n", "  frontal frames", frontal_rate,
                    frontal_hits, frontal);
        std::printf("  %-28s %8d\n", "false positives", false_positives);
    }
    if (json) {
        std::printf(
            "{\"head\":\"%s\",\"frames\":%d,\"fps\":%.2f,\"ms_per_frame\":%.3f,\"detection_rate\":%.4f,"
            "\"frontal_detection_rate\":%.4f,\"false_positives\":%d}\n",
            head_name.c_str(), sim.frameCount(), fps, 1000.0 / fps, detect ? rate : -1.0, detect ? frontal_rate : -1.0,
            detect ? false_positives : -1);
    }
    return 0;
}

}  // namespace

FACESCAN_BENCH_COMMAND("synth", "synthetic Kinect: render frames/s and Viola-Jones detection rate", runSynth);
