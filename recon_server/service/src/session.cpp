#include "service/session.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>

#include "recon/marching_cubes.hpp"
#include "recon/parallel.hpp"
#include "service/session_store.hpp"
#include "wire/mesh_codec.hpp"

namespace facescan::service {
namespace {

constexpr size_t kLatencyWindow = 512;  // frames; latency percentiles are over the last this many tracked frames
constexpr size_t kMaxFrameTimings = 30 * 3600;   // frames.tsv keeps a session's first hour (2.6 MB)
constexpr int64_t kFpsWindowNs = 2'000'000'000;  // the status fps counts frames processed in the last 2 s
constexpr float kEmaAlpha = 0.1f;                // per-stage ms in the status: exponential average over ~10 frames
constexpr float kBehindSkipFraction = 0.1f;      // a live session skipping more of its recent frames is behind

void emaUpdate(recon::StageTimesMs& avg, const recon::StageTimesMs& x, bool first) {
    const float a = first ? 1.0f : kEmaAlpha;
    avg.detect += a * (x.detect - avg.detect);
    avg.segment += a * (x.segment - avg.segment);
    avg.filter += a * (x.filter - avg.filter);
    avg.icp += a * (x.icp - avg.icp);
    avg.integrate += a * (x.integrate - avg.integrate);
    avg.raycast += a * (x.raycast - avg.raycast);
}

void accumulate(recon::StageTimesMs& sum, const recon::StageTimesMs& x) {
    sum.detect += x.detect;
    sum.segment += x.segment;
    sum.filter += x.filter;
    sum.icp += x.icp;
    sum.integrate += x.integrate;
    sum.raycast += x.raycast;
}

float percentile(std::vector<float> v, float q) {
    if (v.empty()) return 0;
    const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * static_cast<float>(v.size() - 1) + 0.5f));
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
    return v[k];
}

// Live snapshots: the coarse stride of --snapshot-stride, otherwise the final mesh's parameters.
recon::MeshParams snapshotMeshParams(const ServerParams& params) {
    recon::MeshParams mp = params.recon.mesh;
    mp.stride_vox = params.snapshot_stride_vox;
    return mp;
}

}  // namespace

int64_t steadyNowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}
int64_t realtimeNowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

const char* sessionStateName(SessionState state) {
    switch (state) {
        case SessionState::kWaiting: return "waiting";
        case SessionState::kScanning: return "scanning";
        case SessionState::kLost: return "tracking lost";
        case SessionState::kFinished: return "finished";
        case SessionState::kRefused: return "refused";
    }
    return "?";
}

void PendingFrame::assign(const facescan_wire_RgbdFrame& msg) {
    seq = msg.seq;
    capture_time_ns = msg.capture_time_ns;
    source_time_ns = msg.source_time_ns;
    depth_codec = static_cast<uint32_t>(msg.depth_codec);
    colour_codec = static_cast<uint32_t>(msg.colour_codec);
    end_of_stream = msg.end_of_stream;
    // A malformed sample may claim bytes without a buffer: keep what is there, the decoder reports the rest.
    depth.assign(msg.depth._buffer, msg.depth._buffer ? msg.depth._buffer + msg.depth._length : msg.depth._buffer);
    colour.assign(msg.colour._buffer,
                  msg.colour._buffer ? msg.colour._buffer + msg.colour._length : msg.colour._buffer);
}

facescan_wire_RgbdFrame PendingFrame::view() const {
    facescan_wire_RgbdFrame msg{};
    msg.seq = seq;
    msg.capture_time_ns = capture_time_ns;
    msg.source_time_ns = source_time_ns;
    msg.depth_codec = static_cast<facescan_wire_DepthCodec>(depth_codec);
    msg.depth = wire::octetView(depth.data(), depth.size());
    msg.colour_codec = static_cast<facescan_wire_ColourCodec>(colour_codec);
    msg.colour = wire::octetView(colour.data(), colour.size());
    msg.end_of_stream = end_of_stream;
    return msg;
}

