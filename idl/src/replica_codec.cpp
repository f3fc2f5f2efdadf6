// The replica format (wire/replica_codec.hpp). Little-endian fixed-width fields; every read is bounds-checked.
#include "wire/replica_codec.hpp"

#include <zstd.h>

#include <cmath>
#include <cstring>

#include "wire/cluster_codec.hpp"

namespace facescan::wire {
namespace {

constexpr uint32_t kMagic = 0x50525346;  // "FSRP"
constexpr uint16_t kFlagFull = 1;
constexpr size_t kVoxelBytes = sizeof(recon::Voxel);
constexpr uint32_t kMaxBlocks = 1u << 21;      // 128^3: every block of the largest cube
constexpr uint32_t kMaxTrajectory = 1u << 22;  // entries (38 hours at 30 Hz)
constexpr size_t kMaxStringBytes = 4096;

class ByteWriter {
 public:
    explicit ByteWriter(std::vector<uint8_t>& out) : out_(out) {}
    template <typename T>
    void put(T v) {
        const size_t at = out_.size();
        out_.resize(at + sizeof(T));
        std::memcpy(out_.data() + at, &v, sizeof(T));
    }
    void str(const std::string& s) {
        put<uint16_t>(static_cast<uint16_t>(std::min(s.size(), kMaxStringBytes)));
        out_.insert(out_.end(), s.begin(), s.begin() + static_cast<ptrdiff_t>(std::min(s.size(), kMaxStringBytes)));
    }
    void pose(const recon::Pose& T) {
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 4; ++c) put<float>(T.matrix()(r, c));
        }
    }
    void bytes(const uint8_t* p, size_t n) { out_.insert(out_.end(), p, p + n); }

 private:
    std::vector<uint8_t>& out_;
};

class ByteReader {
 public:
    ByteReader(const uint8_t* p, size_t n) : p_(p), end_(p + n) {}
    size_t left() const { return static_cast<size_t>(end_ - p_); }
    template <typename T>
    bool get(T& v) {
        if (left() < sizeof(T)) return false;
        std::memcpy(&v, p_, sizeof(T));
        p_ += sizeof(T);
        return true;
    }
    bool str(std::string& s) {
        uint16_t n = 0;
        if (!get(n) || n > kMaxStringBytes || left() < n) return false;
        s.assign(reinterpret_cast<const char*>(p_), n);
        p_ += n;
        return true;
    }
    bool pose(recon::Pose& T) {
        T = recon::Pose::Identity();
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 4; ++c) {
                if (!get(T.matrix()(r, c))) return false;
            }
        }
        return true;
    }
    const uint8_t* take(size_t n) {
        if (left() < n) return nullptr;
        const uint8_t* at = p_;
        p_ += n;
        return at;
    }

 private:
    const uint8_t* p_;
    const uint8_t* end_;
};

void putCamera(ByteWriter& w, const CameraInfoData& c) {
    w.put<uint32_t>(static_cast<uint32_t>(c.intrinsics.width_px));
    w.put<uint32_t>(static_cast<uint32_t>(c.intrinsics.height_px));
    for (const float f :
         {c.intrinsics.fx_px, c.intrinsics.fy_px, c.intrinsics.cx_px, c.intrinsics.cy_px, c.depth_units_m, c.rate_hz}) {
        w.put<float>(f);
    }
    w.put<uint8_t>(c.colour_registered);
    w.put<uint8_t>(c.every_frame);
    w.put<uint32_t>(c.expected_frames);
    w.str(c.source);
    w.str(c.agent_host);
    // Version 3: the camera.
    w.str(c.sensor.name);
    w.put<uint8_t>(static_cast<uint8_t>(c.sensor.family));
    for (const float f : {c.sensor.min_depth_m, c.sensor.max_depth_m, c.sensor.noise.c0_m, c.sensor.noise.c1,
                          c.sensor.noise.c2_per_m}) {
        w.put<float>(f);
    }
    const recon::Intrinsics& k = c.colour_intrinsics;
    w.put<uint32_t>(static_cast<uint32_t>(k.width_px));
    w.put<uint32_t>(static_cast<uint32_t>(k.height_px));
    for (const float f : {k.fx_px, k.fy_px, k.cx_px, k.cy_px}) w.put<float>(f);
    w.pose(c.T_colour_depth);
}

