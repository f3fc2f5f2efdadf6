// facescan-bench codecs: the payload codecs of the wire on real and synthetic frames.
// Depth: every lossless codec (and zstd levels) per data set: ratio, encode and decode ms (mean per frame after a
// warm-up; thread CPU ms, see Clock), checked bit-exact. Colour: TurboJPEG against OpenCV's imencode at the same
// quality. Mesh: Draco on a ~200k-triangle head (Lee Perry-Smith scan, metres, Loop + sqrt(3) subdivision, texture
// colours). JSON keys (docs/design.md s6): depth{codec,ratio,encode_ms,decode_ms} colour{...}
// mesh{bytes,encode_ms,decode_ms}; per-codec detail under depth_sets{set:{codec:{ratio,encode_ms,decode_ms}}}.
#include <draco/compression/decode.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "bench_command.hpp"
#include "recon_input.hpp"
#include "test_data.hpp"
#include "wire/codecs.hpp"
// clang-format off
// OpenMesh's subdividers only compile after the mesh kernel headers (pulled in by wire/codecs.hpp) are seen.
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/Sqrt3T.hh>
// clang-format on

#if __has_include(<synth/kinect_simulator.hpp>)
#include "synth/kinect_simulator.hpp"
#define FACESCAN_BENCH_HAS_SYNTH 1
#endif