Session::Session(std::string session_id, const ServerParams& params, std::function<void()> space_freed)
    : id_(std::move(session_id)),
      params_(params),
      space_freed_(std::move(space_freed)),
      snapshot_mesher_(snapshotMeshParams(params)) {
    keyframes_ = TextureKeyframes(params_.texture_keyframes);
    stats_.session_id = id_;
    stats_.detail = "waiting for CameraInfo";
    latency_ms_.reserve(kLatencyWindow);
    frame_timings_.reserve(30 * 60);  // a minute at 30 Hz before the vector first grows
    last_activity_ns_ = steadyNowNs();
}

Session::~Session() {
    {
        std::lock_guard lk(mutex_);
        stop_ = true;
        queue_.clear();
    }
    cv_.notify_all();
    // A Session ends on the server's retiring thread (retirer.hpp): its worker must never hold the last reference,
    // since joining itself aborts the process.
    if (worker_.joinable()) worker_.join();
    for (Control& c : control_) {  // never leave a waiting caller without an answer
        if (c.kind == Control::kRun && c.reset_done) c.reset_done(unavailable("session '" + id_ + "' is closed"));
    }
}

void Session::setWatch(std::shared_ptr<Watchdog::Beat> beat, std::function<bool()> hold) {
    std::lock_guard lk(mutex_);
    beat_ = std::move(beat);
    hold_ = std::move(hold);
}

void Session::abandon(bool discard_written) {
    std::deque<Control> dropped;
    {
        std::lock_guard lk(mutex_);
        stop_ = true;
        discard_written_ = discard_written;
        queue_.clear();
        dropped.swap(control_);  // unanswered: the new owner answers these commands
    }
    cv_.notify_all();
}

Status Session::setCamera(const wire::CameraInfoData& camera, SessionEngine engine) {
    return start(camera, nullptr, 0, std::move(engine));
}

Status Session::start(const wire::CameraInfoData& camera, const wire::ReplicaData* replica, int64_t takeover_from_ns,
                      SessionEngine engine) {
    std::unique_lock lk(mutex_);
    last_activity_ns_ = steadyNowNs();
    if (finishing_ || stats_.state == SessionState::kFinished) return Status::ok();
    if (camera_) {
        if (replica) return invalidArgument("session '" + id_ + "' is already running: no replica to restore");
        const recon::Intrinsics& a = camera_->intrinsics;
        const recon::Intrinsics& b = camera.intrinsics;
        if (a.width_px != b.width_px || a.height_px != b.height_px || a.fx_px != b.fx_px || a.fy_px != b.fy_px ||
            a.cx_px != b.cx_px || a.cy_px != b.cy_px || camera_->depth_units_m != camera.depth_units_m) {
            return invalidArgument("CameraInfo of session '" + id_ + "' changed mid-session; ignored");
        }
        return Status::ok();
    }
    lk.unlock();
    if (!engine.recon || !engine.pipeline) {
        ASSIGN_OR_RETURN(engine, SessionEngine::build(params_, camera, replica));  // outside the lock: a moment
    }
    lk.lock();
    if (camera_ || finishing_) return Status::ok();
    camera_ = camera;
    recon_ = std::move(engine.recon);
    pipeline_ = std::move(engine.pipeline);
    advice_ = engine.advice;
    recon_params_ = recon_->params();
    stats_.camera_known = true;
    stats_.every_frame = camera.every_frame;
    stats_.source = camera.source;
    stats_.detail = "waiting for frames; camera " + engine.camera_line;
    if (replica) applyReplicaLocked(*replica, takeover_from_ns);
    // A live session keeps only the newest of what arrived before its CameraInfo.
    if (!camera.every_frame) {
        while (queue_.size() > 1 && !queue_.front().end_of_stream) {
            spare_.push_back(std::move(queue_.front()));
            queue_.pop_front();
            ++stats_.frames_skipped;
        }
    }
    load_ = std::make_unique<FrameLoad>(camera.rate_hz);
    worker_ = std::thread([this] { workerLoop(); });
    lk.unlock();
    cv_.notify_all();
    return Status::ok();
}