bool getCamera(ByteReader& r, CameraInfoData& c) {
    uint32_t w = 0, h = 0;
    uint8_t reg = 0, every = 0;
    if (!r.get(w) || !r.get(h) || w > 4096 || h > 4096) return false;
    c.intrinsics.width_px = static_cast<int>(w);
    c.intrinsics.height_px = static_cast<int>(h);
    for (float* f : {&c.intrinsics.fx_px, &c.intrinsics.fy_px, &c.intrinsics.cx_px, &c.intrinsics.cy_px,
                     &c.depth_units_m, &c.rate_hz}) {
        if (!r.get(*f)) return false;
    }
    if (!r.get(reg) || !r.get(every) || !r.get(c.expected_frames)) return false;
    c.colour_registered = reg != 0;
    c.every_frame = every != 0;
    if (!r.str(c.source) || !r.str(c.agent_host)) return false;
    uint8_t family = 0;
    uint32_t cw = 0, ch = 0;
    if (!r.str(c.sensor.name) || !r.get(family) || family > static_cast<uint8_t>(recon::SensorFamily::kTimeOfFlight))
        return false;
    c.sensor.family = static_cast<recon::SensorFamily>(family);
    for (float* f : {&c.sensor.min_depth_m, &c.sensor.max_depth_m, &c.sensor.noise.c0_m, &c.sensor.noise.c1,
                     &c.sensor.noise.c2_per_m}) {
        if (!r.get(*f)) return false;
    }
    if (!r.get(cw) || !r.get(ch) || cw > 4096 || ch > 4096) return false;
    recon::Intrinsics& k = c.colour_intrinsics;
    k.width_px = static_cast<int>(cw);
    k.height_px = static_cast<int>(ch);
    for (float* f : {&k.fx_px, &k.fy_px, &k.cx_px, &k.cy_px}) {
        if (!r.get(*f)) return false;
    }
    return r.pose(c.T_colour_depth);
}

void putCounters(ByteWriter& w, const SessionCounters& c) {
    for (const uint32_t v : {c.frames_received, c.frames_integrated, c.frames_rejected, c.frames_skipped,
                             c.frames_dropped, c.snapshot_seq, c.failovers, c.frames_tracked_only}) {
        w.put<uint32_t>(v);
    }
    w.put<float>(c.last_takeover_ms);
    w.put<uint64_t>(c.frames_processed);
    w.put<double>(c.duration_s);
    w.put<uint64_t>(c.frames_digest);
}

bool getCounters(ByteReader& r, SessionCounters& c) {
    for (uint32_t* v : {&c.frames_received, &c.frames_integrated, &c.frames_rejected, &c.frames_skipped,
                        &c.frames_dropped, &c.snapshot_seq, &c.failovers, &c.frames_tracked_only}) {
        if (!r.get(*v)) return false;
    }
    return r.get(c.last_takeover_ms) && r.get(c.frames_processed) && r.get(c.duration_s) && r.get(c.frames_digest) &&
           std::isfinite(c.last_takeover_ms) && std::isfinite(c.duration_s) && c.duration_s >= 0;
}

void putState(ByteWriter& w, const recon::ReconState& s, std::vector<uint8_t>& body) {
    w.put<int32_t>(s.resolution_vox);
    w.put<float>(s.volume_size_m);
    w.put<float>(s.trunc_dist_m);
    w.put<uint8_t>(s.placed);
    for (int a = 0; a < 3; ++a) w.put<float>(s.origin_world[a]);
    w.put<uint64_t>(s.generation);
    w.put<uint64_t>(s.since_generation);
    w.put<int32_t>(s.total_blocks);
    w.put<uint8_t>(s.have_model);
    w.put<int32_t>(s.frames_integrated);
    w.put<int32_t>(s.consecutive_failures);
    w.pose(s.T_world_camera);
    w.pose(s.T_world_model);
    for (const int v : {s.model_roi.x, s.model_roi.y, s.model_roi.width, s.model_roi.height}) w.put<int32_t>(v);
    w.put<uint8_t>(s.region.valid);
    for (int a = 0; a < 3; ++a) w.put<float>(s.region.centre_world[a]);
    for (int a = 0; a < 3; ++a) w.put<float>(s.region.down_world[a]);
    for (const float f : {s.region.below_centre_m, s.region.radius_m, s.region.centre_behind_m, s.visible_ref_px}) {
        w.put<float>(f);
    }
    w.put<uint8_t>(s.verify_next);
    w.put<uint64_t>(s.trajectory_begin);
    w.put<uint32_t>(static_cast<uint32_t>(s.trajectory.size()));
    for (const auto& [t_ns, T] : s.trajectory) {
        w.put<int64_t>(t_ns);
        w.pose(T);
    }
    w.put<uint32_t>(static_cast<uint32_t>(s.blocks.count()));
    for (const Eigen::Vector3i& c : s.blocks.coords) {
        for (int a = 0; a < 3; ++a) w.put<uint16_t>(static_cast<uint16_t>(c[a]));
    }
    // Voxels byte-plane by byte-plane: all first bytes of every voxel, then all second bytes, ... (zstd finds the
    // runs of equal exponents and empty voxels that an interleaved layout hides).
    const size_t n = s.blocks.voxels.size();
    const size_t at = body.size();
    body.resize(at + n * kVoxelBytes);
    const auto* src = reinterpret_cast<const uint8_t*>(s.blocks.voxels.data());
    uint8_t* dst = body.data() + at;
    for (size_t b = 0; b < kVoxelBytes; ++b) {
        uint8_t* plane = dst + b * n;
        for (size_t i = 0; i < n; ++i) plane[i] = src[i * kVoxelBytes + b];
    }
}

