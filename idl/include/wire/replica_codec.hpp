// A session's replica as bytes: what the owner sends its standby every round and appends to its data
// dir, so that the standby (or the same server after a restart) continues the scan. One versioned format:
//
//   header (24 bytes, little-endian): magic "FSRP", u16 format version, u16 flags (bit 0: full),
//                                     u32 body bytes, u32 compressed bytes, u64 reserved (0)
//   body (one zstd frame with its content checksum): ids and counters, the CameraInfo, the recon core's state
//        (recon::ReconState), its voxels stored byte-plane by byte-plane (similar bytes together compress best).
//
// The decoder checks every size and value before anything is allocated or used: network and disk bytes are not
// trusted (tests/fuzz/fuzz_replica.cpp).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "recon/recon_state.hpp"
#include "recon/status.hpp"
#include "wire/messages.hpp"

namespace facescan::wire {

// 2: SessionCounters::frames_tracked_only; 3: the camera (CameraInfoData::sensor, its colour camera and extrinsics);
// 4: the texture's colour keyframes (ReplicaData::keyframes).
// A server reads its own version and the one before, so a rolling upgrade keeps the older servers' replicas.
inline constexpr uint16_t kReplicaFormatVersion = 4;
inline constexpr uint16_t kOldestReplicaFormatVersion = 3;
inline constexpr uint32_t kMaxReplicaKeyframes = 256;
inline constexpr size_t kMaxReplicaKeyframeBytes = size_t{16} << 20;  // one JPEG: far above a 4K frame
inline constexpr size_t kReplicaHeaderBytes = 24;
inline constexpr size_t kMaxReplicaBodyBytes = size_t{512} << 20;  // 512 MiB: far above a face volume

// The service's counters a takeover continues from (the recon core's own are in ReconState).
struct SessionCounters {
    uint32_t frames_received = 0;
    uint32_t frames_integrated = 0;
    uint32_t frames_rejected = 0;
    uint32_t frames_skipped = 0;
    uint32_t frames_dropped = 0;
    uint32_t snapshot_seq = 0;
    uint32_t failovers = 0;
    uint32_t frames_tracked_only = 0;  // tracked but not fused (recon::ReconParams::fuse_every)
    float last_takeover_ms = 0;
    uint64_t frames_processed = 0;
    double duration_s = 0;       // seconds of processing so far
    uint64_t frames_digest = 0;  // FNV-1a over the payloads of every frame accepted, in order (frameDigest)
};

// A colour keyframe the texture is baked from (the session's TextureKeyframes): its bytes as received (JPEG) and
// the depth camera's pose in the model's frame when it was tracked.
struct ReplicaKeyframe {
    uint32_t seq = 0;
    std::vector<uint8_t> jpeg;
    recon::Pose T_world_depth = recon::Pose::Identity();
};

struct ReplicaData {
    std::string session_id;
    std::string owner_id;
    uint32_t epoch = 1;
    uint32_t round = 1;       // 1, 2, ... per owner and epoch
    uint32_t base_round = 0;  // 0: a full state; else the round this delta applies to
    uint32_t next_seq = 0;    // frames with seq < next_seq are in this state
    CameraInfoData camera;
    SessionCounters counters;
    recon::ReconState state;  // full iff base_round == 0
    // The texture's keyframes, in a full replica and in a delta whose keyframes changed since the round before
    // (has_keyframes); a delta without them keeps its base's (mergeReplica). They are small beside the volume
    // (a few hundred KB) and change seldom once the head has been seen from all sides.
    bool has_keyframes = false;
    std::vector<ReplicaKeyframe> keyframes;

    bool full() const { return base_round == 0; }
};

// Encodes `r` into `out` (cleared first). zstd_level trades CPU for bytes (1 = fastest).
Status encodeReplica(const ReplicaData& r, std::vector<uint8_t>& out, int zstd_level = 1);

// encodeReplica round after round: one zstd context, and a body and compressed buffer that keep their capacity.
// A server encodes every live session's replica once a second, megabytes each; with fresh buffers every round,
// the kernel's zeroing of their new pages cost about as much CPU as the compression (perf at four sessions on 2
// cores: 3.7 % of the server's CPU, against 2.3 % in zstd). The bytes are those of encodeReplica. Not
// thread-safe: one per thread.
class ReplicaEncoder {
 public:
    explicit ReplicaEncoder(int zstd_level = 1);
    ~ReplicaEncoder();
    ReplicaEncoder(const ReplicaEncoder&) = delete;
    ReplicaEncoder& operator=(const ReplicaEncoder&) = delete;

    // As encodeReplica: `out` is resized to the replica (its capacity is kept when it suffices).
    Status encode(const ReplicaData& r, std::vector<uint8_t>& out);
    Status frameBody(const uint8_t* body, size_t size, bool full, std::vector<uint8_t>& out);

 private:
    struct Context;
    int zstd_level_;
    std::unique_ptr<Context> ctx_;  // the zstd context, made on first use
    std::vector<uint8_t> body_;     // the serialised body
    std::vector<uint8_t> packed_;   // the compressed frame (kept at its largest size: no zeroing on reuse)
};
// The header and the compressed frame around an already serialised body (what encodeReplica does after
// serialising): for the fuzzer, which feeds bodies straight to the parser behind a valid frame.
Status frameReplicaBody(const uint8_t* body, size_t size, bool full, std::vector<uint8_t>& out, int zstd_level = 1);
// Decodes and validates. kUnimplemented for another format version (the message says which), kDataLoss for
// corrupt or truncated bytes, kInvalidArgument/kOutOfRange for values that make no sense.
Status decodeReplica(const uint8_t* data, size_t size, ReplicaData& out);

// Applies a delta replica onto a full one (the standby's copy, or the rounds of a replica log): the delta must
// belong to the same session and owner epoch and continue base.round. Leaves base unchanged on error.
Status mergeReplica(ReplicaData& base, const ReplicaData& delta);

// Running digest of accepted frames: FNV-1a 64 over depth then colour, eight bytes (little-endian) a step, then
// the tail byte by byte, then the size (a recording that arrived bit-exact has the digest the agent computed while
// sending it). A step per word, not per byte: the byte-wise hash was 0.8 % of the server's CPU.
uint64_t frameDigest(uint64_t digest, const uint8_t* depth, size_t depth_size, const uint8_t* colour,
                     size_t colour_size);
inline constexpr uint64_t kFrameDigestSeed = 1469598103934665603ull;

}  // namespace facescan::wire