int Session::roomForFrames() const {
    constexpr int kUnbounded = 1 << 20;
    std::lock_guard lk(mutex_);
    if (finishing_ || stats_.state == SessionState::kFinished) return kUnbounded;  // taken and discarded
    if (camera_ && !camera_->every_frame) return kUnbounded;                       // live: the newest wins
    return std::max(0, params_.queue_frames - static_cast<int>(queue_.size()));
}

FrameFate Session::pushFrame(const facescan_wire_RgbdFrame& msg) {
    last_activity_ns_ = steadyNowNs();
    std::unique_lock lk(mutex_);
    if (finishing_ || stats_.state == SessionState::kFinished) return FrameFate::kIgnored;
    const bool recording = camera_ && camera_->every_frame;
    if (msg.seq < next_seq_) return recording ? FrameFate::kDuplicate : FrameFate::kIgnored;
    // A recording is integrated in order: a frame after a gap (sent while a new owner took over) waits for the
    // agent to resend from next_seq_, unless the agent no longer holds those frames: an earlier owner confirmed
    // them and its copy was lost with it (its standby died too). They are counted dropped and said so, and the
    // scan goes on from the oldest frame that exists; waiting would hold the scan and its agent for ever.
    if (recording && msg.seq > next_seq_ && msg.oldest_kept_seq > next_seq_) {
        const uint32_t lost = msg.oldest_kept_seq - next_seq_;
        stats_.frames_dropped += lost;
        if (!frames_lost_note_.empty()) frames_lost_note_ += "; ";
        frames_lost_note_ += "frames " + std::to_string(next_seq_) + "-" + std::to_string(msg.oldest_kept_seq - 1) +
                             " lost: an earlier owner confirmed them and no copy survived it";
        std::fprintf(stderr,
                     "facescan-server: session %s: frames %u-%u lost: an earlier owner confirmed them and no copy "
                     "survived it (%u frames); going on from frame %u\n",
                     id_.c_str(), next_seq_, msg.oldest_kept_seq - 1, lost, msg.oldest_kept_seq);
        next_seq_ = msg.oldest_kept_seq;
    }
    if (recording && msg.seq > next_seq_) return FrameFate::kAhead;
    if (msg.seq > next_seq_) stats_.frames_dropped += msg.seq - next_seq_;  // live: lost on the way
    next_seq_ = msg.seq + 1;
    if (takeover_from_ns_ != 0 && takeover_received_ns_ == 0) takeover_received_ns_ = steadyNowNs();
    if (camera_ && !camera_->every_frame && !msg.end_of_stream) {
        // Live: anything still waiting is older than this frame and will never be worth processing.
        while (!queue_.empty() && !queue_.back().end_of_stream) {
            spare_.push_back(std::move(queue_.back()));
            queue_.pop_back();
            ++stats_.frames_skipped;
        }
    }
    PendingFrame slot;
    if (!spare_.empty()) {
        slot = std::move(spare_.back());
        spare_.pop_back();
    }
    lk.unlock();
    slot.assign(msg);  // the copy out of the loan, outside the lock
    lk.lock();
    // Counted received as it enters the queue, under the same lock: a replica captured meanwhile subtracts the
    // queued frames from the received ones, and a frame counted before it was queued was counted twice once
    // the agent resent it to whoever continued from that replica.
    if (!msg.end_of_stream) ++stats_.frames_received;
    queue_.push_back(std::move(slot));
    lk.unlock();
    cv_.notify_all();
    return FrameFate::kAccepted;
}

uint32_t Session::nextSeq() const {
    std::lock_guard lk(mutex_);
    return next_seq_;
}