Status getState(ByteReader& r, recon::ReconState& s) {
    const Status truncated = dataLoss("replica body truncated in the model state");
    uint8_t placed = 0, have_model = 0;
    if (!r.get(s.resolution_vox) || !r.get(s.volume_size_m) || !r.get(s.trunc_dist_m) || !r.get(placed)) {
        return truncated;
    }
    for (int a = 0; a < 3; ++a) {
        if (!r.get(s.origin_world[a])) return truncated;
    }
    if (!r.get(s.generation) || !r.get(s.since_generation) || !r.get(s.total_blocks) || !r.get(have_model) ||
        !r.get(s.frames_integrated) || !r.get(s.consecutive_failures) || !r.pose(s.T_world_camera) ||
        !r.pose(s.T_world_model)) {
        return truncated;
    }
    s.placed = placed != 0;
    s.have_model = have_model != 0;
    int32_t roi[4];
    for (int32_t& v : roi) {
        if (!r.get(v)) return truncated;
    }
    s.model_roi = cv::Rect(roi[0], roi[1], roi[2], roi[3]);
    uint8_t region_valid = 0, verify_next = 0;
    if (!r.get(region_valid)) return truncated;
    for (int a = 0; a < 3; ++a) {
        if (!r.get(s.region.centre_world[a])) return truncated;
    }
    for (int a = 0; a < 3; ++a) {
        if (!r.get(s.region.down_world[a])) return truncated;
    }
    for (float* f : {&s.region.below_centre_m, &s.region.radius_m, &s.region.centre_behind_m, &s.visible_ref_px}) {
        if (!r.get(*f)) return truncated;
    }
    if (!r.get(verify_next)) return truncated;
    s.region.valid = region_valid != 0;
    s.verify_next = verify_next != 0;
    uint64_t begin = 0;
    uint32_t n_traj = 0;
    if (!r.get(begin) || !r.get(n_traj)) return truncated;
    if (n_traj > kMaxTrajectory || begin > kMaxTrajectory) return outOfRange("replica trajectory too long");
    if (r.left() / (sizeof(int64_t) + 12 * sizeof(float)) < n_traj) return truncated;
    s.trajectory_begin = begin;
    s.trajectory.resize(n_traj);
    for (auto& [t_ns, T] : s.trajectory) {
        if (!r.get(t_ns) || !r.pose(T)) return truncated;
    }
    uint32_t n_blocks = 0;
    if (!r.get(n_blocks)) return truncated;
    if (n_blocks > kMaxBlocks) return outOfRange("replica holds " + std::to_string(n_blocks) + " blocks");
    // The coordinates and the voxels must both be there before anything is allocated for them.
    const size_t voxel_count = size_t{n_blocks} * recon::kBlockVoxels;
    if (r.left() < size_t{n_blocks} * 6 + voxel_count * kVoxelBytes) return truncated;
    s.blocks.coords.resize(n_blocks);
    for (Eigen::Vector3i& c : s.blocks.coords) {
        uint16_t v[3];
        for (uint16_t& x : v) (void)r.get(x);
        c = Eigen::Vector3i(v[0], v[1], v[2]);
    }
    const uint8_t* planes = r.take(voxel_count * kVoxelBytes);
    s.blocks.voxels.resize(voxel_count);
    auto* dst = reinterpret_cast<uint8_t*>(s.blocks.voxels.data());
    for (size_t b = 0; b < kVoxelBytes; ++b) {
        const uint8_t* plane = planes + b * voxel_count;
        for (size_t i = 0; i < voxel_count; ++i) dst[i * kVoxelBytes + b] = plane[i];
    }
    return Status::ok();
}

