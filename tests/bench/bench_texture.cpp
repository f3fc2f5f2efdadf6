// facescan-bench texture: what the texture atlas (recon/texture_atlas.hpp) gains over vertex colours, measured
// against the truth. A synthetic scan of the Lee Perry-Smith head (its own colour texture is the truth) is
// reconstructed; colour frames are rendered from that head into a colour camera of its own (not registered to
// depth: 2.5 cm beside it, at its own resolution; unlit like the sensor's frames the vertex colours come from, or
// both lit with --lit), JPEG-encoded and kept as the server keeps them
// (service/texture_keyframes.hpp); the finished model is textured from them with the poses the reconstruction
// tracked. The model (vertex colours, texture at full resolution, texture at 20,000 triangles) and the ground-truth
// head are rendered unlit from six views (front, 30 and 60 degrees either side, from above) and compared over the
// face's pixels (within 0.11 m of the nose tip): PSNR and SSIM.
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "bench_command.hpp"
#include "eval/accuracy.hpp"
#include "eval/colour_render.hpp"
#include "finish_stall.hpp"
#include "recon/finishing.hpp"
#include "recon/mesh_writer.hpp"
#include "recon/reconstructor.hpp"
#include "recon/texture_atlas.hpp"
#include "recon_input.hpp"
#include "service/texture_keyframes.hpp"
#include "wire/colour_codec.hpp"

