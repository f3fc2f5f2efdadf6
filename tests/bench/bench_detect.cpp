// facescan-bench detect: the depth-accelerated detector (recon::FaceDetector) against stock OpenCV
// detectMultiScale on the same frames, same cascade, scaleFactor 1.1, minNeighbors 3; stock runs on the full
// grey image. Both are timed in the same process, frame by frame, interleaved, so load on the machine hits both.
// Scoring: a detection matches an unmatched truth box at IoU >= 0.3; every other detection is a false positive.
// Sources: synthetic[:frames=N] (facescan_synth at 0.5-1.5 m, with head-label IoU of the segmentation),
// biwi:DIR (real Kinect, colour not registered), dlib:DIR (photos, no depth: stock reference only), tum:DIR (any
// recording, e.g. a TUM RGB-D folder or `facescan-bench synth --tum`; it has no face boxes, so speed, how often
// each detector finds a face and how often the two agree are reported, and --boxes writes both detectors' boxes
// for scoring outside).
#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "../detect/detect_data.hpp"
#include "bench_command.hpp"
#include "recon/face_detector.hpp"
#include "recon/face_pipeline.hpp"
#include "recon/head_segmenter.hpp"
#include "recon_input.hpp"
#include "test_data.hpp"
#if __has_include("synth/kinect_simulator.hpp")
#include "synth/kinect_simulator.hpp"
#define FACESCAN_BENCH_HAVE_SYNTH 1
#endif