// Version 4, at the end of the body: a flag, then the keyframes.
void putKeyframes(ByteWriter& w, const ReplicaData& d) {
    w.put<uint8_t>(d.has_keyframes ? 1 : 0);
    if (!d.has_keyframes) return;
    w.put<uint32_t>(static_cast<uint32_t>(d.keyframes.size()));
    for (const ReplicaKeyframe& k : d.keyframes) {
        w.put<uint32_t>(k.seq);
        w.pose(k.T_world_depth);
        w.put<uint32_t>(static_cast<uint32_t>(k.jpeg.size()));
        w.bytes(k.jpeg.data(), k.jpeg.size());
    }
}

Status getKeyframes(ByteReader& r, ReplicaData& d) {
    const Status truncated = dataLoss("replica body truncated in its keyframes");
    uint8_t has = 0;
    if (!r.get(has) || has > 1) return truncated;
    d.has_keyframes = has != 0;
    if (!d.has_keyframes) return Status::ok();
    uint32_t n = 0;
    if (!r.get(n)) return truncated;
    if (n > kMaxReplicaKeyframes) return outOfRange("replica holds " + std::to_string(n) + " keyframes");
    d.keyframes.reserve(std::min<size_t>(n, r.left() / 56));  // what the bytes can hold, whatever n says
    for (uint32_t i = 0; i < n; ++i) {
        ReplicaKeyframe k;
        uint32_t size = 0;
        if (!r.get(k.seq) || !r.pose(k.T_world_depth) || !r.get(size)) return truncated;
        if (size > kMaxReplicaKeyframeBytes)
            return outOfRange("replica keyframe of " + std::to_string(size) + " bytes");
        const uint8_t* bytes = r.take(size);
        if (!bytes) return truncated;
        k.jpeg.assign(bytes, bytes + size);
        if (!k.T_world_depth.matrix().allFinite())
            return invalidArgument("replica keyframe with a pose that is not finite");
        d.keyframes.push_back(std::move(k));
    }
    return Status::ok();
}

}  // namespace

uint64_t frameDigest(uint64_t digest, const uint8_t* depth, size_t depth_size, const uint8_t* colour,
                     size_t colour_size) {
    constexpr uint64_t kPrime = 1099511628211ull;
    auto mix = [&](const uint8_t* p, size_t n) {
        size_t i = 0;
        for (; i + 8 <= n; i += 8) {
            uint64_t word = 0;
            for (int b = 7; b >= 0; --b) word = word << 8 | p[i + static_cast<size_t>(b)];  // one load on x86/arm
            digest = (digest ^ word) * kPrime;
        }
        for (; i < n; ++i) digest = (digest ^ p[i]) * kPrime;
        digest = (digest ^ static_cast<uint64_t>(n)) * kPrime;  // where depth ends and colour begins
    };
    mix(depth, depth_size);
    mix(colour, colour_size);
    return digest;
}

struct ReplicaEncoder::Context {
    ZSTD_CCtx* cctx = nullptr;
    ~Context() { ZSTD_freeCCtx(cctx); }
};

ReplicaEncoder::ReplicaEncoder(int zstd_level) : zstd_level_(zstd_level) {}
ReplicaEncoder::~ReplicaEncoder() = default;

Status ReplicaEncoder::encode(const ReplicaData& r, std::vector<uint8_t>& out) {
    if (r.full() != r.state.full) return invalidArgument("replica: base round and state disagree on full");
    size_t keyframe_bytes = 0;
    for (const ReplicaKeyframe& k : r.keyframes) {
        if (k.jpeg.size() > kMaxReplicaKeyframeBytes) return invalidArgument("replica: a keyframe is too large");
        keyframe_bytes += 56 + k.jpeg.size();
    }
    if (r.keyframes.size() > kMaxReplicaKeyframes) return invalidArgument("replica: too many keyframes");
    body_.clear();
    body_.reserve(1024 + r.state.blocks.voxels.size() * kVoxelBytes + r.state.trajectory.size() * 56 + keyframe_bytes);
    ByteWriter w(body_);
    w.str(r.session_id);
    w.str(r.owner_id);
    for (const uint32_t v : {r.epoch, r.round, r.base_round, r.next_seq}) w.put<uint32_t>(v);
    putCamera(w, r.camera);
    putCounters(w, r.counters);
    putState(w, r.state, body_);
    putKeyframes(w, r);
    return frameBody(body_.data(), body_.size(), r.full(), out);
}