namespace {

using namespace facescan;
constexpr float kPi = 3.14159265f;

int usage(std::FILE* out) {
    std::fprintf(
        out,
        "usage: facescan-bench texture [--frames N] [--colour WxH] [--texels-per-pixel R] [--weight-power P]\n"
        "                              [--pixel-centre-sigma S] [--bilinear] [--true-poses] [--lit] [--stall]\n"
        "                              [--save DIR] [--json]\n"
        "  Scans the synthetic Lee Perry-Smith head (N frames, default 300), textures the finished model from\n"
        "  colour keyframes of a WxH colour camera (default: both 1280x720 and 640x480; 2.5 cm beside the\n"
        "  depth camera, the same horizontal field of view) and compares renders of the model with the\n"
        "  ground truth from six views over the face: PSNR (dB) and SSIM of vertex colours, the texture at\n"
        "  full resolution and the texture at 20,000 triangles. --save DIR writes the renders (truth, vertex\n"
        "  colours, texture) side by side per view, and the atlases. --texels-per-pixel R: atlas texels per colour\n"
        "  pixel (the server's texture.texels_per_pixel, default 2). --weight-power P: the views' weights raised\n"
        "  to P before blending (default 1). --pixel-centre-sigma S: the spread in pixels of a view's weight\n"
        "  about its nearest pixel centre (default 0.25; 0 turns it off). --bilinear: resample the colour images\n"
        "  bilinearly instead of by cubic convolution. --true-poses: bake with the simulator's true poses instead\n"
        "  of the tracked ones (what the tracking's error costs the texture).\n"
        "  Colour is the head's own, unlit, in the sensor's frames (vertex colours) and the colour camera's\n"
        "  alike, so that both compare with the texture of the truth; --lit lights both as the synthetic Kinect\n"
        "  does (a lamp above-left of the camera), which the unlit truth then differs from everywhere.\n"
        "  --stall: what the watertight finish costs a session still scanning: a thread reconstructing the scan\n"
        "  frame after frame beside one that finishes, every thread on one core; its frames per second alone and\n"
        "  beside the finish run at the worker's priority with the pool, and as the server runs it (nice 5, alone).\n");
    return out == stdout ? 0 : 2;
}

struct Figures {
    double psnr_db = 0, ssim = 0;
};

// The six views of the comparison: a camera 0.6 m from a point 5 cm in front of the head's centre, head frame.
std::vector<recon::Pose> evalViews() {
    std::vector<recon::Pose> out;
    const std::pair<float, float> yaw_pitch[] = {{0, 0}, {-30, 0}, {30, 0}, {-60, 0}, {60, 0}, {0, 20}};
    for (const auto& [yaw, pitch] : yaw_pitch) {
        const Eigen::Matrix3f turn = (Eigen::AngleAxisf(yaw * kPi / 180, Eigen::Vector3f::UnitY()) *
                                      Eigen::AngleAxisf(-pitch * kPi / 180, Eigen::Vector3f::UnitX()))
                                         .toRotationMatrix();
        recon::Pose T_head_camera = recon::Pose::Identity();
        T_head_camera.linear() = turn * Eigen::Vector3f(1, -1, -1).asDiagonal();  // looking along -z of the head
        T_head_camera.translation() = Eigen::Vector3f(0, 0, 0.05f) + turn * Eigen::Vector3f(0, 0, 0.6f);
        out.push_back(T_head_camera.inverse());
    }
    return out;
}

struct Truth {
    std::vector<Eigen::Vector3f> positions;
    std::vector<recon::Triangle> triangles;
    std::vector<Eigen::Vector2f> uv;
    std::vector<Eigen::Vector3f> normals;
    cv::Mat texture;
    Eigen::Vector3f nose;
};

Truth truthOf(const synth::HeadModel& head) {
    Truth t;
    for (const auto vh : head.mesh.vertices()) {
        const auto& p = head.mesh.point(vh);
        t.positions.emplace_back(p[0], p[1], p[2]);
        const auto uv = head.mesh.texcoord2D(vh);
        t.uv.emplace_back(uv[0], 1.0f - uv[1]);  // OpenGL's v up to the image's rows
        const auto& n = head.mesh.normal(vh);
        t.normals.emplace_back(n[0], n[1], n[2]);
    }
    for (const auto fh : head.mesh.faces()) {
        recon::Triangle tri{};
        int i = 0;
        for (const auto vh : head.mesh.fv_range(fh)) tri[static_cast<size_t>(i++)] = static_cast<uint32_t>(vh.idx());
        t.triangles.push_back(tri);
    }
    t.texture = head.texture_bgr;
    t.nose = eval::findNoseTip(head.mesh);
    return t;
}

// The model against the truth over the six views; `save` (non-empty) writes truth | model per view.
Figures compare(const Truth& truth, const eval::ColourMesh& model, const recon::Pose& T_head_model,
                const recon::Intrinsics& k, const std::string& save, const std::string& name) {
    eval::ColourMesh gt;
    gt.positions_m = &truth.positions;
    gt.triangles = &truth.triangles;
    gt.uv = &truth.uv;
    gt.texture_bgr = &truth.texture;
    Figures sum;
    const std::vector<recon::Pose> views = evalViews();
    for (size_t v = 0; v < views.size(); ++v) {
        const eval::ColourRender a = eval::renderColour(gt, views[v], k);
        const eval::ColourRender b = eval::renderColour(model, views[v] * T_head_model, k);
        cv::Mat face(k.height_px, k.width_px, CV_8U, cv::Scalar(0));
        for (int y = 0; y < k.height_px; ++y) {
            for (int x = 0; x < k.width_px; ++x) {
                if (!a.hit.at<uint8_t>(y, x) || !b.hit.at<uint8_t>(y, x)) continue;
                const cv::Vec3f p = a.point_m.at<cv::Vec3f>(y, x);
                if ((Eigen::Vector3f(p[0], p[1], p[2]) - truth.nose).norm() <= 0.11f) face.at<uint8_t>(y, x) = 255;
            }
        }
        sum.psnr_db += eval::psnrDb(a.bgr, b.bgr, face);
        sum.ssim += eval::ssim(a.bgr, b.bgr, face);
        if (!save.empty()) {
            cv::Mat side;
            cv::hconcat(a.bgr, b.bgr, side);
            cv::imwrite(save + "/" + name + "_view" + std::to_string(v) + ".png", side);
        }
    }
    sum.psnr_db /= double(views.size());
    sum.ssim /= double(views.size());
    return sum;
}

struct Scan {
    recon::IndexedMesh raw;                          // as extracted
    recon::IndexedMesh full, web;                    // finished: the head alone; and at 20,000 triangles
    recon::HeadRegion region;                        // where the tracked head was
    recon::TsdfSnapshot volume;                      // the model's volume (what the server's finish closes)
    std::vector<std::pair<int, recon::Pose>> poses;  // frame index, T_world_depth as tracked
    recon::Pose T_head_model;
};

StatusOr<Scan> scan(bench::Sequence& seq) {
    recon::Reconstructor rec(seq.k, recon::ReconParams::faceDefaults());
    RETURN_IF_ERROR(rec.initStatus());
    Scan s;
    for (size_t i = 0; i < seq.frames.size(); ++i) {
        const recon::FrameResult r = rec.processFrame(seq.frames[i], seq.masks[i]);
        if (r.restarted) s.poses.clear();
        if (r.tracked) s.poses.emplace_back(static_cast<int>(i), rec.lastPose());
    }
    const recon::Mesh mesh = rec.extractMesh();
    const recon::Mesh& gt = seq.sim->head().mesh;
    ASSIGN_OR_RETURN(const eval::AccuracyReport acc,
                     eval::measureAccuracy(mesh, gt, eval::findNoseTip(gt), {}, seq.sim->poseAt(0).inverse()));
    s.T_head_model = acc.T_gt_mesh;
    s.full = recon::fromOpenMesh(mesh);
    s.raw = s.full;
    s.region = rec.headRegion();
    rec.copyVolume(s.volume);
    const recon::HeadRegion& region = s.region;
    recon::FinishParams finish;
    finish.measure_distance = false;
    RETURN_IF_ERROR(recon::finishMesh(s.full, finish, &region).status());
    s.web = s.full;
    finish.max_triangles = 20'000;
    RETURN_IF_ERROR(recon::finishMesh(s.web, finish, &region).status());
    return s;
}

}  // namespace

