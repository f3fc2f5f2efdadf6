// One scan session on the server: its CameraInfo, a frame slot (live: the newest frame only) or a bounded queue
// (recording: every frame), and a worker thread that runs decode -> detection/segmentation -> recon core.
// Knows nothing of DDS topics: the server routes samples in and publishes what the session reports.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "recon/face_pipeline.hpp"
#include "recon/marching_cubes.hpp"
#include "recon/reconstructor.hpp"
#include "recon/scan_step.hpp"
#include "service/frame_load.hpp"
#include "service/live_count.hpp"
#include "service/server_params.hpp"
#include "service/texture_keyframes.hpp"
#include "service/watchdog.hpp"
#include "wire/mesh_codec.hpp"
#include "wire/messages.hpp"
#include "wire/replica_codec.hpp"

namespace facescan::service {

enum class SessionState { kWaiting, kScanning, kLost, kFinished, kRefused };
const char* sessionStateName(SessionState state);

// A received RgbdFrame with its bytes copied out of the DDS loan (the loan goes back at once).
struct PendingFrame {
    uint32_t seq = 0;
    int64_t capture_time_ns = 0;  // agent CLOCK_REALTIME
    int64_t source_time_ns = 0;   // the source's timestamp (trajectory)
    uint32_t depth_codec = 0;
    uint32_t colour_codec = 0;
    bool end_of_stream = false;
    std::vector<uint8_t> depth;  // capacity reused frame to frame
    std::vector<uint8_t> colour;

    void assign(const facescan_wire_RgbdFrame& msg);
    // A message view over this frame's buffers (valid while this object is unchanged).
    facescan_wire_RgbdFrame view() const;
};

// A consistent copy of what the status and the summary report.
struct SessionStats {
    std::string session_id;
    SessionState state = SessionState::kWaiting;
    std::string detail;
    bool camera_known = false;
    bool every_frame = false;
    uint32_t frames_received = 0;
    uint32_t frames_integrated = 0;
    uint32_t frames_rejected = 0;
    uint32_t frames_skipped = 0;
    uint32_t frames_dropped = 0;
    uint32_t frames_tracked_only = 0;  // tracked but not fused: the load's last economy step (frame_load.hpp)
    float fps = 0;                     // frames processed per second, last ~2 s (status) or whole session (summary)
    recon::StageTimesMs ms;            // recent average per stage (status); ms.mesh = snapshot mesh + encode
    recon::StageTimesMs ms_mean;       // session mean per stage
    float latency_p50_ms = 0;          // capture (agent clock) to pose known, last 512 tracked frames
    float latency_p95_ms = 0;
    float snapshot_copy_ms = 0;    // last snapshot: volume copy (by the worker between frames, see SnapshotCopy)
    float snapshot_mesh_ms = 0;    // last snapshot: coarse marching cubes
    float snapshot_encode_ms = 0;  // last snapshot: Draco encode
    uint32_t snapshot_seq = 0;
    double duration_s = 0;  // first to last processed frame
    std::string source;
    // The cluster.
    std::string owner_id;    // this server, as the session's owner
    std::string standby_id;  // where its replicas go (empty: none)
    uint32_t epoch = 1;      // ownership epoch: 1, +1 per takeover
    uint32_t failovers = 0;
    float last_takeover_ms = 0;  // the owner's last sign of life to the first frame integrated after the takeover
    uint32_t next_seq = 0;       // the next frame the session takes (the agent resends from here)
    uint64_t frames_digest = wire::kFrameDigestSeed;  // of the frames processed, in order
    // Bad input: the worker's load (service/frame_load.hpp). A live session that is throttled or skips
    // more than kBehindSkipFraction of its recent frames is behind; stats() then says so in the detail, first
    // unless the face is lost (the advice to the person comes first then).
    bool behind = false;
    bool throttled = false;
    float frame_cpu_ms = 0;     // CPU a frame, recent average (pool workers' share included)
    float frame_budget_ms = 0;  // CPU a frame the session may use now
    float skipped_recent = 0;   // fraction of recent frames skipped (exponential average)
};

// What became of a received frame (Session::pushFrame).
enum class FrameFate {
    kAccepted,
    kDuplicate,  // already had it (a replay overlapping what arrived)
    kAhead,      // a recording's frame after a gap: dropped, the agent must resend from the session's next_seq
    kIgnored,    // finished, or older than the newest live frame
};

// A replica taken by the worker between two frames (captureReplica).
struct ReplicaCapture {
    wire::CameraInfoData camera;
    wire::SessionCounters counters;
    uint32_t next_seq = 0;  // frames before this one are in the state
    recon::ReconState state;
    bool has_keyframes = false;  // a full capture, or the keyframes changed since the last capture
    std::vector<wire::ReplicaKeyframe> keyframes;
};

struct MeshResult {
    std::shared_ptr<const std::vector<uint8_t>> draco;  // Draco with positions and colours (no normals)
    uint32_t vertex_count = 0;                          // of the mesh as encoded (cleaned on Draco's grid)
    uint32_t triangle_count = 0;
};

// Draco parameters for a mesh of `grid` (marching cubes): quantisation within max_error_m, aligned with the voxels.
wire::MeshCodecParams meshCodecParams(const recon::VoxelBlockGrid& grid, float max_error_m);
// Draco bytes of `mesh` and their counts; `encoded`, when given, receives the cleaned mesh the bytes hold.
StatusOr<MeshResult> encodeMesh(const recon::IndexedMesh& mesh, const wire::MeshCodecParams& params,
                                recon::IndexedMesh* encoded = nullptr);

struct SnapshotResult {
    uint32_t seq = 0;
    uint32_t frames_integrated = 0;
    MeshResult mesh;
};

// One processed frame's timings, written to the data dir as frames.tsv: where a loaded server's slow poses and
// skipped frames fell, which the summary's percentiles cannot say.
struct FrameTiming {
    uint32_t seq = 0;
    float queued_ms = 0;       // capture (the agent's clock) to the worker taking it: transport and the wait
    float processing_ms = 0;   // the worker's wall clock on it; capture to pose is about queued + processing
    float cpu_ms = 0;          // its CPU: the worker's thread and the pool's work for it (FrameLoad)
    uint8_t economy_step = 0;  // FrameLoad::economy() while it ran
    char outcome = 'D';        // F fused, T tracked only, R rejected (no face, or not fitted), D dropped (undecodable)
};

// Called once the session is finished (written to disk or not): ok, or why the files could not be written.
using FinishCallback = std::function<void(const Status&, const MeshResult&)>;

// What a session computes with: the reconstructor (from a replica's state when there is one) and the face pipeline.
// Building it allocates every per-frame buffer up front and loads the detector's cascade: 25 ms on an idle 2-core
// server, 100-130 ms with four sessions running. The server builds it on a thread of its own while the claim
// settles (server_cluster.cpp): on the intake thread, every other session got no frame meanwhile, and skipped them.
struct SessionEngine {
    std::shared_ptr<recon::Reconstructor> recon;
    std::unique_ptr<recon::FacePipeline> pipeline;
    recon::AdviceParams advice;  // the distance advice for this camera's range (recon/sensor_adapt.hpp)
    std::string camera_line;     // the camera as the status says it: range, advised distances, noise