namespace facescan::bench {
namespace {

namespace fs = std::filesystem;
// Codec calls are single-threaded: time them as CPU time of the calling thread, which a busy shared machine
// (CI, or engineers building beside the bench) does not inflate with preemption; on an idle machine it is wall time.
struct Clock {
    using time_point = double;  // milliseconds
    static time_point now() {
        timespec ts{};
        clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
        return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
    }
};

struct DataSet {
    std::string name;
    std::vector<cv::Mat> depth;   // CV_16UC1, millimetres (tum:, 7scenes: inputs: 0.2 mm)
    std::vector<cv::Mat> colour;  // CV_8UC3 (may be empty)
};

struct Figures {
    double ratio = 0;
    double encode_ms = 0;
    double decode_ms = 0;
    size_t bytes = 0;  // mean payload bytes
};

double msSince(Clock::time_point t0) { return Clock::now() - t0; }

std::vector<fs::path> sortedFiles(const fs::path& dir, const std::string& suffix) {
    std::vector<fs::path> files;
    if (!fs::is_directory(dir)) return files;
    for (const auto& e : fs::directory_iterator(dir)) {
        const std::string name = e.path().filename().string();
        if (name.size() >= suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0) {
            files.push_back(e.path());
        }
    }
    std::sort(files.begin(), files.end());
    return files;
}

void addFrames(DataSet& set, const std::vector<fs::path>& depth_files, const std::vector<fs::path>& colour_files,
               size_t max_frames) {
    for (size_t i = 0; i < depth_files.size() && set.depth.size() < max_frames; ++i) {
        cv::Mat d = cv::imread(depth_files[i].string(), cv::IMREAD_UNCHANGED);
        if (d.type() == CV_16UC1) set.depth.push_back(d);
        if (i < colour_files.size()) {
            cv::Mat c = cv::imread(colour_files[i].string(), cv::IMREAD_COLOR);
            if (!c.empty()) set.colour.push_back(c);
        }
    }
}

std::vector<DataSet> loadDataSets(const std::string& input, size_t max_frames) {
    std::vector<DataSet> sets;
    const auto data = testing::sharedDataDir();
    auto want = [&](const std::string& name) { return input == "all" || input == name; };
#ifdef FACESCAN_BENCH_HAS_SYNTH
    if (want("synthetic")) {
        // Face range: the head at 0.7 m turning, torso and wall behind, Kinect v1 noise; millimetre units as OpenNI.
        synth::SequenceParams seq;
        seq.frames = static_cast<int>(max_frames);
        const synth::KinectSimulator sim(synth::defaultHead(), seq);
        DataSet set{"synthetic", {}, {}};
        recon::RgbdFrame frame;
        for (int i = 0; i < seq.frames; ++i) {
            sim.render(i * 7, frame);  // spread over the head's turn
            cv::Mat raw;
            recon::depthMetresToRaw(frame.depth_m, 0.001f, raw);
            set.depth.push_back(raw);
            if (!frame.colour_bgr.empty()) set.colour.push_back(frame.colour_bgr.clone());
        }
        sets.push_back(std::move(set));
    }
#endif
    if (data && want("biwi")) {
        DataSet set{"biwi", {}, {}};
        addFrames(set, sortedFiles(*data / "biwi_subject01_5frames/depth", ".png"),
                  sortedFiles(*data / "biwi_subject01_5frames/rgb", ".png"), max_frames);
        if (!set.depth.empty()) sets.push_back(std::move(set));
    }
    if (data && want("7scenes")) {
        DataSet set{"7scenes", {}, {}};
        addFrames(set, sortedFiles(*data / "7scenes_tsdf_fusion/rgbd-frames", ".depth.png"),
                  sortedFiles(*data / "7scenes_tsdf_fusion/rgbd-frames", ".color.png"), max_frames);
        if (!set.depth.empty()) sets.push_back(std::move(set));
    }
    if (data && want("pcl")) {
        DataSet set{"pcl-person", {}, {}};
        addFrames(set, {*data / "pcl_kinect_person/person_depth_mm.png"}, {}, max_frames);
        if (!set.depth.empty()) sets.push_back(std::move(set));
    }
    if (input.rfind("tum:", 0) == 0 || input.rfind("7scenes:", 0) == 0) {
        // A recording, read by the same loader as `recon --input`. The codecs are lossless, so the units the frames
        // are re-quantised to (0.2 mm, TUM's 5000 per metre, what the agent sends for tum: sources) only matter
        // through how many distinct values a frame holds; that is the recording's own quantisation here.
        Sequence seq;
        if (const Status s = loadSequence(input, static_cast<int>(max_frames), seq); !s.isOk()) {
            std::fprintf(stderr, "codecs: %s\n", s.toString().c_str());
            return sets;
        }
        DataSet set{fs::path(input.substr(input.find(':') + 1)).filename().string(), {}, {}};
        for (const recon::RgbdFrame& f : seq.frames) {
            cv::Mat raw;
            recon::depthMetresToRaw(f.depth_m, 1.0f / 5000.0f, raw);
            set.depth.push_back(raw);
            if (!f.colour_bgr.empty()) set.colour.push_back(f.colour_bgr);
        }
        if (!set.depth.empty()) sets.push_back(std::move(set));
        return sets;
    }
    if (sets.empty() && fs::is_directory(input)) {  // a folder of 16-bit PNGs
        DataSet set{fs::path(input).filename().string(), {}, {}};
        addFrames(set, sortedFiles(input, ".png"), {}, max_frames);
        if (!set.depth.empty()) sets.push_back(std::move(set));
    }
    return sets;
}

struct DepthVariant {
    std::string label;
    wire::DepthCodecParams params;
};

std::vector<DepthVariant> depthVariants() {
    std::vector<DepthVariant> v;
    for (int c = 0; c < wire::kDepthCodecCount; ++c) {
        wire::DepthCodecParams p;
        p.codec = static_cast<wire::DepthCodecId>(c);
        v.push_back({wire::depthCodecName(p.codec), p});
    }
    for (const auto codec : {wire::DepthCodecId::kRvlZstd, wire::DepthCodecId::kDeltaZstd}) {
        for (const int level : {-3, 3}) {
            wire::DepthCodecParams p;
            p.codec = codec;
            p.zstd_level = level;
            v.push_back({std::string(wire::depthCodecName(codec)) + "@" + std::to_string(level), p});
        }
    }
    for (const int step : {0, 8, 128}) {  // the match-finder step of the packed codec (default 32)
        wire::DepthCodecParams p;
        p.codec = wire::DepthCodecId::kPackedDeltaZstd;
        p.zstd_fast_step = step;
        v.push_back({"packed-delta-zstd/step" + std::to_string(step), p});
    }
    return v;
}

// Mean per frame over `repeat` passes after one warm-up pass; false when a round trip is not bit-exact.
bool measureDepth(const DataSet& set, const wire::DepthCodecParams& params, int repeat, Figures& f) {
    wire::DepthEncoder encoder(params);
    wire::DepthDecoder decoder;
    std::vector<std::vector<uint8_t>> payloads(set.depth.size());
    cv::Mat decoded;
    double raw_bytes = 0;
    double coded_bytes = 0;
    for (size_t i = 0; i < set.depth.size(); ++i) {  // warm-up + exactness
        const cv::Mat& d = set.depth[i];
        if (!encoder.encode(d, payloads[i]).isOk()) return false;
        if (!decoder.decode(params.codec, payloads[i].data(), payloads[i].size(), d.cols, d.rows, decoded).isOk())
            return false;
        if (cv::norm(decoded, d, cv::NORM_INF) != 0.0) return false;
        raw_bytes += 2.0 * double(d.total());
        coded_bytes += double(payloads[i].size());
    }
    const double n = double(repeat) * double(set.depth.size());
    auto t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) {
        for (size_t i = 0; i < set.depth.size(); ++i) (void)encoder.encode(set.depth[i], payloads[i]);
    }
    f.encode_ms = msSince(t0) / n;
    t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) {
        for (size_t i = 0; i < set.depth.size(); ++i) {
            (void)decoder.decode(params.codec, payloads[i].data(), payloads[i].size(), set.depth[i].cols,
                                 set.depth[i].rows, decoded);
        }
    }
    f.decode_ms = msSince(t0) / n;
    f.ratio = raw_bytes / coded_bytes;
    f.bytes = static_cast<size_t>(coded_bytes / double(set.depth.size()));
    return true;
}

