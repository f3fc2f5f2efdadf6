// The finishing stage (finishing.hpp): parameters, their parsing, the report, and the steps in order.
#include "recon/finishing.hpp"

#include <time.h>

#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "recon/parallel.hpp"

namespace facescan::recon {
namespace {

// The report's distance is measured from at most this many of the full mesh's vertices (every k-th): a p99 over
// 30,000 samples is as good as over all 100,000, at a third of the time the server's finish spends on it.
constexpr size_t kDistanceSamples = 30'000;

double msSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.4g", v);
    return buf;
}

std::string jsonEscape(const std::string& s) {
    std::string out;
    for (const char c : s) {
        if (c == '"' || c == '\\') out += '\\';
        if (static_cast<unsigned char>(c) >= 0x20) out += c;
    }
    return out;
}

}  // namespace

double finishCpuNowMs() {
    if (!parallelAccounting()) setParallelAccounting(true);
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6 + double(parallelPoolCpuNs()) * 1e-6;
}

Status FinishParams::validate() const {
    if (max_triangles < 0 || (max_triangles > 0 && max_triangles < kMinTriangleBudget)) {
        return invalidArgument("a triangle budget of " + std::to_string(max_triangles) +
                               " is below what a head needs: give at least " + std::to_string(kMinTriangleBudget) +
                               " (or 0 for the full mesh)");
    }
    if (!(min_part_share >= 0 && min_part_share <= 1)) {
        return invalidArgument("min_part_share must be a share in [0, 1], got " + num(min_part_share));
    }
    if (!(watertight_voxel_m >= 0.0005f && watertight_voxel_m <= 0.01f)) {
        return invalidArgument("watertight_voxel_m must be metres in [0.0005, 0.01], got " + num(watertight_voxel_m));
    }
    if (!(max_hole_m > 0 && max_hole_m <= 1)) {
        return invalidArgument("max_hole_m must be metres in (0, 1], got " + num(max_hole_m));
    }
    if (crop_m && (crop_m->isEmpty() || !crop_m->min().allFinite() || !crop_m->max().allFinite())) {
        return invalidArgument("the crop box is empty: each of its maxima must exceed its minimum (metres)");
    }
    return Status::ok();
}

StatusOr<int> triangleBudgetPreset(const std::string& name) {
    if (name == "web") return 20'000;
    if (name == "avatar") return 50'000;
    if (name == "print") return 200'000;
    if (name == "full") return 0;
    return invalidArgument("unknown triangle budget '" + name +
                           "': give a number of triangles or one of web (20000), avatar (50000), print (200000), "
                           "full (no budget)");
}

StatusOr<int> parseTriangleBudget(const std::string& text) {
    if (!text.empty() && !std::isdigit(static_cast<unsigned char>(text[0]))) return triangleBudgetPreset(text);
    int n = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), n);
    if (ec != std::errc() || end != text.data() + text.size()) {
        return invalidArgument("--max-triangles needs a number of triangles or web|avatar|print|full, got '" + text +
                               "'");
    }
    FinishParams p;
    p.max_triangles = n;
    RETURN_IF_ERROR(p.validate());
    return n;
}

StatusOr<KeepParts> parseKeepParts(const std::string& text) {
    if (text == "head") return KeepParts::kHead;
    if (text == "all") return KeepParts::kAll;
    return invalidArgument("--keep must be head (the tracked head alone) or all (everything the volume holds), got '" +
                           text + "'");
}

StatusOr<ClosingMode> parseClosingMode(const std::string& text) {
    if (text == "none") return ClosingMode::kNone;
    if (text == "holes") return ClosingMode::kHoles;
    if (text == "watertight") return ClosingMode::kWatertight;
    return invalidArgument("--close must be none, holes or watertight, got '" + text + "'");
}

StatusOr<Eigen::AlignedBox3f> parseCropBox(const std::string& text) {
    float v[6];
    std::istringstream in(text);
    for (int i = 0; i < 6; ++i) {
        std::string field;
        if (!std::getline(in, field, ',')) {
            return invalidArgument("--crop needs six numbers x0,y0,z0,x1,y1,z1 in metres, got '" + text + "'");
        }
        char* end = nullptr;
        v[i] = std::strtof(field.c_str(), &end);
        if (field.empty() || *end != '\0' || !std::isfinite(v[i])) {
            return invalidArgument("--crop: '" + field + "' is not a number (metres)");
        }
    }
    std::string rest;
    if (std::getline(in, rest)) return invalidArgument("--crop takes six numbers, got more: '" + text + "'");
    const Eigen::AlignedBox3f box(Eigen::Vector3f(v[0], v[1], v[2]), Eigen::Vector3f(v[3], v[4], v[5]));
    if (box.isEmpty() || (box.max() - box.min()).minCoeff() <= 0) {
        return invalidArgument("--crop: the box's maxima x1,y1,z1 must exceed its minima x0,y0,z0, got '" + text + "'");
    }
    return box;
}

const char* keepPartsName(KeepParts keep) { return keep == KeepParts::kHead ? "head" : "all"; }
const char* closingModeName(ClosingMode close) {
    switch (close) {
        case ClosingMode::kHoles: return "holes";
        case ClosingMode::kWatertight: return "watertight";
        case ClosingMode::kNone: break;
    }
    return "none";
}

