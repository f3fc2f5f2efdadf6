// Finishing a session: the final full-resolution mesh, its Draco bytes (encodeMesh, which snapshots use too), a
// last preview, and the files in the data dir (session_store.hpp). Runs on the session's worker (or on the caller's
// thread when the session never had a worker), never on the intake thread.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "service/failpoint.hpp"
#include "service/session.hpp"
#include "service/session_store.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::service {
namespace {

constexpr double kFinishStepLimitS = 60.0;  // seconds one step of the finish may take on a busy machine

// FACESCAN_FAILPOINT=finish-step-sleep-s:N (failpoint.hpp): the texture step of every finish takes N s more, as
// it does on a saturated machine, where it runs below the sessions still scanning.
void finishStepFailpoint() {
    static const double sleep_s = [] {
        const auto arg = failpointArg("finish-step-sleep-s");
        return arg ? std::atof(arg->c_str()) : 0.0;
    }();
    if (sleep_s > 0) std::this_thread::sleep_for(std::chrono::duration<double>(sleep_s));
}

std::string num(double v) {
    std::ostringstream o;
    o.precision(6);
    o << v;
    return o.str();
}

std::string msJson(const recon::StageTimesMs& ms) {
    return "{\"detect\": " + num(ms.detect) + ", \"segment\": " + num(ms.segment) + ", \"filter\": " + num(ms.filter) +
           ", \"icp\": " + num(ms.icp) + ", \"integrate\": " + num(ms.integrate) + ", \"raycast\": " + num(ms.raycast) +
           ", \"mesh\": " + num(ms.mesh) + "}";
}

}  // namespace

wire::MeshCodecParams meshCodecParams(const recon::VoxelBlockGrid& grid, float max_error_m) {
    wire::MeshCodecParams params;
    params.max_position_error_m = max_error_m;
    params.lattice_step_m = grid.voxel_size_m;
    params.lattice_origin_m = grid.origin_world;
    return params;
}

StatusOr<MeshResult> encodeMesh(const recon::IndexedMesh& mesh, const wire::MeshCodecParams& params,
                                recon::IndexedMesh* encoded) {
    auto bytes = std::make_shared<std::vector<uint8_t>>();
    recon::IndexedMesh cleaned;
    RETURN_IF_ERROR(wire::encodeMeshDraco(mesh, params, *bytes, &cleaned));
    MeshResult result{std::move(bytes), static_cast<uint32_t>(cleaned.vertexCount()),
                      static_cast<uint32_t>(cleaned.triangleCount())};
    if (encoded) *encoded = std::move(cleaned);
    return result;
}