    static StatusOr<SessionEngine> build(const ServerParams& params, const wire::CameraInfoData& camera,
                                         const wire::ReplicaData* replica);
};

class Session {
 public:
    // `space_freed` is called (from the worker) whenever a full frame queue gets room again.
    Session(std::string session_id, const ServerParams& params, std::function<void()> space_freed);
    ~Session();  // finishes (without writing) and joins the worker if still running
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;

    const std::string& id() const { return id_; }

    // --- intake thread ---
    // The first valid CameraInfo starts the worker with `engine` (built here when empty, as for that camera);
    // later ones must match it.
    Status setCamera(const wire::CameraInfoData& camera, SessionEngine engine = {});
    // How many more frames the session takes now: a recording (or a session whose CameraInfo has not arrived yet)
    // has a bounded queue; live sessions and finished ones take everything (live keeps the newest).
    int roomForFrames() const;
    // Recording frames are taken in order only (seq == next_seq); live frames when newer than the last one.
    FrameFate pushFrame(const facescan_wire_RgbdFrame& msg);
    void noteWriterGone();  // the agent's writer is gone (killed or exited without end of stream)
    int64_t lastActivityNs() const { return last_activity_ns_.load(); }

    // --- any thread ---
    void requestReset(std::function<void(const Status&)> done);
    // --- cluster (session_replica.cpp) ---
    // Instead of setCamera: continues from a replica (a takeover, or a restart from the data dir). `takeover_from_ns`
    // (steady clock) is the owner's last sign of life: the takeover time runs from there to the first frame
    // integrated here.
    // `engine`, when not empty, was built from this replica.
    Status restore(const wire::ReplicaData& replica, int64_t takeover_from_ns, SessionEngine engine = {});
    // After setCamera: the session starts over from its first frame because its dead owner left no replica (the
    // agent still keeps every frame); it counts as a failover, timed like one.
    void noteTakeoverFromFirstFrame(uint32_t failovers_before, int64_t takeover_from_ns);
    // Before the worker starts: `beat` times each of the worker's steps (the server's watchdog); while `hold` returns
    // true the worker takes nothing, neither a frame nor a finish: the server's view of the cluster is stale (it was
    // frozen) and it must not integrate, finish or write for a session that another server may own by now.
    void setWatch(std::shared_ptr<Watchdog::Beat> beat, std::function<bool()> hold);
    // This server gave the session up (another one owns it): the worker stops without finishing, nothing more is
    // written, replicated or answered for it here, and waiting callers are dropped unanswered (the new owner
    // answers). The destructor then only joins. A finish that was already writing when the session was given up
    // removes what it wrote when discard_written (the caller's rule for files it found written: Server::yield).
    void abandon(bool discard_written = true);
    // Who owns it (the summary and the data dir record it) and where its replicas go.
    void setOwnership(const std::string& owner_id, uint32_t epoch);
    void setStandby(const std::string& standby_id);
    // The state between two frames, taken by the worker: the blocks changed since the last capture (all of them
    // when `full`). Unavailable when the session has no model or finished meanwhile.
    Status captureReplica(bool full, ReplicaCapture& out, std::chrono::milliseconds timeout);
    uint32_t nextSeq() const;
    // Finish now: queued frames are skipped, then the final mesh is extracted and written to dir.
    void requestFinish(const std::string& why, FinishCallback done);
    bool finished() const;
    // Its finish is under way (meshing, texturing or writing): not finished yet.
    bool finishing() const;
    bool open() const { return !finished(); }
    SessionStats stats() const;
    // Full-resolution mesh: the final one once finished, else extracted from the current model now.
    StatusOr<MeshResult> mesh();
    std::string trajectoryTum() const;
    StatusOr<std::vector<uint8_t>> previewPng();
    // Snapshot thread: a coarse mesh of the current model when something was integrated since the last one.
    std::optional<SnapshotResult> makeSnapshot();
    // Once, after finishing: the final full-resolution mesh as the last snapshot (late subscribers get it).
    std::optional<SnapshotResult> takeFinalSnapshot();
    // Once finished: the folder its files went to (empty when they could not be written).
    std::filesystem::path filesDir() const;
    // Sessions alive in this process: a finished one must not stay (the server's memory would grow with its scans).
    static int liveCount() { return LiveCount<Session>::alive(); }

