// What facescan-server runs with: the recon core's Params structs (from a preset, a config file and flags) and
// the service's own settings (sessions, snapshots, data dir, DDS domain). Validated once at start.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "recon/face_pipeline.hpp"
#include "recon/finishing.hpp"
#include "recon/reconstructor.hpp"
#include "recon/status.hpp"
#include "recon/texture_atlas.hpp"
#include "service/texture_keyframes.hpp"
#include "wire/dds.hpp"

namespace facescan::service {

struct ServerParams {
    std::string preset = "face";  // face | fast: ReconParams::faceDefaults() or ReconParams::fast()
    recon::ReconParams recon = recon::ReconParams::faceDefaults();
    recon::FacePipelineParams face;  // detection and segmentation in front of the recon core
    recon::FinishParams finish;      // the final model: the head alone, holes, a triangle budget (on finish)
    // The texture atlas baked on finish from colour keyframes kept during the scan (texture.max_keyframes 0: none).
    KeyframeParams texture_keyframes;
    recon::TextureParams texture;
    // Snapshots are meshed with cubes of this many voxels while scanning (2 = an eighth of the cubes); the final
    // mesh (GET_MESH, disk) is always full resolution (recon.mesh).
    int snapshot_stride_vox = 2;           // voxels
    float snapshot_hz = 1.0f;              // Hz; MeshSnapshot rate per session (0 = no snapshots while scanning)
    float snapshot_max_error_m = 0.2e-3f;  // metres; Draco position quantisation of snapshots (final: 0.05 mm)
    float status_hz = 2.0f;                // Hz; ScanStatus rate per session
    int max_sessions = 4;                  // count; open (not finished) sessions at once; more are refused
    float idle_timeout_s = 60.0f;          // seconds; a session without frames for this long is finished
    // A finished session leaves memory once its files are written and its final status and mesh are out; it stays
    // listed (its status, `facescan sessions`) while it is among the newest keep_finished and younger than
    // keep_finished_s, and its files in the data dir answer its commands after that too.
    int keep_finished = 16;          // count; finished sessions listed at most
    float keep_finished_s = 600.0f;  // seconds; a finished session is listed at most this long
    // Retention: a session in the data dir whose newest file is older than this is erased (service/erasure.hpp),
    // checked at start and every hour. 0: scans are kept until deleted.
    int retain_days = 0;   // days
    int queue_frames = 8;  // frames; bounded per-session queue of a recording (every_frame) session
    std::filesystem::path data_dir = "facescan-data";  // finished sessions go to data_dir/SESSION/
    wire::DomainConfig domain{0, "lan"};
    std::string server_id;  // in every reply, status and announcement; default "<hostname>-<pid>"; [A-Za-z0-9._-]
    // The cluster.
    float replica_interval_s = 1.0f;      // seconds between replicas of a session (to the standby and the data dir)
    int replica_full_every = 30;          // rounds; every this many, a full replica (the data dir's log starts over)
    int replica_zstd_level = 1;           // 1 (fastest) .. 19
    float join_settle_s = 2.0f;           // seconds of discovery after start before taking sessions
    float claim_settle_s = 0.25f;         // seconds a claim must stand before the owner reads frames
    float first_frame_timeout_s = 10.0f;  // seconds a claimed session may wait for its first frame (then released)
    // seconds one step of the intake, a session's worker or the retiring thread may take before this server counts
    // as stuck: it then exits non-zero (the service manager restarts it) and the cluster takes its sessions over.
    // Short, because a stuck server's frame reader still matches the agent's writer while the process lives, and a
    // recording's reliable writer waits for every reader it matches. A finish (the whole mesh) takes about a second.
    float stall_limit_s = 10.0f;

    Status validate() const;
};

// `key = value` as in a config file: recon core fields under their struct's name (tsdf.voxel_size_m,
// tsdf.resolution_vox, icp.iterations0, filter.sigma_depth_m, ...) and the service's own keys (snapshot_hz,
// max_sessions, ...). Unknown keys and unparsable values are errors that name the key.
Status applySetting(ServerParams& params, const std::string& key, const std::string& value);
// A file of `key = value` lines; '#' starts a comment. Errors name the file and line.
Status loadConfigFile(const std::filesystem::path& path, ServerParams& params);
// Every key applySetting understands (for --help and tests).
std::vector<std::string> settingKeys();

// Parses the command line: `--preset` first (it resets the recon params), then `--config FILE`, then the other
// flags (they override the file). `help` is set for --help/-h (params are then left at defaults); `check` for
// --check (validate the configuration, DDS profile included, and exit).
struct ParsedArgs {
    ServerParams params;
    bool help = false;
    bool check = false;
};
StatusOr<ParsedArgs> parseServerArgs(const std::vector<std::string>& args);
std::string serverUsage();

}  // namespace facescan::service