void Session::noteWriterGone() {
    std::lock_guard lk(mutex_);
    if (finishing_ || stats_.state == SessionState::kFinished) return;
    stats_.state = SessionState::kWaiting;
    stats_.detail = "agent gone";
}

bool Session::finished() const {
    std::lock_guard lk(mutex_);
    return stats_.state == SessionState::kFinished;
}

bool Session::finishing() const {
    std::lock_guard lk(mutex_);
    return finishing_ && stats_.state != SessionState::kFinished;
}

void Session::requestReset(std::function<void(const Status&)> done) {
    std::unique_lock lk(mutex_);
    if (stats_.state == SessionState::kFinished || finishing_) {
        lk.unlock();
        done(invalidArgument("session '" + id_ + "' is finished: nothing to reset"));
        return;
    }
    if (!worker_.joinable()) {
        lk.unlock();
        done(Status::ok());  // no model yet: nothing to clear
        return;
    }
    control_.push_back({Control::kReset, "", std::move(done), nullptr, nullptr});
    lk.unlock();
    cv_.notify_all();
}

void Session::requestFinish(const std::string& why, FinishCallback done) {
    std::unique_lock lk(mutex_);
    if (stop_) return;  // given up (abandon) or closing: the owner now is another server
    if (stats_.state == SessionState::kFinished) {
        const MeshResult m = final_mesh_;
        lk.unlock();
        if (done) done(Status::ok(), m);
        return;
    }
    if (finishing_ && !done) return;  // already on its way (e.g. the idle check repeating itself)
    if (worker_.joinable() || finishing_) {
        control_.push_back({Control::kFinish, why, nullptr, std::move(done), nullptr});
        lk.unlock();
        cv_.notify_all();
        return;
    }
    // No worker (no CameraInfo ever came): finish here.
    finishing_ = true;
    lk.unlock();
    finalize(why, done);
}