// TurboJPEG (our codec) and OpenCV imencode/imdecode at the same quality.
void measureColour(const std::vector<cv::Mat>& frames, int quality, int repeat, Figures& turbo, Figures& opencv) {
    wire::ColourJpegParams params;
    params.quality = quality;
    wire::ColourJpegEncoder encoder(params);
    wire::ColourJpegDecoder decoder;
    std::vector<uint8_t> bytes;
    cv::Mat out;
    double raw = 0;
    double coded = 0;
    for (const auto& f : frames) {
        (void)encoder.encode(f, bytes);
        raw += 3.0 * double(f.total());
        coded += double(bytes.size());
    }
    const double n = double(repeat) * double(frames.size());
    auto t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) {
        for (const auto& f : frames) (void)encoder.encode(f, bytes);
    }
    turbo.encode_ms = msSince(t0) / n;
    std::vector<std::vector<uint8_t>> coded_frames;
    for (const auto& f : frames) {
        (void)encoder.encode(f, bytes);
        coded_frames.push_back(bytes);
    }
    t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) {
        for (size_t i = 0; i < frames.size(); ++i) {
            (void)decoder.decode(coded_frames[i].data(), coded_frames[i].size(), frames[i].cols, frames[i].rows, out);
        }
    }
    turbo.decode_ms = msSince(t0) / n;
    turbo.ratio = raw / coded;
    turbo.bytes = static_cast<size_t>(coded / double(frames.size()));

    const std::vector<int> cv_params = {cv::IMWRITE_JPEG_QUALITY, quality};
    coded = 0;
    for (const auto& f : frames) {
        cv::imencode(".jpg", f, bytes, cv_params);
        coded += double(bytes.size());
    }
    t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) {
        for (const auto& f : frames) cv::imencode(".jpg", f, bytes, cv_params);
    }
    opencv.encode_ms = msSince(t0) / n;
    t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) {
        for (const auto& c : coded_frames) out = cv::imdecode(c, cv::IMREAD_COLOR);
    }
    opencv.decode_ms = msSince(t0) / n;
    opencv.ratio = raw / coded;
    opencv.bytes = static_cast<size_t>(coded / double(frames.size()));
}

struct MeshFigures {
    size_t triangles = 0;
    size_t vertices = 0;
    size_t bytes = 0;
    double encode_ms = 0;
    double decode_ms = 0;
    double max_error_mm = 0;
};