Status ReplicaEncoder::frameBody(const uint8_t* body, size_t size, bool full, std::vector<uint8_t>& out) {
    if (size > kMaxReplicaBodyBytes) return outOfRange("replica too large");
    if (!ctx_) ctx_ = std::make_unique<Context>();
    if (!ctx_->cctx) ctx_->cctx = ZSTD_createCCtx();
    ZSTD_CCtx* cctx = ctx_->cctx;
    if (!cctx) return internalError("zstd: cannot create a context");
    (void)ZSTD_CCtx_reset(cctx, ZSTD_reset_session_and_parameters);
    (void)ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, zstd_level_);
    (void)ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 1);
    const size_t bound = ZSTD_compressBound(size);
    if (packed_.size() < bound) packed_.resize(bound);  // never shrunk: the next round writes over it
    const size_t packed = ZSTD_compress2(cctx, packed_.data(), packed_.size(), body, size);
    if (ZSTD_isError(packed)) return internalError(std::string("zstd: ") + ZSTD_getErrorName(packed));
    out.resize(kReplicaHeaderBytes + packed);
    const uint32_t magic = kMagic, body_size = static_cast<uint32_t>(size), packed_size = static_cast<uint32_t>(packed);
    const uint16_t version = kReplicaFormatVersion, flags = full ? kFlagFull : 0;
    const uint64_t reserved = 0;
    std::memcpy(out.data(), &magic, 4);
    std::memcpy(out.data() + 4, &version, 2);
    std::memcpy(out.data() + 6, &flags, 2);
    std::memcpy(out.data() + 8, &body_size, 4);
    std::memcpy(out.data() + 12, &packed_size, 4);
    std::memcpy(out.data() + 16, &reserved, 8);
    std::memcpy(out.data() + kReplicaHeaderBytes, packed_.data(), packed);
    return Status::ok();
}

Status encodeReplica(const ReplicaData& r, std::vector<uint8_t>& out, int zstd_level) {
    return ReplicaEncoder(zstd_level).encode(r, out);
}

Status frameReplicaBody(const uint8_t* body, size_t size, bool full, std::vector<uint8_t>& out, int zstd_level) {
    return ReplicaEncoder(zstd_level).frameBody(body, size, full, out);
}