void Session::workerLoop() {
    recon::nameThisThread(("fs-s " + id_).c_str());  // "fs-s rt1": top -H shows which session a busy core serves
    load_->join();
    struct Leave {
        FrameLoad& load;
        Watchdog::Beat* beat;  // a worker that ended is not stuck in its last step
        ~Leave() {
            load.leave();
            if (beat) beat->end();
        }
    } leave{*load_, beat_.get()};
    // A recording has no deadline: its agent keeps every frame until it is confirmed and waits for the server, so a
    // loaded server makes it take longer, never come out worse. The economy steps (a cheaper model cast, frames
    // tracked but not fused) are for live scans, which must keep up with the camera.
    const bool economy = camera_ && !camera_->every_frame;
    if (economy) applyEconomy(*load_, params_.recon, id_, *recon_);  // a session joining busy ones starts at their step
    for (;;) {
        std::unique_lock lk(mutex_);
        if (beat_) beat_->end();
        cv_.wait(lk, [&] { return stop_ || !control_.empty() || !queue_.empty(); });
        if (!stop_ && hold_ && hold_()) {
            // The server's view of the cluster is stale: nothing is integrated, finished or written until it knows
            // whether it still owns this session. Frames wait in the queue meanwhile.
            cv_.wait_for(lk, std::chrono::milliseconds(20), [&] { return stop_; });
            continue;
        }
        if (beat_) beat_->begin();
        if (!control_.empty()) {
            Control c = std::move(control_.front());
            control_.pop_front();
            if (c.kind == Control::kFinish) {
                finishing_ = true;
                stats_.frames_skipped += static_cast<uint32_t>(
                    std::count_if(queue_.begin(), queue_.end(), [](const auto& f) { return !f.end_of_stream; }));
                queue_.clear();
                lk.unlock();
                if (space_freed_) space_freed_();
                finalize(c.why, c.finish_done);
                return;
            }
            if (c.kind == Control::kRun) {
                lk.unlock();
                c.run();
                c.reset_done(Status::ok());
                continue;
            }
            lk.unlock();
            recon_->reset();
            pipeline_->reset();
            keyframes_.clear();  // their poses are in the old model's frame
            lk.lock();
            trajectory_.clear();
            last_pose_ = recon::Pose::Identity();
            snapshot_frames_ = -1;
            stats_.detail = "model reset";
            lk.unlock();
            c.reset_done(Status::ok());
            continue;
        }
        if (queue_.empty()) return;  // stop_ with nothing left
        const bool was_full = static_cast<int>(queue_.size()) >= params_.queue_frames;
        std::swap(working_, queue_.front());
        queue_.pop_front();
        lk.unlock();
        if (was_full && space_freed_) space_freed_();
        if (working_.end_of_stream) {
            {
                std::lock_guard g(mutex_);
                finishing_ = true;
            }
            finalize("end of stream", nullptr);
            return;
        }
        const uint64_t digest =
            wire::frameDigest(stats_.frames_digest, working_.depth.data(), working_.depth.size(),
                              working_.colour.data(), working_.colour.size());  // the worker alone writes it
        FrameTiming timing;
        timing.seq = working_.seq;
        timing.queued_ms = static_cast<float>(realtimeNowNs() - working_.capture_time_ns) * 1e-6f;
        timing.economy_step = static_cast<uint8_t>(load_->economy());
        const int64_t start_ns = steadyNowNs();
        load_->beginFrame();
        timing.outcome = processFrame(working_);
        load_->endFrame();
        timing.processing_ms = static_cast<float>(steadyNowNs() - start_ns) * 1e-6f;
        timing.cpu_ms = load_->lastFrameMs();
        if (frame_timings_.size() < kMaxFrameTimings) frame_timings_.push_back(timing);
        recon_->setSearchEvery(load_->searchEvery());  // a lost session over budget searches less often
        if (economy) applyEconomy(*load_, params_.recon, id_, *recon_);
        noteLoad();
        copySnapshotIfAsked();
        lk.lock();
        stats_.frames_digest = digest;
        processed_next_seq_ = working_.seq + 1;
        spare_.push_back(std::move(working_));
        working_ = PendingFrame();
    }
}