// The Lee Perry-Smith head in metres, subdivided to ~212k triangles (one Loop step: 4x faces, one sqrt(3) step: 3x),
// coloured from its texture at the original vertices and by neighbour averaging at the new ones.
bool makeHeadMesh(recon::Mesh& mesh) {
    const auto dir = testing::sharedData("leeperrysmith");
    if (!dir) return false;
    mesh.request_vertex_texcoords2D();
    OpenMesh::IO::Options opt = OpenMesh::IO::Options::VertexTexCoord;
    if (!OpenMesh::IO::read_mesh(mesh, (*dir / "LeePerrySmith_converted.ply").string(), opt)) return false;
    const cv::Mat texture = cv::imread((*dir / "Map-COL.jpg").string(), cv::IMREAD_COLOR);
    const size_t original = mesh.n_vertices();
    for (const auto vh : mesh.vertices()) {
        mesh.set_point(vh, mesh.point(vh) * 0.049f);
        OpenMesh::Vec3uc c(200, 160, 140);
        if (!texture.empty() && opt.vertex_has_texcoord()) {
            const auto uv = mesh.texcoord2D(vh);
            const int x = std::clamp(int(uv[0] * float(texture.cols)), 0, texture.cols - 1);
            const int y = std::clamp(int(uv[1] * float(texture.rows)), 0, texture.rows - 1);
            const cv::Vec3b bgr = texture.at<cv::Vec3b>(y, x);
            c = OpenMesh::Vec3uc(bgr[2], bgr[1], bgr[0]);
        }
        mesh.set_color(vh, c);
    }
    mesh.release_vertex_texcoords2D();
    OpenMesh::Subdivider::Uniform::LoopT<recon::Mesh> loop;
    OpenMesh::Subdivider::Uniform::Sqrt3T<recon::Mesh> sqrt3;
    if (!loop.attach(mesh) || !loop(1)) return false;
    loop.detach();
    if (!sqrt3.attach(mesh) || !sqrt3(1)) return false;
    sqrt3.detach();
    mesh.garbage_collection();
    // New vertices (index >= original) take the mean colour of already-coloured neighbours, in waves.
    std::vector<char> known(mesh.n_vertices(), 0);
    for (size_t i = 0; i < original && i < known.size(); ++i) known[i] = 1;
    for (bool changed = true; changed;) {
        changed = false;
        std::vector<std::pair<recon::Mesh::VertexHandle, OpenMesh::Vec3uc>> updates;
        for (const auto vh : mesh.vertices()) {
            if (known[vh.idx()]) continue;
            OpenMesh::Vec3f sum(0, 0, 0);
            int count = 0;
            for (const auto nb : mesh.vv_range(vh)) {
                if (known[nb.idx()]) sum += OpenMesh::Vec3f(mesh.color(nb)), ++count;
            }
            if (count > 0) updates.emplace_back(vh, OpenMesh::Vec3uc(sum / float(count)));
        }
        for (const auto& [vh, c] : updates) mesh.set_color(vh, c), known[vh.idx()] = 1, changed = true;
    }
    mesh.update_normals();
    return true;
}

bool measureMesh(const recon::Mesh& mesh, int repeat, MeshFigures& f) {
    std::vector<uint8_t> bytes;
    const wire::MeshCodecParams params;
    if (!wire::encodeMeshDraco(mesh, params, bytes).isOk()) return false;
    recon::Mesh decoded;
    if (!wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded).isOk()) return false;
    auto t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) (void)wire::encodeMeshDraco(mesh, params, bytes);
    f.encode_ms = msSince(t0) / repeat;
    t0 = Clock::now();
    for (int r = 0; r < repeat; ++r) (void)wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded);
    f.decode_ms = msSince(t0) / repeat;
    f.bytes = bytes.size();
    f.triangles = mesh.n_faces();
    f.vertices = mesh.n_vertices();
    // Position error: a copy whose colours are vertex ids (colours are lossless) identifies each decoded vertex.
    recon::Mesh ids = mesh;
    for (const auto vh : ids.vertices()) {
        const auto i = static_cast<uint32_t>(vh.idx());
        ids.set_color(vh, OpenMesh::Vec3uc(uint8_t(i), uint8_t(i >> 8), uint8_t(i >> 16)));
    }
    if (!wire::encodeMeshDraco(ids, params, bytes).isOk()) return false;
    if (!wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded).isOk()) return false;
    for (const auto vh : decoded.vertices()) {
        const auto c = decoded.color(vh);
        const int i = c[0] | c[1] << 8 | c[2] << 16;
        if (i >= int(mesh.n_vertices())) return false;
        const float e = (decoded.point(vh) - mesh.point(recon::Mesh::VertexHandle(i))).norm();
        f.max_error_mm = std::max(f.max_error_mm, 1000.0 * double(e));
    }
    return true;
}