 private:
    struct Control {
        enum Kind { kReset, kFinish, kRun } kind;
        std::string why;
        std::function<void(const Status&)> reset_done;  // kReset; kRun: called with the outcome
        FinishCallback finish_done;
        std::function<void()> run;  // kRun: executed by the worker between frames
    };
    // setCamera and restore: builds the engine unless given one (from the replica's state when there is one),
    // starts the worker.
    Status start(const wire::CameraInfoData& camera, const wire::ReplicaData* replica, int64_t takeover_from_ns,
                 SessionEngine engine);
    void applyReplicaLocked(const wire::ReplicaData& replica, int64_t takeover_from_ns);
    void captureOnWorker(bool full, ReplicaCapture& out);
    void noteFirstFrameAfterTakeover(uint32_t seq, int64_t now_ns);  // mutex_ held
    void workerLoop();
    char processFrame(PendingFrame& pending);  // the frame's FrameTiming::outcome
    void copySnapshotIfAsked();
    void finalize(const std::string& why, const FinishCallback& done);
    // Meshing, finishing the model and encoding it are one watchdog step each (a triangle budget on a loaded host
    // takes seconds of its own): starts the next step of the worker's finish, within the watchdog's stall limit or
    // `limit_s` seconds when given.
    void nextWatchedStep(double limit_s = 0);
    // finalize, before it writes: waits while the server's view is stale (hold_); false once the session was given up
    // (abandon) or is closing.
    bool mayWrite();
    void noteLoad();  // after a frame: the worker's load and recent skips into stats_
    void recordLatency(float ms);
    // finish_json: the finishing stage's report (recon::FinishReport::json()), or null.
    std::string summaryJson(const SessionStats& s, const MeshResult& m, const std::string& finish_json,
                            const std::string& texture_json = "null") const;
    // Bakes the texture atlas of the finished mesh from the colour keyframes (on the worker, in finalize); `out`
    // stays empty when there is none (no colour, dark colour, too large: logged, and the report says why). The
    // texture's report as JSON for summary.json.
    std::string bakeFinishedTexture(const recon::IndexedMesh& mesh, recon::TexturedMesh& out);
    std::string frameTimingsTsv() const;

