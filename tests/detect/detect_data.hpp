// Loaders and scoring for the detection tests and `facescan-bench detect`: Biwi frames, the PCL person frame,
// dlib's labelled photos, and IoU matching. Header-only so the bench can include it too.
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/face_detector.hpp"
#include "recon/frame.hpp"

namespace facescan::detect_data {

namespace fs = std::filesystem;

// Biwi Kinect Head Pose database, subject 01. Depth intrinsics from the folder's intrinsics.txt; the colour camera
// from Biwi's rgb.cal for subject 01 (not shipped in the data folder): f = 517.679 px, c = (320, 240.5), and the
// depth-to-colour extrinsics R ~ I, t = (-24.06, 5.07, -4.07) mm, used as p_colour = R p_depth + t. The data pick
// this direction: mapped this way the cascade's face box lands centred on the depth head (355 vs 351 px); the
// inverse puts it 17 px left and 26 px low (on the chin). BiwiDetect.FaceBoxMapsOntoDepthHead checks it.
inline recon::Intrinsics biwiDepthIntrinsics(const fs::path& dir) {
    recon::Intrinsics k;
    std::ifstream in(dir / "intrinsics.txt");
    float fx = 575.816f, fy = 575.816f, cx = 320.0f, cy = 240.0f;
    if (in) in >> fx >> fy >> cx >> cy;
    k.fx_px = fx, k.fy_px = fy, k.cx_px = cx, k.cy_px = cy;
    return k;
}

inline recon::ColourCamera biwiColourCamera() {
    recon::ColourCamera c;
    c.registered = false;
    c.intrinsics.fx_px = c.intrinsics.fy_px = 517.679f;
    c.intrinsics.cx_px = 320.0f;
    c.intrinsics.cy_px = 240.5f;
    Eigen::Matrix3f r;
    r << 0.999947f, 0.00432361f, 0.00929419f, -0.00446314f, 0.999877f, 0.0150443f, -0.00922785f, -0.0150851f, 0.999843f;
    const Eigen::Vector3f t(-0.0240571f, 0.00506651f, -0.00407278f);
    c.T_colour_depth = recon::Pose::Identity();
    c.T_colour_depth.linear() = r;
    c.T_colour_depth.translation() = t;
    return c;
}

inline std::vector<fs::path> biwiFrames(const fs::path& dir) {
    std::vector<fs::path> frames;
    if (!fs::is_directory(dir / "depth")) return frames;
    for (const auto& e : fs::directory_iterator(dir / "depth")) {
        if (e.path().extension() == ".png") frames.push_back(e.path().filename());
    }
    std::sort(frames.begin(), frames.end());
    return frames;
}

// One Biwi frame: 16-bit mm depth -> metres, colour BGR (not registered).
inline bool loadBiwiFrame(const fs::path& dir, const fs::path& name, recon::RgbdFrame& frame) {
    const cv::Mat raw = cv::imread((dir / "depth" / name).string(), cv::IMREAD_ANYDEPTH);
    frame.colour_bgr = cv::imread((dir / "rgb" / name).string(), cv::IMREAD_COLOR);
    if (raw.empty() || raw.type() != CV_16UC1 || frame.colour_bgr.empty()) return false;
    recon::depthRawToMetres(raw, 0.001f, frame.depth_m);
    return true;
}

// Hand-labelled face box of the (static) Biwi subject 01 frames in the colour image: hairline to chin, ear to ear
// excluded, read off frame 0. Used only for scoring at IoU >= 0.3.
inline cv::Rect biwiFaceBoxColour() { return {293, 205, 100, 110}; }

// PCL's person frame: 16-bit mm depth, fx = fy = 525, c = (319.5, 239.5) (README of the folder).
inline recon::Intrinsics pclIntrinsics() {
    recon::Intrinsics k;
    k.fx_px = k.fy_px = 525.0f;
    k.cx_px = 319.5f;
    k.cy_px = 239.5f;
    return k;
}

struct LabelledImage {
    std::string file;
    std::vector<cv::Rect> faces;
};

// dlib's imglab XML (<image file='..'><box top left width height/>...).
inline std::vector<LabelledImage> loadDlibXml(const fs::path& xml) {
    std::ifstream in(xml);
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string text = ss.str();
    std::vector<LabelledImage> images;
    static const std::regex image_re("<image file='([^']+)'");
    static const std::regex box_re("<box top='(-?\\d+)' left='(-?\\d+)' width='(\\d+)' height='(\\d+)'");
    size_t pos = 0;
    while (true) {
        const size_t start = text.find("<image ", pos);
        if (start == std::string::npos) break;
        size_t end = text.find("</image>", start);
        if (end == std::string::npos) end = text.size();
        const std::string block = text.substr(start, end - start);
        std::smatch m;
        if (std::regex_search(block, m, image_re)) {
            LabelledImage img;
            img.file = m[1];
            for (auto it = std::sregex_iterator(block.begin(), block.end(), box_re); it != std::sregex_iterator();
                 ++it) {
                img.faces.emplace_back(std::stoi((*it)[2]), std::stoi((*it)[1]), std::stoi((*it)[3]),
                                       std::stoi((*it)[4]));
            }
            images.push_back(img);
        }
        pos = end;
    }
    return images;
}

inline double iou(const cv::Rect& a, const cv::Rect& b) {
    const double inter = (a & b).area();
    const double uni = a.area() + b.area() - inter;
    return uni > 0 ? inter / uni : 0.0;
}

struct Score {
    int faces = 0;            // ground-truth faces
    int hits = 0;             // matched (IoU >= threshold), each truth at most once
    int false_positives = 0;  // detections matching no unmatched truth
    void add(const Score& s) { faces += s.faces, hits += s.hits, false_positives += s.false_positives; }
    double recall() const { return faces ? static_cast<double>(hits) / faces : 0.0; }
};

// Greedy one-to-one matching by best IoU.
inline Score scoreDetections(const std::vector<cv::Rect>& truth, const std::vector<cv::Rect>& found,
                             double min_iou = 0.3) {
    Score s;
    s.faces = static_cast<int>(truth.size());
    std::vector<bool> used(truth.size(), false);
    for (const cv::Rect& d : found) {
        int best = -1;
        double best_iou = min_iou;
        for (size_t i = 0; i < truth.size(); ++i) {
            const double v = iou(d, truth[i]);
            if (!used[i] && v >= best_iou) best_iou = v, best = static_cast<int>(i);
        }
        if (best >= 0) {
            used[static_cast<size_t>(best)] = true;
            ++s.hits;
        } else {
            ++s.false_positives;
        }
    }
    return s;
}

}  // namespace facescan::detect_data