// What each attribute costs, at Draco's best compression (speed 0), the shipped speed and its fastest (10): the
// evidence for which of the mesh targets (150 KB, 30 ms, 15 ms for ~200k triangles) Draco can reach at all at
// the required position error. "draco" decode is Draco's own decoder alone, without building the OpenMesh mesh.
void printMeshBreakdown(const recon::Mesh& mesh) {
    std::printf("  per attribute (positions at the error bound; normals 10 bits; colours 8-bit):\n");
    std::printf("  %-26s %6s %10s %10s %10s %12s\n", "attributes", "speed", "KB", "encode_ms", "decode_ms",
                "draco_dec_ms");
    struct Row {
        const char* name;
        bool normals;
        bool colours;
    };
    for (const Row row : {Row{"positions", false, false}, Row{"positions+colours", false, true},
                          Row{"positions+colours+normals", true, true}}) {
        for (const int speed : {0, wire::MeshCodecParams{}.speed, 10}) {
            wire::MeshCodecParams p;
            p.speed = speed;
            p.colours = row.colours;
            p.normal_bits = row.normals ? 10 : 0;
            std::vector<uint8_t> bytes;
            auto t0 = Clock::now();
            if (!wire::encodeMeshDraco(mesh, p, bytes).isOk()) continue;
            const double encode_ms = msSince(t0);
            recon::Mesh decoded;
            t0 = Clock::now();
            if (!wire::decodeMeshDraco(bytes.data(), bytes.size(), decoded).isOk()) continue;
            const double decode_ms = msSince(t0);
            draco::DecoderBuffer buffer;
            buffer.Init(reinterpret_cast<const char*>(bytes.data()), bytes.size());
            draco::Decoder decoder;
            t0 = Clock::now();
            const bool ok = decoder.DecodeMeshFromBuffer(&buffer).ok();
            const double draco_ms = msSince(t0);
            std::printf("  %-26s %6d %10.1f %10.2f %10.2f %12.2f%s\n", row.name, speed, double(bytes.size()) / 1024.0,
                        encode_ms, decode_ms, draco_ms, ok ? "" : " (draco failed)");
        }
    }
}

std::string jsonFigures(const Figures& f) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "\"ratio\":%.3f,\"encode_ms\":%.4f,\"decode_ms\":%.4f,\"bytes\":%zu", f.ratio,
                  f.encode_ms, f.decode_ms, f.bytes);
    return buf;
}