std::string FinishReport::summary() const {
    std::string s = std::to_string(triangles_in) + " -> " + std::to_string(triangles_out) + " triangles";
    if (triangles_outside > 0) s += ", " + std::to_string(triangles_outside) + " outside the head or crop dropped";
    if (parts_dropped > 0) {
        s += ", " + std::to_string(parts_dropped) + " fragment" + (parts_dropped == 1 ? "" : "s") + " (" +
             std::to_string(parts_triangles) + " triangles) dropped";
    }
    if (holes_filled > 0) s += ", " + std::to_string(holes_filled) + " holes filled";
    if (watertight) s += ", closed into a solid (" + std::to_string(views_used) + " views carved)";
    if (distance.samples > 0) {
        s += "; distance to the full mesh mean " + num(distance.mean_mm) + " mm, p99 " + num(distance.p99_mm) +
             " mm, max " + num(distance.max_mm) + " mm";
    }
    for (const std::string& n : notes) s += "; " + n;
    return s;
}

std::string FinishReport::cpuBreakdown() const {
    std::string s = "CPU ms: parts " + num(cpu_ms.parts) + ", close " + num(cpu_ms.close);
    if (watertight || cpu_ms.close_field > 0) {
        s += " (field " + num(cpu_ms.close_field) + ", marching cubes and largest piece " + num(cpu_ms.close_march) +
             ", pinch checks and thickening " + num(cpu_ms.close_thicken) + ", manifold check " +
             num(cpu_ms.close_check) + ")";
    }
    return s + ", decimate " + num(cpu_ms.decimate) + ", distance " + num(cpu_ms.distance) + "; finish " +
           num(cpu_ms.total());
}

std::string FinishReport::json() const {
    std::string j =
        "{\"triangles_in\": " + std::to_string(triangles_in) + ", \"triangles_out\": " + std::to_string(triangles_out) +
        ", \"vertices_out\": " + std::to_string(vertices_out) +
        ", \"triangles_outside\": " + std::to_string(triangles_outside) +
        ", \"parts_dropped\": " + std::to_string(parts_dropped) +
        ", \"holes_filled\": " + std::to_string(holes_filled) + ", \"holes_left\": " + std::to_string(holes_left) +
        ", \"budget_reached\": " + (budget_reached ? "true" : "false") +
        ", \"watertight\": " + (watertight ? "true" : "false") +
        ", \"distance_mm\": {\"mean\": " + num(distance.mean_mm) + ", \"p99\": " + num(distance.p99_mm) +
        ", \"max\": " + num(distance.max_mm) + "}, \"ms\": {\"parts\": " + num(ms_parts) +
        ", \"close\": " + num(ms_close) + ", \"decimate\": " + num(ms_decimate) +
        ", \"distance\": " + num(ms_distance) + "}, \"cpu_ms\": {\"parts\": " + num(cpu_ms.parts) +
        ", \"close\": " + num(cpu_ms.close) + ", \"close_field\": " + num(cpu_ms.close_field) +
        ", \"close_march\": " + num(cpu_ms.close_march) + ", \"close_thicken\": " + num(cpu_ms.close_thicken) +
        ", \"close_check\": " + num(cpu_ms.close_check) + ", \"decimate\": " + num(cpu_ms.decimate) +
        ", \"distance\": " + num(cpu_ms.distance) + "}, \"notes\": [";
    for (size_t i = 0; i < notes.size(); ++i) j += (i ? ", \"" : "\"") + jsonEscape(notes[i]) + "\"";
    return j + "]}";
}

StatusOr<FinishReport> finishMesh(IndexedMesh& mesh, const FinishParams& params, const HeadRegion* head,
                                  const VoxelBlockGrid* volume) {
    RETURN_IF_ERROR(params.validate());
    FinishReport report;
    report.triangles_in = mesh.triangleCount();
    if (mesh.triangles.empty()) {
        report.notes.emplace_back("the mesh is empty: nothing to finish");
        return report;
    }
    auto t0 = std::chrono::steady_clock::now();
    double c0 = finishCpuNowMs();
    removeDefects(mesh);  // welded by position: parts and holes are judged on shared vertices
    keepHead(mesh, params, head, report);
    report.ms_parts = msSince(t0);
    report.cpu_ms.parts = finishCpuNowMs() - c0;
    if (mesh.triangles.empty()) {
        report.notes.emplace_back("nothing of the mesh lies inside the head region or the crop box");
        return report;
    }
    const bool changes = params.close != ClosingMode::kNone || params.max_triangles > 0;
    IndexedMesh full;
    if (params.measure_distance && changes) full = mesh;
    if (params.close == ClosingMode::kHoles) {
        t0 = std::chrono::steady_clock::now();
        c0 = finishCpuNowMs();
        fillHoles(mesh, params.max_hole_m, report);
        report.ms_close = msSince(t0);
        report.cpu_ms.close = finishCpuNowMs() - c0;
    } else if (params.close == ClosingMode::kWatertight) {
        t0 = std::chrono::steady_clock::now();
        c0 = finishCpuNowMs();
        const VoxelBlockGrid band = meshVolume(mesh, params.watertight_voxel_m, volume);
        report.cpu_ms.close_field = finishCpuNowMs() - c0;
        closeWatertight(mesh, band, head, params, report);
        report.ms_close = msSince(t0);
        report.cpu_ms.close = finishCpuNowMs() - c0;
    }
    if (params.max_triangles > 0) {
        t0 = std::chrono::steady_clock::now();
        c0 = finishCpuNowMs();
        decimate(mesh, params.max_triangles, report);
        report.ms_decimate = msSince(t0);
        report.cpu_ms.decimate = finishCpuNowMs() - c0;
    }
    if (!full.triangles.empty()) {
        t0 = std::chrono::steady_clock::now();
        c0 = finishCpuNowMs();
        report.distance = vertexToSurfaceDistance(full, mesh, kDistanceSamples);
        report.ms_distance = msSince(t0);
        report.cpu_ms.distance = finishCpuNowMs() - c0;
    }
    report.triangles_out = mesh.triangleCount();
    report.vertices_out = mesh.vertexCount();
    return report;
}

}  // namespace facescan::recon