char Session::processFrame(PendingFrame& pending) {
    const int64_t t0 = steadyNowNs();
    // camera_ is set once before the worker starts: no lock to read it. Colour on demand: a frame only tracked
    // decodes none, a fused one only its head's region.
    const Status decoded = decoder_.decode(pending.view(), *camera_, wire::ColourDecode::kOnDemand, frame_);
    if (!decoded.isOk()) {
        std::lock_guard lk(mutex_);
        ++stats_.frames_dropped;
        stats_.detail = "frame " + std::to_string(pending.seq) + " dropped: " + decoded.message();
        return 'D';
    }
    // The model's prediction seeds the segmentation, detection otherwise; a frame without a head counts as
    // rejected, and the next head after a loss is verified before it is fused (recon/scan_step.hpp).
    recon::scanFrame(*pipeline_, *recon_, frame_, step_, advice_);
    const char outcome = !step_.head.found || !step_.frame.tracked ? 'R' : step_.frame.integrated ? 'F' : 'T';
    const Status colour = decoder_.colourStatus();  // damaged colour costs the frame its colour, not its depth
    // The texture's keyframes: the colour payload as received, with the pose just tracked. A restarted model has a
    // new world frame, in which the old keyframes' poses mean nothing.
    if (step_.frame.restarted) keyframes_.clear();
    if (step_.head.found && step_.frame.tracked && colour.isOk()) {
        keyframes_.offer(pending.seq, static_cast<wire::ColourCodecId>(pending.colour_codec), pending.colour,
                         recon_->lastPose());
    }
    decoder_.releaseColour();  // pending's bytes are recycled after this frame
    const recon::HeadObservation& head = step_.head;
    const recon::FrameResult& r = step_.frame;
    const int64_t pose_known_ns = realtimeNowNs();
    const int64_t now = steadyNowNs();
    // What the person should do comes first in the status detail ("face lost: hold still (...)").
    auto detail = [&](std::string what) {
        if (!colour.isOk()) what += "; frame " + std::to_string(pending.seq) + " without colour: " + colour.message();
        return *step_.advice ? std::string(step_.advice) + " (" + what + ")" : what;
    };

    std::lock_guard lk(mutex_);
    if (processed_count_ == 0) first_processed_ns_ = t0;
    last_processed_ns_ = now;
    ++processed_count_;
    processed_ns_.push_back(now);
    while (!processed_ns_.empty() && processed_ns_.front() < now - kFpsWindowNs) processed_ns_.pop_front();
    emaUpdate(stats_.ms, r.ms, ms_count_ == 0);
    accumulate(ms_sum_, r.ms);
    ++ms_count_;
    if (!head.found) {
        ++stats_.frames_rejected;
        stats_.state = stats_.frames_integrated > 0 ? SessionState::kLost : SessionState::kWaiting;
        stats_.detail = detail("no face: " + head.reason);
        return outcome;
    }
    if (r.tracked) {
        // A frame tracked but not fused (the load's last economy step) has its pose and latency like any other.
        ++(r.integrated ? stats_.frames_integrated : stats_.frames_tracked_only);
        stats_.state = SessionState::kScanning;
        stats_.detail = detail(head.depth_only ? "face found (depth only)" : "face found");
        if (r.restarted) trajectory_.clear();  // a model of one frame restarted: world = this frame's camera
        if (!recon_->trajectory().empty()) trajectory_.push_back(recon_->trajectory().back());
        last_pose_ = recon_->lastPose();
        if (takeover_from_ns_ != 0) noteFirstFrameAfterTakeover(pending.seq, now);
        recordLatency(static_cast<float>(pose_known_ns - pending.capture_time_ns) * 1e-6f);
        return outcome;
    }
    ++stats_.frames_rejected;
    stats_.state = r.reacquiring ? SessionState::kLost : SessionState::kScanning;
    stats_.detail = detail(std::string("frame rejected: ") + r.reason);
    return outcome;
}

void Session::noteLoad() {
    std::lock_guard lk(mutex_);
    // Frames skipped since the last processed one: live sessions keep only the newest, so a slow frame shows here.
    const auto skipped = static_cast<float>(stats_.frames_skipped - skipped_at_last_frame_);
    skipped_at_last_frame_ = stats_.frames_skipped;
    stats_.skipped_recent += FrameLoad::kEmaAlpha * (skipped / (skipped + 1.0f) - stats_.skipped_recent);
    load_->noteSkipped(stats_.skipped_recent);
    stats_.throttled = load_->throttled();
    stats_.frame_cpu_ms = load_->costMs();
    stats_.frame_budget_ms = load_->budgetMs();
}

void Session::recordLatency(float ms) {
    if (latency_ms_.size() < kLatencyWindow) {
        latency_ms_.push_back(ms);
    } else {
        latency_ms_[latency_next_] = ms;
        latency_next_ = (latency_next_ + 1) % kLatencyWindow;
    }
}