namespace facescan::bench {
namespace {

namespace dd = detect_data;
using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

struct Tally {
    std::string name;
    int frames = 0;
    double ours_ms = 0, stock_ms = 0, candidates_ms = 0;
    dd::Score ours, stock;
    int rejected = 0;
    // Sources without face boxes (tum:): frames where each detector found a face, and where both agree.
    int ours_found = 0, stock_found = 0, agree = 0;
    std::FILE* boxes_csv = nullptr;  // --boxes: one line per frame and detector (not owned)
    // Segmentation (where a head label exists).
    int segmented = 0, iou_frames = 0;
    double segment_ms = 0, iou_sum = 0, iou_min = 1;
    void add(const Tally& t) {
        frames += t.frames, ours_ms += t.ours_ms, stock_ms += t.stock_ms, candidates_ms += t.candidates_ms;
        ours.add(t.ours), stock.add(t.stock), rejected += t.rejected;
        segmented += t.segmented, segment_ms += t.segment_ms, iou_sum += t.iou_sum, iou_frames += t.iou_frames;
        iou_min = std::min(iou_min, t.iou_min);
        ours_found += t.ours_found, stock_found += t.stock_found, agree += t.agree;
    }
};

std::vector<cv::Rect> colourBoxes(const recon::FaceDetections& d) {
    std::vector<cv::Rect> boxes;
    for (const auto& f : d.faces) boxes.push_back(f.box_colour_px);
    return boxes;
}

// --boxes: source,frame,timestamp_s,detector,faces,x,y,w,h (colour pixels) with the first box of each detector
// (ours: the nearest accepted face; stock: the largest), x..h empty when it found none.
void writeBoxes(std::FILE* out, const Tally& t, const recon::RgbdFrame& frame, const char* detector,
                std::vector<cv::Rect> boxes) {
    if (!out) return;
    std::fprintf(out, "%s,%d,%.6f,%s,%zu", t.name.c_str(), t.frames - 1, static_cast<double>(frame.timestamp_ns) * 1e-9,
                 detector, boxes.size());
    if (std::string(detector) == "stock") {
        std::sort(boxes.begin(), boxes.end(), [](const cv::Rect& a, const cv::Rect& b) { return a.area() > b.area(); });
    }
    if (boxes.empty()) {
        std::fprintf(out, ",,,,\n");
    } else {
        std::fprintf(out, ",%d,%d,%d,%d\n", boxes[0].x, boxes[0].y, boxes[0].width, boxes[0].height);
    }
}

// One frame through both detectors; truth boxes in colour pixels.
void runFrame(recon::FaceDetector& detector, const recon::RgbdFrame& frame, const recon::Intrinsics& k,
              const recon::ColourCamera& cam, const std::vector<cv::Rect>& truth, Tally& t,
              recon::FaceDetections* ours_out = nullptr) {
    cv::Mat grey;
    cv::cvtColor(frame.colour_bgr, grey, cv::COLOR_BGR2GRAY);
    auto t0 = Clock::now();
    StatusOr<recon::FaceDetections> ours = detector.detect(frame.depth_m, frame.colour_bgr, k, cam);
    t.ours_ms += msSince(t0);
    t0 = Clock::now();
    const std::vector<cv::Rect> stock = detector.detectStock(grey);
    t.stock_ms += msSince(t0);
    ++t.frames;
    writeBoxes(t.boxes_csv, t, frame, "stock", stock);
    if (!ours.isOk()) {
        std::fprintf(stderr, "detect: %s\n", ours.status().toString().c_str());
        writeBoxes(t.boxes_csv, t, frame, "ours", {});
        return;
    }
    writeBoxes(t.boxes_csv, t, frame, "ours", colourBoxes(*ours));
    t.ours_found += ours->faces.empty() ? 0 : 1;
    t.stock_found += stock.empty() ? 0 : 1;
    t.agree += dd::scoreDetections(stock, colourBoxes(*ours)).hits > 0 ? 1 : 0;
    t.candidates_ms += ours->candidates_ms;
    t.rejected += ours->rejected;
    t.ours.add(dd::scoreDetections(truth, colourBoxes(*ours)));
    t.stock.add(dd::scoreDetections(truth, stock));
    if (ours_out) *ours_out = *ours;
}

double maskIou(const cv::Mat& a, const cv::Mat& b) {
    const double inter = cv::countNonZero(a & b), uni = cv::countNonZero(a | b);
    return uni > 0 ? inter / uni : 0.0;
}

#ifdef FACESCAN_BENCH_HAVE_SYNTH
// Four sequences with the face (nose tip) at 0.5, 0.8, 1.1 and 1.5 m: SequenceParams::distance_m places the
// head-frame origin, 0.10 m behind the nose tip. The head turns +-25 deg and nods +-10 deg.
Tally runSynthetic(recon::FaceDetector& detector, int frames_per_distance, std::FILE* boxes_csv) {
    Tally t;
    t.name = "synthetic";
    t.boxes_csv = boxes_csv;
    const synth::HeadModel head = synth::defaultHead();
    std::printf("synthetic subject: %s\n", head.name.c_str());
    recon::HeadSegmenter segmenter;
    for (float distance : {0.6f, 0.9f, 1.2f, 1.6f}) {
        synth::SequenceParams p;
        p.frames = frames_per_distance;
        p.distance_m = distance;
        p.wall_distance_m = distance + 1.0f;
        p.yaw_amplitude_deg = 25.0f;
        p.pitch_amplitude_deg = 10.0f;
        p.yaw_period_frames = static_cast<float>(frames_per_distance);
        p.pitch_period_frames = static_cast<float>(frames_per_distance) / 2.0f;
        const synth::KinectSimulator sim(head, p);
        const recon::ColourCamera cam = recon::ColourCamera::registeredTo(sim.intrinsics());
        recon::RgbdFrame frame;
        synth::FrameTruth truth;
        for (int i = 0; i < frames_per_distance; ++i) {
            sim.render(i, frame, &truth);
            std::vector<cv::Rect> boxes;
            if (!truth.face_box_px.empty()) boxes.push_back(truth.face_box_px);
            recon::FaceDetections found;
            runFrame(detector, frame, sim.intrinsics(), cam, boxes, t, &found);
            if (found.faces.empty()) continue;
            recon::HeadSegmentation seg;
            const auto t0 = Clock::now();
            segmenter.segment(frame.depth_m, sim.intrinsics(), found.faces.front().box_depth_px, seg);
            t.segment_ms += msSince(t0);
            // Against the head label where the sensor measured depth: nothing else can be segmented.
            const cv::Mat head_label =
                (truth.label == static_cast<int>(synth::PixelLabel::kHead)) & (frame.depth_m > 0);
            const double iou = maskIou(seg.mask, head_label);
            ++t.segmented;
            ++t.iou_frames;
            t.iou_sum += iou;
            t.iou_min = std::min(t.iou_min, iou);
        }
    }
    return t;
}
#endif

Tally runBiwi(recon::FaceDetector& detector, const std::filesystem::path& dir, double& maskgen_ms,
              int& maskgen_zero_dets, std::FILE* boxes) {
    Tally t;
    t.name = "biwi";
    t.boxes_csv = boxes;
    const recon::Intrinsics k = dd::biwiDepthIntrinsics(dir);
    const recon::ColourCamera cam = dd::biwiColourCamera();
    recon::HeadSegmenter segmenter;
    maskgen_ms = 0;
    maskgen_zero_dets = 0;
    for (const auto& name : dd::biwiFrames(dir)) {
        recon::RgbdFrame frame;
        if (!dd::loadBiwiFrame(dir, name, frame)) continue;
        recon::FaceDetections found;
        runFrame(detector, frame, k, cam, {dd::biwiFaceBoxColour()}, t, &found);
        if (!found.faces.empty()) {
            recon::HeadSegmentation seg;
            const auto t0 = Clock::now();
            segmenter.segment(frame.depth_m, k, found.faces.front().box_depth_px, seg);
            t.segment_ms += msSince(t0);
            ++t.segmented;  // no head label on real frames: time only
        }
        // The MaskGenerator hook with an all-zero mask: if OpenCV honoured it, nothing could be found.
        cv::Mat grey;
        cv::cvtColor(frame.colour_bgr, grey, cv::COLOR_BGR2GRAY);
        const auto t0 = Clock::now();
        maskgen_zero_dets +=
            static_cast<int>(detector.detectWithMaskGenerator(grey, cv::Mat::zeros(grey.size(), CV_8U)).size());
        maskgen_ms += msSince(t0);
    }
    return t;
}

// tum:DIR: a recording without face boxes (intrinsics.txt or the Kinect defaults; colour registered to depth, as
// TUM's and `facescan-bench synth --tum` folders are). Speed, and how often each detector finds a face.
StatusOr<Tally> runTum(recon::FaceDetector& detector, const std::string& dir, int max_frames, std::FILE* boxes) {
    Sequence seq;
    RETURN_IF_ERROR(loadSequence("tum:" + dir, max_frames, seq));
    Tally t;
    t.name = std::filesystem::path(dir).filename().string();
    if (t.name.empty()) t.name = std::filesystem::path(dir).parent_path().filename().string();
    t.boxes_csv = boxes;
    const recon::ColourCamera cam = recon::ColourCamera::registeredTo(seq.k);
    int no_colour = 0;
    std::fprintf(stderr, "detect: %s: %zu frames\n", dir.c_str(), seq.frames.size());
    for (const recon::RgbdFrame& frame : seq.frames) {
        if (frame.colour_bgr.empty()) {
            ++no_colour;
            continue;
        }
        runFrame(detector, frame, seq.k, cam, {}, t);
    }
    if (t.frames == 0) {
        return invalidArgument("tum:" + dir + ": none of its " + std::to_string(no_colour) +
                               " frames has a colour image of the depth image's size (rgb.txt); the detector needs "
                               "colour");
    }
    if (no_colour > 0) std::fprintf(stderr, "detect: %s: %d frames without colour skipped\n", dir.c_str(), no_colour);
    return t;
}

void printUnlabelledRow(const Tally& t) {
    const double n = std::max(1, t.frames);
    std::printf("%-10s %6d %9.2f %9.2f %8.2fx   no face boxes: a face in %d (ours) / %d (stock) frames, agree in %d\n",
                t.name.c_str(), t.frames, t.ours_ms / n, t.stock_ms / n, t.ours_ms > 0 ? t.stock_ms / t.ours_ms : 0.0,
                t.ours_found, t.stock_found, t.agree);
}

struct DlibResult {
    int images = 0;
    double stock_ms = 0;
    dd::Score stock;
    int negative_false_positives = 0;
};

DlibResult runDlib(recon::FaceDetector& detector, const std::filesystem::path& dir) {
    DlibResult r;
    for (const char* xml : {"training.xml", "testing.xml"}) {
        for (const dd::LabelledImage& img : dd::loadDlibXml(dir / xml)) {
            const cv::Mat grey = cv::imread((dir / img.file).string(), cv::IMREAD_GRAYSCALE);
            if (grey.empty()) continue;
            const auto t0 = Clock::now();
            const std::vector<cv::Rect> found = detector.detectStock(grey);
            r.stock_ms += msSince(t0);
            ++r.images;
            r.stock.add(dd::scoreDetections(img.faces, found));
        }
    }
    const cv::Mat dogs = cv::imread((dir / "dogs.jpg").string(), cv::IMREAD_GRAYSCALE);
    if (!dogs.empty()) r.negative_false_positives = static_cast<int>(detector.detectStock(dogs).size());
    return r;
}

void printRow(const Tally& t) {
    const double n = std::max(1, t.frames);
    std::printf("%-10s %6d %9.2f %9.2f %8.2fx %7.3f %7.3f %6d %6d %8d", t.name.c_str(), t.frames, t.ours_ms / n,
                t.stock_ms / n, t.ours_ms > 0 ? t.stock_ms / t.ours_ms : 0.0, t.ours.recall(), t.stock.recall(),
                t.ours.false_positives, t.stock.false_positives, t.rejected);
    if (t.segmented > 0) std::printf("   seg %.2f ms", t.segment_ms / t.segmented);
    if (t.iou_frames > 0) std::printf(" head IoU mean %.3f min %.3f", t.iou_sum / t.iou_frames, t.iou_min);
    std::printf("\n");
}

int runDetect(const std::vector<std::string>& args) {
    bool json = false;
    int synth_frames = 30, max_frames = 0;
    std::vector<std::string> inputs;
    std::string boxes_path;
    for (size_t i = 0; i < args.size(); ++i) {
        if (args[i] == "--json") {
            json = true;
        } else if (args[i] == "--input" && i + 1 < args.size()) {
            inputs.push_back(args[++i]);
        } else if (args[i] == "--boxes" && i + 1 < args.size()) {
            boxes_path = args[++i];
        } else if (args[i] == "--frames" && i + 1 < args.size()) {
            max_frames = std::max(0, std::atoi(args[++i].c_str()));
        } else if (args[i] == "--help" || args[i] == "-h") {
            std::printf(
                "usage: facescan-bench detect [--input SRC]... [--frames N] [--boxes OUT.csv] [--json]\n"
                "  SRC: synthetic[:frames=N] (N per distance, faces at 0.5-1.5 m; default 30), biwi:DIR, dlib:DIR,\n"
                "       tum:DIR (a recording without face boxes: speed, frames with a face per detector, agreement).\n"
                "  Without --input: synthetic, biwi and dlib, from the shared data folder when present.\n"
                "  --frames N: at most N frames of a tum: recording (default all).\n"
                "  --boxes OUT.csv: source,frame,timestamp_s,detector,faces,x,y,w,h, one line per frame and detector\n"
                "    (ours | stock; the first box: ours' nearest face, stock's largest; colour pixels), to score\n"
                "    the boxes outside.\n");
            return 0;
        } else {
            std::fprintf(stderr, "detect: unknown argument '%s' (see --help)\n", args[i].c_str());
            return 2;
        }
    }
    if (inputs.empty()) {
        inputs.push_back("synthetic");
        if (auto d = testing::sharedData("biwi_subject01_5frames")) inputs.push_back("biwi:" + d->string());
        if (auto d = testing::sharedData("dlib_faces")) inputs.push_back("dlib:" + d->string());
    }
    StatusOr<recon::FaceDetector> made = recon::FaceDetector::create({});
    if (!made.isOk()) {
        std::fprintf(stderr, "detect: %s\n", made.status().toString().c_str());
        return 1;
    }
    recon::FaceDetector& detector = *made;
    std::FILE* boxes = nullptr;
    if (!boxes_path.empty()) {
        boxes = std::fopen(boxes_path.c_str(), "w");
        if (!boxes) {
            std::fprintf(stderr, "detect: cannot write --boxes %s: %s\n", boxes_path.c_str(), std::strerror(errno));
            return 1;
        }
        std::fprintf(boxes, "source,frame,timestamp_s,detector,faces,x,y,w,h\n");
    }
    struct Closer {
        std::FILE* f;
        ~Closer() {
            if (f) std::fclose(f);
        }
    } closer{boxes};
    const recon::FaceDetectorParams& p = detector.params();
    std::printf("cascade %s, scaleFactor %.2f, minNeighbors %d; W %.2f-%.2f m, theta %.2f m, IoU >= 0.3\n",
                p.cascade_path.c_str(), p.scale_factor, p.min_neighbours, static_cast<double>(p.face_width_min_m),
                static_cast<double>(p.face_width_max_m), static_cast<double>(p.boundary_jump_m));
    std::printf("%-10s %6s %9s %9s %9s %7s %7s %6s %6s %8s\n", "source", "frames", "ours_ms", "stock_ms", "speedup",
                "recall", "s_recl", "FP", "s_FP", "rejected");

    Tally all;
    all.name = "all-depth";
    std::vector<Tally> rows;
    DlibResult dlib;
    bool have_dlib = false;
    double maskgen_ms = 0;
    int maskgen_dets = -1, maskgen_frames = 0;
    for (const std::string& in : inputs) {
        Tally t;
        if (in.rfind("synthetic", 0) == 0) {
#ifdef FACESCAN_BENCH_HAVE_SYNTH
            if (const size_t pos = in.find("frames="); pos != std::string::npos) {
                synth_frames = std::max(1, std::atoi(in.c_str() + pos + 7));
            }
            t = runSynthetic(detector, synth_frames, boxes);
#else
            std::fprintf(stderr, "detect: built without facescan_synth; skipping %s\n", in.c_str());
            continue;
#endif
        } else if (in.rfind("biwi:", 0) == 0) {
            t = runBiwi(detector, in.substr(5), maskgen_ms, maskgen_dets, boxes);
            maskgen_frames = t.frames;
        } else if (in.rfind("tum:", 0) == 0) {
            StatusOr<Tally> tum = runTum(detector, in.substr(4), max_frames, boxes);
            if (!tum.isOk()) {
                std::fprintf(stderr, "detect: %s\n", tum.status().toString().c_str());
                return 1;
            }
            printUnlabelledRow(*tum);  // not in all-depth: without boxes it has no recall
            rows.push_back(*tum);
            continue;
        } else if (in.rfind("dlib:", 0) == 0) {
            dlib = runDlib(detector, in.substr(5));
            have_dlib = true;
            continue;
        } else {
            std::fprintf(stderr, "detect: unknown source '%s' (synthetic, biwi:DIR, dlib:DIR, tum:DIR)\n", in.c_str());
            return 2;
        }
        printRow(t);
        all.add(t);
        rows.push_back(t);
    }
    if (rows.size() > 1) printRow(all);
    if (have_dlib) {
        std::printf(
            "dlib (colour only, stock reference): %d images, %d faces, stock %.1f ms/image, recall %.3f, "
            "false positives %d (+%d on dogs.jpg)\n",
            dlib.images, dlib.stock.faces, dlib.images ? dlib.stock_ms / dlib.images : 0.0, dlib.stock.recall(),
            dlib.stock.false_positives, dlib.negative_false_positives);
    }
    if (maskgen_frames > 0) {
        std::printf("MaskGenerator hook, all-zero mask, biwi: %.1f ms/frame and %d detections (%s)\n",
                    maskgen_ms / maskgen_frames, maskgen_dets,
                    maskgen_dets > 0 ? "the mask is ignored by OpenCV's CPU path: no pruning" : "honoured");
    }
    if (json) {
        const double n = std::max(1, all.frames);
        std::printf(
            "{\"frames\":%d,\"ours_ms\":%.3f,\"stock_ms\":%.3f,\"speedup\":%.3f,\"recall\":%.4f,"
            "\"stock_recall\":%.4f,\"false_positives\":%d,\"stock_false_positives\":%d,"
            "\"segment_ms\":%.3f,\"head_iou\":%.4f,\"head_iou_min\":%.4f,\"sources\":{",
            all.frames, all.ours_ms / n, all.stock_ms / n, all.ours_ms > 0 ? all.stock_ms / all.ours_ms : 0.0,
            all.ours.recall(), all.stock.recall(), all.ours.false_positives, all.stock.false_positives,
            all.segmented ? all.segment_ms / all.segmented : 0.0,
            all.iou_frames > 0 ? all.iou_sum / all.iou_frames : 0.0, all.iou_frames > 0 ? all.iou_min : 0.0);
        bool first = true;
        for (const Tally& t : rows) {
            const double m = std::max(1, t.frames);
            std::printf(
                "%s\"%s\":{\"frames\":%d,\"ours_ms\":%.3f,\"stock_ms\":%.3f,\"speedup\":%.3f,\"recall\":%.4f,"
                "\"stock_recall\":%.4f,\"false_positives\":%d,\"stock_false_positives\":%d,\"ours_found\":%d,"
                "\"stock_found\":%d,\"agree\":%d}",
                first ? "" : ",", t.name.c_str(), t.frames, t.ours_ms / m, t.stock_ms / m,
                t.ours_ms > 0 ? t.stock_ms / t.ours_ms : 0.0, t.ours.recall(), t.stock.recall(), t.ours.false_positives,
                t.stock.false_positives, t.ours_found, t.stock_found, t.agree);
            first = false;
        }
        if (have_dlib) {
            std::printf(
                "%s\"dlib\":{\"frames\":%d,\"faces\":%d,\"stock_ms\":%.3f,\"stock_recall\":%.4f,"
                "\"stock_false_positives\":%d,\"stock_negative_false_positives\":%d}",
                first ? "" : ",", dlib.images, dlib.stock.faces, dlib.images ? dlib.stock_ms / dlib.images : 0.0,
                dlib.stock.recall(), dlib.stock.false_positives, dlib.negative_false_positives);
        }
        std::printf("}");
        if (maskgen_frames > 0) {
            std::printf(",\"maskgen_ms\":%.3f,\"maskgen_zero_mask_detections\":%d", maskgen_ms / maskgen_frames,
                        maskgen_dets);
        }
        std::printf("}\n");
    }
    return 0;
}

}  // namespace

FACESCAN_BENCH_COMMAND("detect", "depth-accelerated face detection vs stock detectMultiScale (+ segmentation)",
                       runDetect);

}  // namespace facescan::bench
