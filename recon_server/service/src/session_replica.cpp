// A session's part in the cluster: building its engine (from a CameraInfo or a replica's state, on a
// thread of the server's own), restoring from a replica, and taking replicas on the worker between two frames.
// Knows nothing of DDS or files: the server's replication thread encodes, sends and stores them.
#include <algorithm>
#include <cstdio>
#include <future>

#include "recon/sensor_adapt.hpp"
#include "service/session.hpp"

namespace facescan::service {

StatusOr<SessionEngine> SessionEngine::build(const ServerParams& params, const wire::CameraInfoData& camera,
                                             const wire::ReplicaData* replica) {
    if (replica && !replica->full()) return invalidArgument("a session can only be restored from a full replica");
    recon::ReconParams recon_params = params.recon;
    recon_params.source_fps =
        camera.rate_hz > 0.0f && camera.rate_hz <= 1000.0f ? camera.rate_hz : 0.0f;  // limits per frame
    SessionEngine e;
    // Depth windows, pixel thresholds and the distance advice from the camera the agent described.
    recon::FacePipelineParams face_params = params.face;
    // How the camera is held: the server's own face.roll when set, else the agent's hint (--roll), else found
    // from the frames.
    static_assert(wire::CameraInfoData::kRollUnknown == recon::FacePipelineParams::kRollAuto);
    const bool roll_from_agent =
        face_params.roll_deg == recon::FacePipelineParams::kRollAuto && camera.roll_deg != camera.kRollUnknown;
    if (roll_from_agent) face_params.roll_deg = camera.roll_deg;
    recon::adaptToSensor(camera.sensor, camera.intrinsics, recon_params, face_params, e.advice);
    e.camera_line = recon::describeSensor(camera.sensor, e.advice, recon_params.tsdf);
    if (face_params.roll_deg != recon::FacePipelineParams::kRollAuto) {
        e.camera_line += "; held at roll " + std::to_string(face_params.roll_deg) +
                         (roll_from_agent ? " deg (the agent's --roll)" : " deg (face.roll)");
    }
    e.recon = std::make_shared<recon::Reconstructor>(camera.intrinsics, recon_params);
    if (!e.recon->initStatus().isOk()) return e.recon->initStatus();
    if (replica) RETURN_IF_ERROR(e.recon->restoreState(replica->state));
    auto pipeline = recon::FacePipeline::create(face_params, camera.intrinsics,
                                                recon::ColourCamera::registeredTo(camera.intrinsics));
    if (!pipeline.isOk()) return pipeline.status();
    e.pipeline = std::make_unique<recon::FacePipeline>(std::move(pipeline).value());
    return e;
}

Status Session::restore(const wire::ReplicaData& replica, int64_t takeover_from_ns, SessionEngine engine) {
    if (!replica.full()) return invalidArgument("a session can only be restored from a full replica");
    return start(replica.camera, &replica, takeover_from_ns, std::move(engine));
}

void Session::applyReplicaLocked(const wire::ReplicaData& r, int64_t takeover_from_ns) {
    const wire::SessionCounters& c = r.counters;
    stats_.frames_received = c.frames_received;
    stats_.frames_integrated = c.frames_integrated;
    stats_.frames_rejected = c.frames_rejected;
    stats_.frames_skipped = c.frames_skipped;
    stats_.frames_dropped = c.frames_dropped;
    stats_.frames_tracked_only = c.frames_tracked_only;
    stats_.snapshot_seq = c.snapshot_seq;
    stats_.failovers = c.failovers + 1;
    stats_.last_takeover_ms = c.last_takeover_ms;
    stats_.frames_digest = c.frames_digest;
    stats_.state = c.frames_integrated > 0 ? SessionState::kScanning : SessionState::kWaiting;
    stats_.detail = "resumed at frame " + std::to_string(r.next_seq) + " (" + std::to_string(c.frames_integrated) +
                    " frames integrated)";
    processed_before_ = c.frames_processed;
    duration_before_s_ = c.duration_s;
    next_seq_ = processed_next_seq_ = r.next_seq;
    trajectory_ = r.state.trajectory;
    last_pose_ = r.state.T_world_camera;
    replica_generation_ = r.state.generation;
    replica_trajectory_ = r.state.trajectorySize();
    // The old owner's texture views (their poses are in the restored model's frame); the worker has not started.
    if (r.has_keyframes) keyframes_.restore(r.keyframes);
    takeover_from_ns_ = takeover_from_ns;
    takeover_started_ns_ = steadyNowNs();
    takeover_received_ns_ = 0;
}

void Session::noteTakeoverFromFirstFrame(uint32_t failovers_before, int64_t takeover_from_ns) {
    std::lock_guard lk(mutex_);
    stats_.failovers = failovers_before + 1;
    takeover_from_ns_ = takeover_from_ns;
    takeover_started_ns_ = steadyNowNs();
    takeover_received_ns_ = 0;
}

void Session::noteFirstFrameAfterTakeover(uint32_t seq, int64_t now_ns) {
    stats_.last_takeover_ms = static_cast<float>(static_cast<double>(now_ns - takeover_from_ns_) * 1e-6);
    // Where the time went: noticing the owner gone and settling the claim (started here), then the agent finding
    // this server's reader (first frame here), then the pipeline finding the face again.
    const auto since_ms = [&](int64_t t_ns) {
        return t_ns > 0 ? static_cast<double>(t_ns - takeover_from_ns_) * 1e-6 : -1.0;
    };
    const double started_ms = since_ms(takeover_started_ns_), received_ms = since_ms(takeover_received_ns_);
    takeover_from_ns_ = takeover_started_ns_ = takeover_received_ns_ = 0;
    // The wall clock too: tests/bench/cluster.sh measures from the moment it killed the old owner.
    std::fprintf(stderr,
                 "facescan-server: session %s: first frame integrated after the takeover (frame %u, %.0f ms after the "
                 "old owner's last sign of life, at realtime_ns %lld; started here after %.0f ms, first frame here "
                 "after %.0f ms)\n",
                 id_.c_str(), seq, static_cast<double>(stats_.last_takeover_ms),
                 static_cast<long long>(realtimeNowNs()), started_ms, received_ms);
}

void Session::setOwnership(const std::string& owner_id, uint32_t epoch) {
    std::lock_guard lk(mutex_);
    stats_.owner_id = owner_id;
    stats_.epoch = epoch;
}

void Session::setStandby(const std::string& standby_id) {
    std::lock_guard lk(mutex_);
    stats_.standby_id = standby_id;
}

void Session::captureOnWorker(bool full, ReplicaCapture& out) {
    recon_->captureState(full ? 0 : replica_generation_, full ? 0 : replica_trajectory_, out.state);
    replica_generation_ = out.state.generation;
    replica_trajectory_ = out.state.trajectorySize();
    // The keyframes are the worker's (it offers them): taken here, between two frames, like the state.
    out.has_keyframes = full || keyframes_.version() != replica_keyframes_version_;
    out.keyframes.clear();
    if (out.has_keyframes) {
        out.keyframes = keyframes_.save();
        replica_keyframes_version_ = keyframes_.version();
    }
    std::lock_guard lk(mutex_);
    out.camera = *camera_;
    out.next_seq = processed_next_seq_;
    wire::SessionCounters& c = out.counters;
    // Frames taken but not processed yet are not in the state: the agent resends them to whoever continues.
    const auto queued = static_cast<uint32_t>(
        std::count_if(queue_.begin(), queue_.end(), [](const PendingFrame& f) { return !f.end_of_stream; }));
    c.frames_received = stats_.frames_received - std::min(queued, stats_.frames_received);
    c.frames_integrated = stats_.frames_integrated;
    c.frames_rejected = stats_.frames_rejected;
    c.frames_skipped = stats_.frames_skipped;
    c.frames_dropped = stats_.frames_dropped;
    c.frames_tracked_only = stats_.frames_tracked_only;
    c.snapshot_seq = stats_.snapshot_seq;
    c.failovers = stats_.failovers;
    c.last_takeover_ms = stats_.last_takeover_ms;
    c.frames_processed = processed_before_ + processed_count_;
    c.duration_s = duration_before_s_ +
                   (processed_count_ > 0 ? static_cast<double>(last_processed_ns_ - first_processed_ns_) * 1e-9 : 0.0);
    c.frames_digest = stats_.frames_digest;
}

Status Session::captureReplica(bool full, ReplicaCapture& out, std::chrono::milliseconds timeout) {
    auto done = std::make_shared<std::promise<Status>>();
    // `out`'s buffers go to the worker and come back: the caller may hand in last round's capture to reuse them.
    auto result = std::make_shared<ReplicaCapture>(std::move(out));
    std::future<Status> outcome = done->get_future();
    {
        std::lock_guard lk(mutex_);
        if (finishing_ || stats_.state == SessionState::kFinished || !worker_.joinable() || !recon_) {
            return unavailable("session '" + id_ + "' has no model to replicate");
        }
        control_.push_back({Control::kRun, "", [done](const Status& s) { done->set_value(s); }, nullptr,
                            [this, full, result] { captureOnWorker(full, *result); }});
    }
    cv_.notify_all();
    if (outcome.wait_for(timeout) != std::future_status::ready) {
        return deadlineExceeded("session '" + id_ + "': the worker did not take the replica in time");
    }
    RETURN_IF_ERROR(outcome.get());
    out = std::move(*result);
    return Status::ok();
}

}  // namespace facescan::service
