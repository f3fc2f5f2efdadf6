// Snapshots while scanning: the worker copies the volume between two frames when the snapshot thread asks (so the
// frame path never waits on a lock held by the lower-priority snapshot thread), and the snapshot thread meshes only
// the blocks that changed since the last snapshot, then encodes the mesh for the wire.
#include <chrono>

#include "service/session.hpp"

namespace facescan::service {
namespace {

float msSince(int64_t t0_ns) { return static_cast<float>(steadyNowNs() - t0_ns) * 1e-6f; }

}  // namespace

void Session::copySnapshotIfAsked() {
    {
        std::lock_guard lk(mutex_);
        if (snapshot_copy_ != SnapshotCopy::kAsked || !recon_) return;
        snapshot_copy_ = SnapshotCopy::kCopying;
    }
    const int64_t t0 = steadyNowNs();
    recon_->copyVolume(snapshot_grid_);
    const float copy_ms = msSince(t0);
    {
        std::lock_guard lk(mutex_);
        snapshot_copy_ms_ = copy_ms;
        snapshot_copy_ = SnapshotCopy::kDone;
    }
    snapshot_copy_cv_.notify_all();
}

std::optional<SnapshotResult> Session::makeSnapshot() {
    std::shared_ptr<recon::Reconstructor> rec;
    int integrated = 0;
    float copy_ms = 0;
    {
        std::unique_lock lk(mutex_);
        if (stats_.state == SessionState::kFinished || !recon_) return std::nullopt;
        integrated = static_cast<int>(stats_.frames_integrated);
        if (integrated == 0 || integrated == snapshot_frames_) return std::nullopt;
        rec = recon_;
        // Ask the worker to copy after its current frame; if no frame comes within a few frame periods (paused
        // agent, end of a recording), copy here: the frame path is idle then, so nothing waits on the lock.
        snapshot_copy_ = SnapshotCopy::kAsked;
        const bool copied = snapshot_copy_cv_.wait_for(lk, std::chrono::milliseconds(150),
                                                       [&] { return snapshot_copy_ == SnapshotCopy::kDone; });
        if (!copied && snapshot_copy_ == SnapshotCopy::kCopying) {  // the worker took it just now: let it finish
            snapshot_copy_cv_.wait(lk, [&] { return snapshot_copy_ == SnapshotCopy::kDone; });
        } else if (!copied) {
            snapshot_copy_ = SnapshotCopy::kIdle;  // withdrawn under the lock: the worker will not start it now
            lk.unlock();
            const int64_t t0 = steadyNowNs();
            rec->copyVolume(snapshot_grid_);
            snapshot_copy_ms_ = msSince(t0);
            lk.lock();
        }
        snapshot_copy_ = SnapshotCopy::kIdle;
        copy_ms = snapshot_copy_ms_;
    }
    // Only the blocks whose voxels changed since the last snapshot are meshed again.
    const int64_t t1 = steadyNowNs();
    const wire::MeshCodecParams cp = meshCodecParams(snapshot_grid_, params_.snapshot_max_error_m);
    const recon::IndexedMesh m = snapshot_mesher_.update(snapshot_grid_);  // swaps the grid away
    const float mesh_ms = msSince(t1);
    if (m.triangles.empty()) return std::nullopt;
    const int64_t t2 = steadyNowNs();
    auto encoded = encodeMesh(m, cp);
    if (!encoded.isOk()) return std::nullopt;
    const float encode_ms = msSince(t2);
    std::lock_guard lk(mutex_);
    snapshot_frames_ = integrated;
    stats_.snapshot_copy_ms = copy_ms;
    stats_.snapshot_mesh_ms = mesh_ms;
    stats_.snapshot_encode_ms = encode_ms;
    stats_.ms.mesh = mesh_ms + encode_ms;
    SnapshotResult out;
    out.seq = ++stats_.snapshot_seq;
    out.frames_integrated = static_cast<uint32_t>(integrated);
    out.mesh = std::move(*encoded);
    return out;
}

}  // namespace facescan::service