int runTexture(const std::vector<std::string>& args) {
    int frames = 300;
    bool json = false, lit = false, stall = false, true_poses = false;
    recon::TextureParams texture_params;
    std::string save;
    std::vector<std::pair<int, int>> sizes;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const bool has_value = i + 1 < args.size();
        if (a == "--help" || a == "-h") return usage(stdout);
        if (a == "--json") {
            json = true;
        } else if (a == "--texels-per-pixel" && has_value) {
            texture_params.texels_per_pixel = static_cast<float>(std::atof(args[++i].c_str()));
        } else if (a == "--weight-power" && has_value) {
            texture_params.weight_power = static_cast<float>(std::atof(args[++i].c_str()));
        } else if (a == "--pixel-centre-sigma" && has_value) {
            texture_params.pixel_centre_sigma_px = static_cast<float>(std::atof(args[++i].c_str()));
        } else if (a == "--bilinear") {
            texture_params.bicubic = false;
        } else if (a == "--true-poses") {
            true_poses = true;
        } else if (a == "--lit") {
            lit = true;
        } else if (a == "--stall") {
            stall = true;
        } else if (a == "--frames" && has_value) {
            frames = std::atoi(args[++i].c_str());
        } else if (a == "--save" && has_value) {
            save = args[++i];
        } else if (a == "--colour" && has_value) {
            int w = 0, h = 0;
            if (std::sscanf(args[++i].c_str(), "%dx%d", &w, &h) != 2 || w < 64 || h < 48 || w > 4096 || h > 4096) {
                std::fprintf(stderr, "texture: --colour needs WxH, 64x48 to 4096x4096, e.g. 1280x720\n");
                return 2;
            }
            sizes.emplace_back(w, h);
        } else {
            std::fprintf(stderr, "texture: unknown argument '%s'\n", a.c_str());
            return usage(stderr);
        }
    }
    if (frames < 30) {
        std::fprintf(stderr, "texture: --frames must be at least 30 (the head must turn)\n");
        return 2;
    }
    if (Status s = texture_params.validate(); !s.isOk()) {
        std::fprintf(stderr, "texture: %s\n", s.message().c_str());
        return 2;
    }
    if (sizes.empty()) sizes = {{1280, 720}, {640, 480}};
    if (!save.empty()) std::filesystem::create_directories(save);

    bench::Sequence seq;
    if (Status s = bench::loadSequence(lit ? "synthetic" : "synthetic:shading=0", frames, seq); !s.isOk()) {
        std::fprintf(stderr, "texture: %s\n", s.toString().c_str());
        return 1;
    }
    if (seq.sim->head().texture_bgr.empty()) {
        std::fprintf(stderr,
                     "texture: the synthetic head has no colour texture (the Lee Perry-Smith scan was not found: "
                     "set FACESCAN_DATA_DIR to the folder holding leeperrysmith/)\n");
        return 1;
    }
    auto scanned = scan(seq);
    if (!scanned.isOk()) {
        std::fprintf(stderr, "texture: the scan failed: %s\n", scanned.status().toString().c_str());
        return 1;
    }
    const Truth truth = truthOf(seq.sim->head());
    // The comparison renders at 1280x720 whatever the colour camera: detail the model lacks shows.
    recon::Intrinsics eval_k{1280, 720, 1151.6f, 1151.6f, 639.5f, 359.5f};

    eval::ColourMesh vertex;
    vertex.positions_m = &scanned->full.positions_m;
    vertex.triangles = &scanned->full.triangles;
    vertex.colours_rgb = &scanned->full.colours_rgb;
    const Figures vertex_figures = compare(truth, vertex, scanned->T_head_model, eval_k, save, "vertex");
    std::printf("texture: %d frames, %zu tracked, model %zu triangles (web %zu)\n", frames, scanned->poses.size(),
                scanned->full.triangleCount(), scanned->web.triangleCount());
    std::printf("  vertex colours (full):          PSNR %6.2f dB  SSIM %.4f\n", vertex_figures.psnr_db,
                vertex_figures.ssim);
    std::string json_out = "{\"frames\": " + std::to_string(frames) +
                           ", \"vertex\": {\"psnr_db\": " + std::to_string(vertex_figures.psnr_db) +
                           ", \"ssim\": " + std::to_string(vertex_figures.ssim) + "}, \"colour\": [";
    for (size_t si = 0; si < sizes.size(); ++si) {
        const auto [w, h] = sizes[si];
        wire::CameraInfoData camera;
        camera.intrinsics = seq.k;
        const float fx = seq.k.fx_px * float(w) / float(seq.k.width_px);  // the depth camera's horizontal view
        camera.colour_intrinsics = {w, h, fx, fx, (float(w) - 1) / 2, (float(h) - 1) / 2};
        camera.T_colour_depth.translation() = Eigen::Vector3f(-0.025f, 0, 0);
        // Colour frames as the server keeps them: JPEG at the agent's quality, the server's keyframe choice.
        service::TextureKeyframes keyframes;
        eval::ColourMesh gt;
        gt.positions_m = &truth.positions;
        gt.triangles = &truth.triangles;
        gt.uv = &truth.uv;
        gt.texture_bgr = &truth.texture;
        if (lit) gt.normals = &truth.normals;  // lit like the synthetic Kinect's colour (its lamp, seen from here)
        gt.lamp_camera_m = camera.T_colour_depth * Eigen::Vector3f(-0.25f, -0.35f, 0.0f);
        for (const auto& [index, T_world_depth] : scanned->poses) {
            const recon::Pose T_colour_head = camera.T_colour_depth * seq.sim->poseAt(index);
            const eval::ColourRender frame = eval::renderColour(gt, T_colour_head, camera.colour_intrinsics);
            std::vector<uint8_t> jpeg;
            if (!wire::encodeColourJpeg(frame.bgr, wire::ColourJpegParams{}.quality, jpeg).isOk()) continue;
            // --true-poses: the simulator's pose of the head, brought into the model's frame by the alignment the
            // comparison uses (what the tracked poses' error costs the texture).
            const recon::Pose T_world_depth_used =
                true_poses ? (seq.sim->poseAt(index) * scanned->T_head_model).inverse() : T_world_depth;
            keyframes.offer(static_cast<uint32_t>(index), wire::ColourCodecId::kJpeg, jpeg, T_world_depth_used);
        }
        std::vector<std::string> notes;
        const std::vector<recon::TextureView> views = keyframes.views(camera, &notes);
        const auto t0 = std::chrono::steady_clock::now();
        recon::TexturedMesh full, web;
        auto full_report = recon::bakeTexture(scanned->full, views, texture_params, full);
        const double full_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        auto web_report = recon::bakeTexture(scanned->web, views, texture_params, web);
        if (!full_report.isOk() || !web_report.isOk()) {
            std::fprintf(stderr, "texture: baking failed: %s\n",
                         (full_report.isOk() ? web_report.status() : full_report.status()).toString().c_str());
            return 1;
        }
        // The server's whole finish of a textured model (head alone, holes closed or closed into a solid,
        // 20,000 triangles, texture), in CPU time of this process (all its threads); then what writing its files
        // costs (mesh.ply, textured.obj/.mtl/.png, textured.ply), and the steps' own CPU (this thread and the
        // pool's workers on its behalf).
        struct FinishCpu {
            bool ok = false;
            double finish_s = 0, writers_ms = 0, bake_ms = 0;
            std::string steps, bake_steps;
            recon::TexturedMesh textured;
        };
        auto finishCpuS = [&](recon::ClosingMode close) {
            FinishCpu out;
            const std::clock_t cpu0 = std::clock();
            recon::IndexedMesh finished = scanned->raw;
            recon::FinishParams finish;
            finish.close = close;
            finish.max_triangles = 20'000;
            auto report = recon::finishMesh(finished, finish, &scanned->region, &scanned->volume);
            const double bake0 = recon::finishCpuNowMs();
            auto baked = recon::bakeTexture(finished, views, texture_params, out.textured);
            out.bake_ms = recon::finishCpuNowMs() - bake0;
            out.finish_s = double(std::clock() - cpu0) / CLOCKS_PER_SEC;
            out.ok = report.isOk() && (close != recon::ClosingMode::kWatertight || report->watertight) && baked.isOk();
            if (!out.ok) {
                out.steps = !report.isOk()  ? report.status().toString()
                            : !baked.isOk() ? "bake: " + baked.status().toString()
                                            : "not closed: " + report->summary();
                return out;
            }
            out.steps = report->cpuBreakdown();
            char buf[160];
            std::snprintf(buf, sizeof buf, "bake %.0f ms CPU (wall: charts %.0f, visibility %.0f, texels %.0f)",
                          out.bake_ms, baked->ms_charts, baked->ms_visibility, baked->ms_bake);
            out.bake_steps = buf;
            const double write0 = recon::finishCpuNowMs();
            out.ok = recon::meshFileBytes(finished, recon::MeshFileFormat::kPly).isOk() &&
                     recon::texturedObjFiles(out.textured, "textured").isOk() &&
                     recon::texturedPlyBytes(out.textured, "textured.png").isOk();
            out.writers_ms = recon::finishCpuNowMs() - write0;
            return out;
        };
        if (stall && si == 0) {
            for (const bool as_server : {false, true}) {
                auto figures = bench::measureFinishStall(
                    seq, [&] { (void)finishCpuS(recon::ClosingMode::kWatertight); }, as_server);
                if (!figures.isOk()) {
                    std::fprintf(stderr, "texture: --stall: %s\n", figures.status().message().c_str());
                    return 1;
                }
                std::printf(
                    "  stall, one core, %s: scanning %.1f frames/s alone, %.1f beside the finish (%.0f %%); "
                    "finish %.1f s wall\n",
                    as_server ? "finish as the server runs it (nice 5, alone)"
                              : "finish at the worker's priority with the pool",
                    figures->alone_fps, figures->beside_fps, 100 * figures->share(), figures->finish_wall_s);
            }
        }
        const FinishCpu holes = finishCpuS(recon::ClosingMode::kHoles);
        const FinishCpu solid = finishCpuS(recon::ClosingMode::kWatertight);
        const double finish_cpu_s = holes.finish_s, solid_cpu_s = solid.finish_s;
        const bool finished_ok = holes.ok, solid_ok = solid.ok;
        const std::string tag = std::to_string(w) + "x" + std::to_string(h);
        auto figures = [&](const recon::TexturedMesh& t, const std::string& name) {
            eval::ColourMesh m;
            m.positions_m = &t.mesh.positions_m;
            m.triangles = &t.mesh.triangles;
            m.uv = &t.uv;
            m.texture_bgr = &t.atlas_bgr;
            if (!save.empty()) cv::imwrite(save + "/" + name + "_atlas.png", t.atlas_bgr);
            return compare(truth, m, scanned->T_head_model, eval_k, save, name);
        };
        const Figures f_full = figures(full, "texture_" + tag);
        const Figures f_web = figures(web, "texture_web_" + tag);
        const Figures f_solid = solid_ok ? figures(solid.textured, "texture_solid_" + tag) : Figures{};
        std::printf("  colour %s: %zu keyframes (%zu KiB JPEG), %s; bake %.0f ms\n", tag.c_str(), keyframes.count(),
                    keyframes.bytes() >> 10, full_report->summary().c_str(), full_ms);
        std::printf("    finish (head, close holes, 20,000 triangles, texture): %.2f s CPU%s\n", finish_cpu_s,
                    finished_ok ? "" : " (FAILED)");
        std::printf("    finish (head, watertight, 20,000 triangles, texture): %.2f s CPU%s\n", solid_cpu_s,
                    solid_ok ? "" : " (FAILED)");
        for (const auto* f : {&holes, &solid}) {
            if (!f->ok) {
                std::printf("      %s FAILED: %s\n", f == &holes ? "holes" : "watertight", f->steps.c_str());
                continue;
            }
            std::printf("      %s: %s; %s; writers %.0f ms CPU\n", f == &holes ? "holes" : "watertight",
                        f->steps.c_str(), f->bake_steps.c_str(), f->writers_ms);
        }
        std::printf("    texture (full):               PSNR %6.2f dB  SSIM %.4f  (%+.2f dB over vertex colours)\n",
                    f_full.psnr_db, f_full.ssim, f_full.psnr_db - vertex_figures.psnr_db);
        std::printf("    texture (20,000 triangles):   PSNR %6.2f dB  SSIM %.4f  (%+.2f dB over vertex colours)\n",
                    f_web.psnr_db, f_web.ssim, f_web.psnr_db - vertex_figures.psnr_db);
        if (solid_ok) {
            std::printf("    texture (solid, 20,000):      PSNR %6.2f dB  SSIM %.4f  (%+.2f dB over vertex colours)\n",
                        f_solid.psnr_db, f_solid.ssim, f_solid.psnr_db - vertex_figures.psnr_db);
        }
        json_out += std::string(si ? ", " : "") + "{\"size\": \"" + tag +
                    "\", \"keyframes\": " + std::to_string(keyframes.count()) +
                    ", \"bake_ms\": " + std::to_string(full_ms) +
                    ", \"finish_cpu_s\": " + std::to_string(finish_cpu_s) +
                    ", \"watertight_finish_cpu_s\": " + std::to_string(solid_cpu_s) +
                    ", \"watertight_writers_cpu_ms\": " + std::to_string(solid.writers_ms) +
                    ", \"solid\": {\"psnr_db\": " + std::to_string(f_solid.psnr_db) +
                    ", \"ssim\": " + std::to_string(f_solid.ssim) + "}" +
                    ", \"full\": {\"psnr_db\": " + std::to_string(f_full.psnr_db) +
                    ", \"ssim\": " + std::to_string(f_full.ssim) +
                    "}, \"web\": {\"psnr_db\": " + std::to_string(f_web.psnr_db) +
                    ", \"ssim\": " + std::to_string(f_web.ssim) + "}}";
    }
    if (json) std::printf("%s]}\n", json_out.c_str());
    return 0;
}

FACESCAN_BENCH_COMMAND("texture",
                       "texture atlas vs vertex colours: PSNR/SSIM of the face against the true head, six views",
                       runTexture);