SessionStats Session::stats() const {
    std::lock_guard lk(mutex_);
    SessionStats s = stats_;
    const int64_t now = steadyNowNs();
    if (stats_.state == SessionState::kFinished) {
        s.fps = s.duration_s > 0
                    ? static_cast<float>(static_cast<double>(processed_before_ + processed_count_) / s.duration_s)
                    : 0;
    } else if (!processed_ns_.empty()) {
        int n = 0;
        for (const int64_t t : processed_ns_) n += t >= now - kFpsWindowNs ? 1 : 0;
        const double window_s = std::min<double>(kFpsWindowNs, static_cast<double>(now - first_processed_ns_)) * 1e-9;
        s.fps = window_s > 0.2 ? static_cast<float>(n / window_s) : 0;
    }
    if (ms_count_ > 0) {
        const float inv = 1.0f / static_cast<float>(ms_count_);
        s.ms_mean = {ms_sum_.detect * inv,
                     ms_sum_.segment * inv,
                     ms_sum_.filter * inv,
                     ms_sum_.icp * inv,
                     ms_sum_.integrate * inv,
                     ms_sum_.raycast * inv,
                     0};
    }
    // Only while frames flow ("agent gone" stays the whole detail); while lost, the advice to the person first.
    const bool lost = stats_.state == SessionState::kLost;
    const bool flowing = !processed_ns_.empty() && processed_ns_.back() >= now - kFpsWindowNs;
    s.behind = !s.every_frame && stats_.state != SessionState::kFinished && flowing &&
               (s.throttled || s.skipped_recent > kBehindSkipFraction);
    if (s.behind) {
        char what[160];
        std::snprintf(what, sizeof what, "behind: %.0f %% of frames skipped, %.0f ms of CPU a frame (budget %.0f ms)%s",
                      100.0f * s.skipped_recent, s.frame_cpu_ms, s.frame_budget_ms, s.throttled ? ", throttled" : "");
        s.detail = lost ? s.detail + "; " + what : std::string(what) + "; " + s.detail;
    }
    if (!frames_lost_note_.empty())
        s.detail = s.detail.empty() ? frames_lost_note_ : s.detail + "; " + frames_lost_note_;
    s.latency_p50_ms = percentile(latency_ms_, 0.5f);
    s.latency_p95_ms = percentile(latency_ms_, 0.95f);
    if (stats_.state != SessionState::kFinished) {
        s.duration_s = duration_before_s_;
        if (processed_count_ > 0) s.duration_s += static_cast<double>(last_processed_ns_ - first_processed_ns_) * 1e-9;
    }
    s.next_seq = next_seq_;
    return s;
}

std::string Session::trajectoryTum() const {
    std::lock_guard lk(mutex_);
    std::string out;
    out.reserve(trajectory_.size() * 80);
    for (const auto& [t_ns, pose] : trajectory_) out += recon::toTumLine(t_ns, pose) + "\n";
    return out;
}

StatusOr<MeshResult> Session::mesh() {
    std::shared_ptr<recon::Reconstructor> rec;
    {
        std::lock_guard lk(mutex_);
        if (stats_.state == SessionState::kFinished) {
            if (!final_mesh_.draco) return notFound("session '" + id_ + "' finished without a surface");
            return final_mesh_;
        }
        rec = recon_;
    }
    if (!rec) return unavailable("session '" + id_ + "' has no model yet (no CameraInfo)");
    recon::TsdfSnapshot grid;
    rec->copyVolume(grid);  // under the volume's short lock; meshed without it
    const recon::IndexedMesh m = recon::extractTriangles(grid, params_.recon.mesh);
    if (m.triangles.empty()) return unavailable("session '" + id_ + "' has no surface yet");
    return encodeMesh(m, meshCodecParams(grid, wire::MeshCodecParams{}.max_position_error_m));
}

StatusOr<std::vector<uint8_t>> Session::previewPng() {
    std::shared_ptr<recon::Reconstructor> rec;
    recon::Pose pose;
    {
        std::lock_guard lk(mutex_);
        if (stats_.state == SessionState::kFinished) {
            if (final_preview_png_.empty()) return notFound("session '" + id_ + "' finished without a model");
            return final_preview_png_;
        }
        rec = recon_;
        pose = last_pose_;
    }
    if (!rec) return unavailable("session '" + id_ + "' has no model yet (no CameraInfo)");
    cv::Mat shaded;
    rec->renderPreview(pose, shaded);
    std::vector<uint8_t> png;
    if (shaded.empty() || !cv::imencode(".png", shaded, png)) return internalError("cannot render the preview");
    return png;
}

}  // namespace facescan::service