    // First member, so last destroyed: a session counts as live until all of its memory is freed.
    LiveCount<Session> live_;
    const std::string id_;
    const ServerParams params_;
    std::function<void()> space_freed_;

    mutable std::mutex mutex_;  // guards everything below unless noted
    std::condition_variable cv_;
    std::optional<wire::CameraInfoData> camera_;
    std::deque<PendingFrame> queue_;
    std::vector<PendingFrame> spare_;  // recycled buffers
    std::deque<Control> control_;
    bool stop_ = false;
    bool finishing_ = false;
    std::shared_ptr<Watchdog::Beat> beat_;  // set before the worker starts
    std::function<bool()> hold_;
    SessionStats stats_;
    uint32_t next_seq_ = 0;  // the next frame to take (intake side)
    // Frames no copy of which survived a takeover: kept apart from the detail, which each frame rewrites, so the
    // status and the summary say it for the rest of the scan.
    std::string frames_lost_note_;
    // Worker side of replication: where the last capture ended, and the frames processed.
    uint32_t processed_next_seq_ = 0;
    uint64_t replica_generation_ = 0;
    size_t replica_trajectory_ = 0;
    uint64_t replica_keyframes_version_ = ~uint64_t{0};  // of the keyframes the last capture carried
    int64_t takeover_from_ns_ = 0;                       // steady clock; 0 = no takeover pending
    int64_t takeover_started_ns_ = 0;   // steady clock: when this server started the taken-over session
    int64_t takeover_received_ns_ = 0;  // steady clock: its first frame here (0: none yet)
    std::vector<std::pair<int64_t, recon::Pose>> trajectory_;  // copy of the recon core's, for other threads
    recon::Pose last_pose_ = recon::Pose::Identity();
    std::vector<float> latency_ms_;  // ring of the last kLatencyWindow
    // Worker only (finalize runs on the worker when there is one): the frames processed.
    std::vector<FrameTiming> frame_timings_;
    TextureKeyframes keyframes_;  // the texture's colour frames, as received
    size_t latency_next_ = 0;
    std::deque<int64_t> processed_ns_;  // steady times of recently processed frames (fps)
    int64_t first_processed_ns_ = 0, last_processed_ns_ = 0;
    uint64_t processed_count_ = 0;
    double duration_before_s_ = 0;   // processing time before a restore (the replica's)
    uint64_t processed_before_ = 0;  // frames processed before a restore
    recon::StageTimesMs ms_sum_;
    uint64_t ms_count_ = 0;
    std::shared_ptr<recon::Reconstructor> recon_;  // null before the camera and after finishing
    MeshResult final_mesh_;
    std::filesystem::path files_dir_;
    bool discard_written_ = true;  // abandon(): what a finish that was writing does with its files
    std::vector<uint8_t> final_preview_png_;
    bool final_snapshot_sent_ = false;
    std::atomic<int64_t> last_activity_ns_{0};

    uint32_t skipped_at_last_frame_ = 0;

    // Worker-only state (no lock).
    std::unique_ptr<FrameLoad> load_;  // made with the worker (it needs the source's rate)
    std::unique_ptr<recon::FacePipeline> pipeline_;
    recon::AdviceParams advice_;       // set with the engine, read by the worker only
    recon::ReconParams recon_params_;  // the session's, adapted to its camera (under mutex_, set with camera_)
    wire::FrameDecoder decoder_;
    recon::RgbdFrame frame_;
    recon::ScanStep step_;  // the frame worker's last frame (head, result, advice); reused
    PendingFrame working_;
    // The snapshot's volume copy is made by the WORKER between two frames when the snapshot thread asks for it
    // (guarded by mutex_): the snapshot thread runs at nice 10, and a copy made there while holding the volume
    // lock was preempted under load (82 ms lock hold measured) and stalled the frame path behind it (priority
    // inversion). On the worker the copy runs at frame priority, takes a few ms, and never waits on a lock.
    enum class SnapshotCopy { kIdle, kAsked, kCopying, kDone };
    SnapshotCopy snapshot_copy_ = SnapshotCopy::kIdle;
    std::condition_variable snapshot_copy_cv_;
    // Written by whoever holds the copy (snapshot_copy_ protocol), read by the snapshot thread after kDone.
    recon::TsdfSnapshot snapshot_grid_;
    float snapshot_copy_ms_ = 0;
    // Snapshot-thread-only state (no lock).
    int snapshot_frames_ = -1;
    recon::IncrementalMesher snapshot_mesher_;  // keeps unchanged blocks' triangles from snapshot to snapshot

    std::thread worker_;
};

int64_t steadyNowNs();
int64_t realtimeNowNs();

}  // namespace facescan::service