Status decodeReplica(const uint8_t* data, size_t size, ReplicaData& out) {
    if (!data || size < kReplicaHeaderBytes) {
        return dataLoss("replica truncated: " + std::to_string(size) + " bytes, the header alone is " +
                        std::to_string(kReplicaHeaderBytes));
    }
    uint32_t magic = 0, body_size = 0, packed_size = 0;
    uint16_t version = 0, flags = 0;
    std::memcpy(&magic, data, 4);
    std::memcpy(&version, data + 4, 2);
    std::memcpy(&flags, data + 6, 2);
    std::memcpy(&body_size, data + 8, 4);
    std::memcpy(&packed_size, data + 12, 4);
    if (magic != kMagic) return dataLoss("not a facescan replica (bad magic)");
    if (version != kReplicaFormatVersion && version != kOldestReplicaFormatVersion) {
        return {StatusCode::kUnimplemented, "replica format version " + std::to_string(version) +
                                                " is not compatible with this server (it reads " + "versions " +
                                                std::to_string(kOldestReplicaFormatVersion) + "-" +
                                                std::to_string(kReplicaFormatVersion) +
                                                "): run the same facescan version on every server of the domain"};
    }
    if ((flags & ~kFlagFull) != 0) return dataLoss("replica header has unknown flags");
    if (packed_size != size - kReplicaHeaderBytes) {
        return dataLoss("replica truncated: " + std::to_string(size - kReplicaHeaderBytes) + " of " +
                        std::to_string(packed_size) + " compressed bytes");
    }
    if (body_size > kMaxReplicaBodyBytes) return outOfRange("replica body of " + std::to_string(body_size) + " bytes");
    const unsigned long long content = ZSTD_getFrameContentSize(data + kReplicaHeaderBytes, packed_size);
    if (content != body_size) return dataLoss("replica body size does not match its compressed frame");
    // Decompressed in pieces into a buffer that only grows with real output: a lying header cannot make us
    // allocate what the bytes do not hold.
    std::vector<uint8_t> body;
    ZSTD_DCtx* dctx = ZSTD_createDCtx();
    if (!dctx) return internalError("zstd: cannot create a context");
    ZSTD_inBuffer in{data + kReplicaHeaderBytes, packed_size, 0};
    std::string error;
    for (;;) {
        const size_t at = body.size();
        if (at == body_size) {
            // All declared bytes are out: the frame must end here (this call also checks its checksum).
            uint8_t extra = 0;
            ZSTD_outBuffer probe{&extra, 1, 0};
            const size_t rc = ZSTD_decompressStream(dctx, &probe, &in);
            if (ZSTD_isError(rc)) {
                error = ZSTD_getErrorName(rc);
            } else if (probe.pos != 0 || rc != 0) {
                error = "the frame does not end where its header says";
            }
            break;
        }
        body.resize(std::min<size_t>(body_size, at + (size_t{1} << 20) + at / 2));
        ZSTD_outBuffer ob{body.data(), body.size(), at};
        const size_t rc = ZSTD_decompressStream(dctx, &ob, &in);
        body.resize(ob.pos);
        if (ZSTD_isError(rc)) {
            error = ZSTD_getErrorName(rc);
            break;
        }
        if (rc == 0) break;  // the frame ended (its checksum held)
        if (ob.pos == at && in.pos == in.size) {
            error = "compressed bytes end inside the frame";
            break;
        }
    }
    ZSTD_freeDCtx(dctx);
    if (!error.empty()) return dataLoss("replica corrupt: " + error);
    if (body.size() != body_size || in.pos != in.size) return dataLoss("replica corrupt: its body is incomplete");

    ByteReader r(body.data(), body.size());
    ReplicaData d;
    if (!r.str(d.session_id) || !r.str(d.owner_id) || !r.get(d.epoch) || !r.get(d.round) || !r.get(d.base_round) ||
        !r.get(d.next_seq) || !getCamera(r, d.camera) || !getCounters(r, d.counters)) {
        return dataLoss("replica body truncated in its header fields");
    }
    RETURN_IF_ERROR(getState(r, d.state));
    if (version >= 4) RETURN_IF_ERROR(getKeyframes(r, d));
    if (r.left() != 0) return dataLoss("replica body has " + std::to_string(r.left()) + " trailing bytes");
    d.state.full = (flags & kFlagFull) != 0;
    if (d.full() != d.state.full) return invalidArgument("replica: full flag and base round disagree");
    if (d.round == 0 || d.epoch == 0 || (!d.full() && d.base_round >= d.round)) {
        return invalidArgument("replica: bad round numbers");
    }
    d.camera.session_id = d.session_id;
    RETURN_IF_ERROR(d.camera.validate());
    RETURN_IF_ERROR(validateServerId(d.owner_id));
    RETURN_IF_ERROR(d.state.validate());
    out = std::move(d);
    return Status::ok();
}

Status mergeReplica(ReplicaData& base, const ReplicaData& delta) {
    if (delta.full()) {
        base = delta;
        return Status::ok();
    }
    if (!base.full() && base.round == 0) return invalidArgument("replica: no full state to apply a delta to");
    if (delta.session_id != base.session_id || delta.owner_id != base.owner_id || delta.epoch != base.epoch) {
        return invalidArgument("replica: the delta is from another session or owner");
    }
    if (delta.base_round != base.round) {
        return invalidArgument("replica: round " + std::to_string(delta.round) + " applies to round " +
                               std::to_string(delta.base_round) + ", the copy here is at round " +
                               std::to_string(base.round));
    }
    RETURN_IF_ERROR(recon::mergeState(base.state, delta.state));
    base.round = delta.round;
    base.next_seq = delta.next_seq;
    base.camera = delta.camera;
    base.counters = delta.counters;
    if (delta.has_keyframes) {
        base.has_keyframes = true;
        base.keyframes = delta.keyframes;
    }
    return Status::ok();
}

}  // namespace facescan::wire