int runCodecs(const std::vector<std::string>& args) {
    std::string input = "all";
    bool json = false;
    int frames = 20;
    int repeat = 5;
    int quality = wire::ColourJpegParams{}.quality;
    bool mesh_breakdown = false;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const bool has_value = i + 1 < args.size();
        if (a == "--json")
            json = true;
        else if (a == "--input" && has_value)
            input = args[++i];
        else if (a == "--frames" && has_value)
            frames = std::max(1, std::stoi(args[++i]));
        else if (a == "--repeat" && has_value)
            repeat = std::max(1, std::stoi(args[++i]));
        else if (a == "--mesh-breakdown")
            mesh_breakdown = true;
        else if (a == "--quality" && has_value)
            quality = std::clamp(std::stoi(args[++i]), 1, 100);
        else {
            std::printf(
                "usage: facescan-bench codecs [--input all|synthetic|biwi|7scenes|pcl|tum:DIR|7scenes:DIR|DIR]\n"
                "                             [--frames N] [--repeat R]\n"
                "                             [--quality Q] [--mesh-breakdown] [--json]\n"
                "Depth codecs (ratio, encode/decode ms per frame, bit-exact checked), JPEG colour (TurboJPEG vs\n"
                "OpenCV), Draco on a ~200k-triangle head. Means over R passes after a warm-up pass.\n"
                "--mesh-breakdown: Draco size and time per attribute set at speeds 0, 7 and 10.\n");
            return a == "--help" ? 0 : 2;
        }
    }
    const std::vector<DataSet> sets = loadDataSets(input, static_cast<size_t>(frames));
    if (sets.empty()) {
        const bool recording = input.rfind("tum:", 0) == 0 || input.rfind("7scenes:", 0) == 0;
        std::fprintf(stderr, "codecs: no frames for --input %s (%s)\n", input.c_str(),
                     recording ? "the reason is above" : "shared data missing, or no 16-bit depth PNGs there?");
        return 1;
    }
    const wire::DepthCodecParams shipped;
    std::string json_sets;
    Figures default_depth;
    std::string default_set;
    for (const auto& set : sets) {
        std::printf("\ndepth: %s (%zu frames %dx%d, raw %.0f KB/frame)\n", set.name.c_str(), set.depth.size(),
                    set.depth[0].cols, set.depth[0].rows, 2.0 * double(set.depth[0].total()) / 1024.0);
        std::printf("  %-26s %8s %10s %10s %10s\n", "codec", "ratio", "KB/frame", "encode_ms", "decode_ms");
        std::string json_codecs;
        for (const auto& v : depthVariants()) {
            Figures f;
            if (!measureDepth(set, v.params, repeat, f)) {
                std::fprintf(stderr, "codecs: %s failed or was not bit-exact on %s\n", v.label.c_str(),
                             set.name.c_str());
                return 1;
            }
            const bool is_default = v.params.codec == shipped.codec && v.params.zstd_level == shipped.zstd_level &&
                                    v.params.zstd_fast_step == shipped.zstd_fast_step;
            std::printf("  %-26s %8.2f %10.1f %10.3f %10.3f%s\n", v.label.c_str(), f.ratio, double(f.bytes) / 1024.0,
                        f.encode_ms, f.decode_ms, is_default ? "  (default)" : "");
            json_codecs += (json_codecs.empty() ? "" : ",") + ("\"" + v.label + "\":{" + jsonFigures(f) + "}");
            if (is_default && default_set.empty()) default_depth = f, default_set = set.name;  // first set = face range
        }
        json_sets += (json_sets.empty() ? "" : ",") + ("\"" + set.name + "\":{" + json_codecs + "}");
    }

    std::vector<cv::Mat> colour_frames;
    std::string colour_set;
    for (const auto& set : sets) {
        if (!set.colour.empty() && colour_frames.empty()) colour_frames = set.colour, colour_set = set.name;
    }
    Figures turbo;
    Figures opencv;
    if (!colour_frames.empty()) {
        measureColour(colour_frames, quality, repeat, turbo, opencv);
        std::printf("\ncolour: %s (%zu frames %dx%d), JPEG quality %d\n", colour_set.c_str(), colour_frames.size(),
                    colour_frames[0].cols, colour_frames[0].rows, quality);
        std::printf("  %-16s %8s %10s %10s %10s\n", "codec", "ratio", "KB/frame", "encode_ms", "decode_ms");
        std::printf("  %-16s %8.2f %10.1f %10.3f %10.3f  (default)\n", "turbojpeg", turbo.ratio,
                    double(turbo.bytes) / 1024.0, turbo.encode_ms, turbo.decode_ms);
        std::printf("  %-16s %8.2f %10.1f %10.3f %10.3f\n", "opencv-imencode", opencv.ratio,
                    double(opencv.bytes) / 1024.0, opencv.encode_ms, opencv.decode_ms);
    }

    MeshFigures mesh_f;
    recon::Mesh head;
    const bool have_mesh = makeHeadMesh(head) && measureMesh(head, std::max(1, repeat / 2), mesh_f);
    if (have_mesh) {
        std::printf("\nmesh: Lee Perry-Smith head subdivided, %zu vertices, %zu triangles (Draco speed %d)\n",
                    mesh_f.vertices, mesh_f.triangles, wire::MeshCodecParams{}.speed);
        std::printf("  %10s %10s %10s %14s\n", "KB", "encode_ms", "decode_ms", "max_error_mm");
        std::printf("  %10.1f %10.2f %10.2f %14.4f\n", double(mesh_f.bytes) / 1024.0, mesh_f.encode_ms,
                    mesh_f.decode_ms, mesh_f.max_error_mm);
        if (mesh_breakdown) printMeshBreakdown(head);
    } else {
        std::printf("\nmesh: skipped (shared data leeperrysmith missing)\n");
    }

    if (json) {
        std::printf("{\"depth\":{\"codec\":\"%s\",\"set\":\"%s\",%s},", wire::depthCodecName(shipped.codec),
                    default_set.c_str(), jsonFigures(default_depth).c_str());
        std::printf("\"colour\":{\"codec\":\"jpeg\",\"quality\":%d,\"set\":\"%s\",%s,\"opencv\":{%s}},", quality,
                    colour_set.c_str(), jsonFigures(turbo).c_str(), jsonFigures(opencv).c_str());
        if (have_mesh) {
            std::printf(
                "\"mesh\":{\"bytes\":%zu,\"encode_ms\":%.3f,\"decode_ms\":%.3f,\"triangles\":%zu,"
                "\"max_error_mm\":%.5f},",
                mesh_f.bytes, mesh_f.encode_ms, mesh_f.decode_ms, mesh_f.triangles, mesh_f.max_error_mm);
        } else {
            std::printf("\"mesh\":null,");
        }
        std::printf("\"depth_sets\":{%s}}\n", json_sets.c_str());
    }
    return 0;
}

}  // namespace

FACESCAN_BENCH_COMMAND("codecs", "depth/colour/mesh codecs: ratio, encode and decode ms", runCodecs);

}  // namespace facescan::bench