bool Session::mayWrite() {
    for (;;) {
        {
            std::lock_guard lk(mutex_);
            if (stop_) return false;
            if (!hold_ || !hold_()) return true;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
}

void Session::nextWatchedStep(double limit_s) {
    // Only while the worker is inside a step (finalize on the worker): a finalize on another thread (a session
    // that never had a worker) must not start a step that nobody ends.
    if (!beat_ || beat_->busySinceNs() == 0) return;
    limit_s > 0 ? beat_->beginLong(limit_s) : beat_->begin();
}

void Session::finalize(const std::string& why, const FinishCallback& done) {
    std::shared_ptr<recon::Reconstructor> rec;
    recon::Pose pose;
    {
        std::lock_guard lk(mutex_);
        rec = recon_;
        pose = last_pose_;
    }
    recon::IndexedMesh mesh;  // as encoded: cleaned on Draco's grid, so mesh.ply and mesh.drc hold one mesh
    MeshResult result;
    std::vector<uint8_t> png;
    Status status;
    recon::FinishReport finish_report;
    std::string finish_json = "null";
    recon::TexturedMesh textured;
    std::string texture_json = "null";
    std::vector<uint8_t> textured_draco;
    if (rec) {
        // Below the sessions still scanning, on the session's own worker (frame_load.hpp).
        if (load_) load_->leaveToFinish();
        recon::TsdfSnapshot grid;
        rec->copyVolume(grid);
        recon::MeshParams mesh_params = params_.recon.mesh;
        // --keep all: everything the volume holds, the small pieces marching cubes would drop included.
        if (params_.finish.keep == recon::KeepParts::kAll) mesh_params.min_fragment_share = 0;
        recon::IndexedMesh extracted = recon::extractTriangles(grid, mesh_params);
        // The finished model (the head alone, holes, the budget) on this worker, like the meshing: it never holds
        // the intake or another session's worker. Its params were validated at start, so it cannot refuse; its
        // notes (a budget not reached, holes left) go to the log and summary.json.
        const recon::HeadRegion region = rec->headRegion();
        // Seconds of CPU with closing, a budget and the texture, at a lower priority than the sessions still
        // scanning (leaveToFinish): on a saturated machine each step is tens of seconds of wall time, and not a
        // stuck server. Every step of the finish has the longer limit (the texture's bake took over 10 s at load 18).
        const double finish_step_limit_s = std::max(kFinishStepLimitS, 4.0 * params_.stall_limit_s);
        nextWatchedStep(finish_step_limit_s);
        auto finished = recon::finishMesh(extracted, params_.finish, &region, &grid);
        nextWatchedStep(finish_step_limit_s);
        if (finished.isOk()) {
            finish_report = *finished;
            finish_json = finish_report.json();
            if (!finish_report.notes.empty() || finish_report.triangles_in != finish_report.triangles_out) {
                std::fprintf(stderr, "facescan-server: session %s: finished model: %s\n", id_.c_str(),
                             finish_report.summary().c_str());
            }
        }
        if (!extracted.triangles.empty()) {
            const auto params = meshCodecParams(grid, wire::MeshCodecParams{}.max_position_error_m);
            auto encoded = encodeMesh(extracted, params, &mesh);
            if (encoded.isOk()) {
                result = std::move(*encoded);
            } else {
                status = encoded.status();
            }
        }
        // The texture of the mesh as encoded (cleaned on Draco's grid): the textured files and textured.drc are
        // the model of mesh.ply and mesh.drc, triangle for triangle, split only where the charts meet.
        if (status.isOk() && !mesh.triangles.empty()) {
            nextWatchedStep(finish_step_limit_s);
            finishStepFailpoint();
            texture_json = bakeFinishedTexture(mesh, textured);
            nextWatchedStep(finish_step_limit_s);
        }
        if (textured.valid()) {
            // For clients that ask for the texture (textured.drc). Normals go with it: its vertices are split where
            // charts meet, and normals recomputed from the triangles would differ on the two sides of a cut; these
            // are the normals of the model before it was cut, one for both copies of a vertex on a cut.
            if (!textured.mesh.hasNormals() && textured.source_vertex.size() == textured.mesh.vertexCount()) {
                const std::vector<Eigen::Vector3f> normals = recon::vertexNormals(mesh);
                textured.mesh.normals.reserve(textured.mesh.vertexCount());
                for (const uint32_t v : textured.source_vertex) textured.mesh.normals.push_back(normals.at(v));
            }
            wire::MeshCodecParams params;
            params.normal_bits = 10;
            if (Status s = wire::encodeTexturedMeshDraco(textured, params, textured_draco); !s.isOk()) {
                textured_draco.clear();
                std::fprintf(stderr,
                             "facescan-server: session %s: the textured model cannot be encoded for clients: %s\n",
                             id_.c_str(), s.toString().c_str());
            }
            nextWatchedStep(finish_step_limit_s);
        }
        cv::Mat shaded;
        rec->renderPreview(pose, shaded);
        if (!shaded.empty()) cv::imencode(".png", shaded, png);
        nextWatchedStep();
    }
    SessionStats s = stats();
    {
        std::lock_guard lk(mutex_);  // the summary's fps is over the whole session, not the last 2 s
        s.fps = s.duration_s > 0
                    ? static_cast<float>(static_cast<double>(processed_before_ + processed_count_) / s.duration_s)
                    : 0;
    }
    s.state = SessionState::kFinished;
    s.detail = "finished: " + why;
    SessionFiles files;
    files.mesh = &mesh;
    files.draco = result.draco.get();
    files.trajectory_tum = trajectoryTum();
    files.textured = &textured;
    files.textured_draco = &textured_draco;
    files.summary_json = summaryJson(s, result, finish_json, texture_json);
    files.frames_tsv = frameTimingsTsv();
    files.preview_png = &png;
    std::filesystem::path written;
    // Meshing takes seconds: a server frozen meanwhile may have lost the session. Nothing is written while its view
    // of the cluster is stale, and nothing at all once it gave the session up: the new owner writes it.
    if (!mayWrite()) {
        std::fprintf(stderr, "facescan-server: session %s: given up while finishing: nothing written here\n",
                     id_.c_str());
        return;
    }
    if (status.isOk()) {
        // The folder records its owner: a server that lost the session to another one (two servers that could
        // not see each other) writes beside the other's files, never over them.
        std::string note;
        auto dir = claimSessionDir(params_.data_dir, id_, s.owner_id, s.epoch, &note);
        if (!note.empty()) std::fprintf(stderr, "facescan-server: %s\n", note.c_str());
        status = dir.isOk() ? writeSessionFiles(*dir, files) : dir.status();
        if (status.isOk()) {
            removeReplicaLog(*dir);
            written = *dir;
        }
    }
    if (!status.isOk()) s.detail += " (not written: " + status.message() + ")";
    if (!written.empty()) {
        // Given up while the files were being written (the server was frozen after mayWrite): the server that gave
        // it up saw no files yet, so the decision it made for written files is carried out here.
        std::lock_guard lk(mutex_);
        if (stop_ && discard_written_) {
            std::error_code ec;
            std::filesystem::remove_all(written, ec);
            std::fprintf(stderr,
                         "facescan-server: session %s: given up while its files were being written: the files in %s "
                         "are removed (the new owner writes the scan)\n",
                         id_.c_str(), written.c_str());
            written.clear();
        } else if (stop_) {
            std::fprintf(stderr,
                         "facescan-server: session %s: given up while its files were being written: the files in %s "
                         "stay (its agent is gone: they may hold frames the new owner never gets)\n",
                         id_.c_str(), written.c_str());
        }
    }

    std::deque<Control> pending;
    {
        std::lock_guard lk(mutex_);
        const auto fps = s.fps;
        stats_.state = SessionState::kFinished;
        stats_.detail = s.detail;
        stats_.duration_s = s.duration_s;
        stats_.fps = fps;
        final_mesh_ = result;
        final_preview_png_ = std::move(png);
        files_dir_ = written;
        recon_.reset();  // frees the volume; finished sessions answer from the cached results
        pending.swap(control_);
        finishing_ = false;
    }
    cv_.notify_all();
    if (done) done(status, result);
    // Requests that arrived while finishing: a second finish is answered like the first; a reset cannot apply.
    for (Control& c : pending) {
        if (c.kind == Control::kRun && c.reset_done) c.reset_done(unavailable("session '" + id_ + "' is finished"));
        if (c.kind == Control::kFinish && c.finish_done) c.finish_done(status, result);
        if (c.kind == Control::kReset && c.reset_done) {
            c.reset_done(invalidArgument("session '" + id_ + "' is finished: nothing to reset"));
        }
    }
}

std::optional<SnapshotResult> Session::takeFinalSnapshot() {
    std::lock_guard lk(mutex_);
    if (stats_.state != SessionState::kFinished || final_snapshot_sent_ || !final_mesh_.draco) return std::nullopt;
    final_snapshot_sent_ = true;
    SnapshotResult out;
    out.seq = ++stats_.snapshot_seq;
    out.frames_integrated = stats_.frames_integrated;
    out.mesh = final_mesh_;
    return out;
}

std::filesystem::path Session::filesDir() const {
    std::lock_guard lk(mutex_);
    return files_dir_;
}

std::string Session::frameTimingsTsv() const {
    // Only this server's frames: after a takeover the previous owner's are in its own data dir, if it wrote one.
    if (frame_timings_.empty()) return {};
    std::string tsv =
        "# seq\tqueued_ms\tprocessing_ms\tcpu_ms\teconomy_step\toutcome (F fused, T tracked only, R "
        "rejected, D dropped)\n";
    tsv.reserve(tsv.size() + frame_timings_.size() * 32);
    char line[96];
    for (const FrameTiming& t : frame_timings_) {
        std::snprintf(line, sizeof line, "%u\t%.2f\t%.2f\t%.2f\t%u\t%c\n", t.seq, static_cast<double>(t.queued_ms),
                      static_cast<double>(t.processing_ms), static_cast<double>(t.cpu_ms), t.economy_step, t.outcome);
        tsv += line;
    }
    return tsv;
}

std::string Session::bakeFinishedTexture(const recon::IndexedMesh& mesh, recon::TexturedMesh& out) {
    std::optional<wire::CameraInfoData> camera;
    {
        std::lock_guard lk(mutex_);
        camera = camera_;
    }
    std::vector<std::string> notes;
    std::string why;
    if (params_.texture_keyframes.max_keyframes == 0) return "null";  // texturing is off
    if (!camera || keyframes_.count() == 0) {
        why = keyframes_.rawSkipped() > 0 ? "the colour came uncompressed (raw), which is not kept for the texture"
                                          : "no colour frames were received";
    } else {
        const std::vector<recon::TextureView> views = keyframes_.views(*camera, &notes);
        auto baked = recon::bakeTexture(mesh, views, params_.texture, out);
        if (baked.isOk()) {
            baked->notes.insert(baked->notes.begin(), notes.begin(), notes.end());
            std::fprintf(stderr, "facescan-server: session %s: %s (%zu keyframes, %zu KiB of colour kept)\n",
                         id_.c_str(), baked->summary().c_str(), keyframes_.count(), keyframes_.bytes() >> 10);
            keyframes_.clear();
            return baked->json();
        }
        why = baked.status().message();
    }
    keyframes_.clear();
    out = recon::TexturedMesh{};
    // The model is still written, with its vertex colours.
    std::fprintf(stderr, "facescan-server: session %s: no texture: %s; the model keeps its vertex colours\n",
                 id_.c_str(), why.c_str());
    return "{\"error\": \"" + jsonEscape(why) + "\"}";
}

std::string Session::summaryJson(const SessionStats& s, const MeshResult& m, const std::string& finish_json,
                                 const std::string& texture_json) const {
    recon::ReconParams r = params_.recon;
    std::string camera = "null";
    {
        std::lock_guard lk(mutex_);
        if (camera_) {
            r = recon_params_;  // as adapted to the camera (recon/sensor_adapt.hpp)
            const recon::Intrinsics& k = camera_->intrinsics;
            camera = "{\"width\": " + std::to_string(k.width_px) + ", \"height\": " + std::to_string(k.height_px) +
                     ", \"fx\": " + num(k.fx_px) + ", \"fy\": " + num(k.fy_px) + ", \"cx\": " + num(k.cx_px) +
                     ", \"cy\": " + num(k.cy_px) + ", \"depth_units_m\": " + num(camera_->depth_units_m) +
                     ", \"rate_hz\": " + num(camera_->rate_hz) + ", \"agent_host\": \"" +
                     jsonEscape(camera_->agent_host) + "\", \"sensor\": \"" + jsonEscape(camera_->sensor.name) +
                     "\", \"sensor_family\": \"" + recon::sensorFamilyName(camera_->sensor.family) +
                     "\", \"min_depth_m\": " + num(camera_->sensor.min_depth_m) +
                     ", \"max_depth_m\": " + num(camera_->sensor.max_depth_m) + "}";
        }
    }
    std::string j = "{\n";
    j += "  \"session_id\": \"" + jsonEscape(s.session_id) + "\",\n";
    j += "  \"server_id\": \"" + jsonEscape(params_.server_id) + "\",\n";
    char digest[24];
    std::snprintf(digest, sizeof(digest), "%016llx", static_cast<unsigned long long>(s.frames_digest));
    j += "  \"owner\": {\"server_id\": \"" + jsonEscape(s.owner_id) + "\", \"epoch\": " + std::to_string(s.epoch) +
         ", \"standby\": \"" + jsonEscape(s.standby_id) + "\", \"failovers\": " + std::to_string(s.failovers) +
         ", \"last_takeover_ms\": " + num(s.last_takeover_ms) + "},\n";
    j += "  \"frames_digest\": \"" + std::string(digest) + "\",\n";
    j += "  \"state\": \"" + std::string(sessionStateName(s.state)) + "\",\n";
    j += "  \"detail\": \"" + jsonEscape(s.detail) + "\",\n";
    j += "  \"source\": \"" + jsonEscape(s.source) + "\",\n";
    j += "  \"mode\": \"" + std::string(s.every_frame ? "every_frame" : "live") + "\",\n";
    j += "  \"frames\": {\"received\": " + std::to_string(s.frames_received) +
         ", \"integrated\": " + std::to_string(s.frames_integrated) +
         ", \"rejected\": " + std::to_string(s.frames_rejected) + ", \"skipped\": " + std::to_string(s.frames_skipped) +
         ", \"dropped\": " + std::to_string(s.frames_dropped) +
         ", \"tracked_only\": " + std::to_string(s.frames_tracked_only) + "},\n";
    j += "  \"fps\": " + num(s.fps) + ",\n";
    j += "  \"duration_s\": " + num(s.duration_s) + ",\n";
    j += "  \"latency_ms\": {\"p50\": " + num(s.latency_p50_ms) + ", \"p95\": " + num(s.latency_p95_ms) + "},\n";
    j += "  \"ms\": " + msJson(s.ms_mean) + ",\n";
    j += "  \"snapshot\": {\"count\": " + std::to_string(s.snapshot_seq) + ", \"copy_ms\": " + num(s.snapshot_copy_ms) +
         ", \"mesh_ms\": " + num(s.snapshot_mesh_ms) + ", \"encode_ms\": " + num(s.snapshot_encode_ms) + "},\n";
    j += "  \"mesh\": {\"vertices\": " + std::to_string(m.vertex_count) +
         ", \"triangles\": " + std::to_string(m.triangle_count) + "},\n";
    j += "  \"finish\": " + finish_json + ",\n";
    j += "  \"texture\": " + texture_json + ",\n";
    j += "  \"camera\": " + camera + ",\n";
    j += "  \"params\": {\"preset\": \"" + params_.preset +
         "\", \"tsdf\": {\"resolution_vox\": " + std::to_string(r.tsdf.resolution_vox) +
         ", \"volume_size_m\": " + num(r.tsdf.volume_size_m) + ", \"voxel_size_m\": " + num(r.tsdf.voxelSizeM()) +
         ", \"trunc_dist_m\": " + num(r.tsdf.trunc_dist_m) + ", \"max_weight\": " + num(r.tsdf.max_weight) +
         "}, \"icp\": {\"levels\": " + std::to_string(r.icp.levels) + ", \"iterations\": [" +
         std::to_string(r.icp.iterations[0]) + ", " + std::to_string(r.icp.iterations[1]) + ", " +
         std::to_string(r.icp.iterations[2]) + "]}, \"filter\": {\"sigma_space_px\": " + num(r.filter.sigma_space_px) +
         ", \"sigma_depth_m\": " + num(r.filter.sigma_depth_m) + "}, \"snapshot_hz\": " + num(params_.snapshot_hz) +
         ", \"snapshot_stride_vox\": " + std::to_string(params_.snapshot_stride_vox) + "}\n";
    j += "}\n";
    return j;
}

}  // namespace facescan::service
