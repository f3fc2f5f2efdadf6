// The cluster's messages and the replica format: round trips, and every kind of bad input refused with
// a Status that says what is wrong (truncated, corrupt, another format version, values out of range).
#include <gtest/gtest.h>
#include <zstd.h>

#include <cstring>
#include <tuple>

#include "sample_replica.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/replica_codec.hpp"

namespace facescan::wire {
namespace {

using testing::sampleReplica;

TEST(ReplicaCodec, RoundTripsFullAndDeltaStatesExactly) {
    for (const bool full : {true, false}) {
        const ReplicaData r = sampleReplica(40, full);
        std::vector<uint8_t> bytes;
        ASSERT_TRUE(encodeReplica(r, bytes).isOk());
        ReplicaData back;
        const Status s = decodeReplica(bytes.data(), bytes.size(), back);
        ASSERT_TRUE(s.isOk()) << s.toString();
        EXPECT_EQ(back.session_id, r.session_id);
        EXPECT_EQ(back.owner_id, r.owner_id);
        EXPECT_EQ(back.full(), full);
        EXPECT_EQ(back.next_seq, 77u);
        EXPECT_EQ(back.counters.frames_digest, r.counters.frames_digest);
        EXPECT_EQ(back.counters.frames_tracked_only, 6u);
        EXPECT_EQ(back.camera.source, "synthetic:test");
        ASSERT_EQ(back.state.blocks.voxels.size(), r.state.blocks.voxels.size());
        EXPECT_EQ(0, std::memcmp(back.state.blocks.voxels.data(), r.state.blocks.voxels.data(),
                                 r.state.blocks.voxels.size() * sizeof(recon::Voxel)));
        EXPECT_EQ(back.state.blocks.coords, r.state.blocks.coords);
        EXPECT_TRUE(back.state.T_world_camera.isApprox(r.state.T_world_camera));
        EXPECT_EQ(back.state.trajectory.size(), r.state.trajectory.size());
        EXPECT_LT(bytes.size(), r.state.blocks.voxels.size() * sizeof(recon::Voxel)) << "not compressed";
    }
}

// One encoder, round after round (the server's replication thread): a large full state, a small delta, then a
// large one again into the same output buffer give exactly encodeReplica's bytes each time, nothing left over.
TEST(ReplicaCodec, AReusedEncoderGivesTheBytesOfAFreshOne) {
    ReplicaEncoder encoder;
    std::vector<uint8_t> reused;
    for (const auto& [blocks, full] :
         {std::pair{40, true}, std::pair{3, false}, std::pair{40, true}, std::pair{0, false}}) {
        const ReplicaData r = sampleReplica(blocks, full);
        std::vector<uint8_t> fresh;
        ASSERT_TRUE(encodeReplica(r, fresh).isOk());
        ASSERT_TRUE(encoder.encode(r, reused).isOk());
        EXPECT_EQ(reused, fresh) << blocks << " blocks, full " << full;
        ReplicaData back;
        EXPECT_TRUE(decodeReplica(reused.data(), reused.size(), back).isOk());
        EXPECT_EQ(back.state.blocks.count(), static_cast<size_t>(blocks));
    }
}

TEST(ReplicaCodec, TruncatedCorruptAndForeignBytesAreRefusedWithAReason) {
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeReplica(sampleReplica(8, true), bytes).isOk());
    ReplicaData out;
    // Truncated anywhere.
    for (const size_t keep : {size_t{0}, size_t{10}, kReplicaHeaderBytes, bytes.size() / 2, bytes.size() - 1}) {
        const Status s = decodeReplica(bytes.data(), keep, out);
        EXPECT_EQ(s.code(), StatusCode::kDataLoss) << keep << ": " << s.toString();
    }
    // A flipped byte inside the compressed body: zstd's checksum (or the format) catches it.
    int refused = 0;
    for (size_t at = kReplicaHeaderBytes; at < bytes.size(); at += 97) {
        std::vector<uint8_t> bad = bytes;
        bad[at] ^= 0x5a;
        refused += decodeReplica(bad.data(), bad.size(), out).isOk() ? 0 : 1;
    }
    EXPECT_EQ(refused, static_cast<int>((bytes.size() - kReplicaHeaderBytes + 96) / 97));
    // Another format version.
    std::vector<uint8_t> future = bytes;
    future[4] = static_cast<uint8_t>(kReplicaFormatVersion + 1);
    const Status v = decodeReplica(future.data(), future.size(), out);
    EXPECT_EQ(v.code(), StatusCode::kUnimplemented);
    EXPECT_NE(v.message().find("not compatible"), std::string::npos) << v.message();
    // Not a replica at all.
    std::vector<uint8_t> junk(100, 0x41);
    EXPECT_EQ(decodeReplica(junk.data(), junk.size(), out).code(), StatusCode::kDataLoss);
    // Well-formed bytes of an impossible state (a voxel's TSDF of 5).
    ReplicaData impossible = sampleReplica(2, true);
    impossible.state.blocks.voxels[7].tsdf = 5.0f;
    ASSERT_TRUE(encodeReplica(impossible, bytes).isOk());
    EXPECT_FALSE(decodeReplica(bytes.data(), bytes.size(), out).isOk());
}

ReplicaKeyframe keyframe(uint32_t seq, size_t bytes) {
    ReplicaKeyframe k;
    k.seq = seq;
    k.jpeg.assign(bytes, static_cast<uint8_t>(seq));
    k.T_world_depth.translation() = Eigen::Vector3f(0.01f * static_cast<float>(seq), 0, 0.6f);
    return k;
}

// The serialised body of an encoded replica (what follows its header, decompressed).
void unpackBody(const std::vector<uint8_t>& bytes, std::vector<uint8_t>& body) {
    uint32_t body_size = 0;
    std::memcpy(&body_size, bytes.data() + 8, 4);
    body.resize(body_size);
    ASSERT_EQ(ZSTD_decompress(body.data(), body.size(), bytes.data() + kReplicaHeaderBytes,
                              bytes.size() - kReplicaHeaderBytes),
              body_size);
}

// The texture's keyframes travel with the replica: in full rounds, and in a delta only when they changed; a delta
// without them keeps its base's, so that a takeover still textures the head from the old owner's views.
TEST(ReplicaCodec, KeyframesRoundTripAndADeltaWithoutThemKeepsItsBases) {
    ReplicaData full = sampleReplica(4, true);
    full.has_keyframes = true;
    full.keyframes = {keyframe(3, 1000), keyframe(40, 2000)};
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeReplica(full, bytes).isOk());
    ReplicaData base;
    ASSERT_TRUE(decodeReplica(bytes.data(), bytes.size(), base).isOk());
    ASSERT_TRUE(base.has_keyframes);
    ASSERT_EQ(base.keyframes.size(), 2u);
    EXPECT_EQ(base.keyframes[1].seq, 40u);
    EXPECT_EQ(base.keyframes[1].jpeg, full.keyframes[1].jpeg);
    EXPECT_TRUE(base.keyframes[1].T_world_depth.isApprox(full.keyframes[1].T_world_depth));

    // A delta that joins the base: no new blocks, the next generation, the trajectory going on.
    ReplicaData delta = sampleReplica(0, false);
    delta.base_round = base.round;
    delta.round = base.round + 1;
    delta.state.since_generation = base.state.generation;
    delta.state.generation = base.state.generation + 1;
    delta.state.trajectory_begin = base.state.trajectorySize();
    delta.state.total_blocks = static_cast<uint32_t>(base.state.blocks.count());
    ReplicaData decoded;
    ASSERT_TRUE(encodeReplica(delta, bytes).isOk());
    ASSERT_TRUE(decodeReplica(bytes.data(), bytes.size(), decoded).isOk());
    EXPECT_FALSE(decoded.has_keyframes);
    ASSERT_TRUE(mergeReplica(base, decoded).isOk());
    EXPECT_EQ(base.keyframes.size(), 2u) << "a delta without keyframes keeps the base's";

    delta.has_keyframes = true;
    delta.keyframes = {keyframe(70, 500)};
    delta.base_round = base.round;
    delta.round = base.round + 1;
    delta.state.since_generation = base.state.generation;
    delta.state.generation = base.state.generation + 1;
    delta.state.trajectory_begin = base.state.trajectorySize();
    ASSERT_TRUE(encodeReplica(delta, bytes).isOk());
    ASSERT_TRUE(decodeReplica(bytes.data(), bytes.size(), decoded).isOk());
    ASSERT_TRUE(mergeReplica(base, decoded).isOk());
    ASSERT_EQ(base.keyframes.size(), 1u) << "a delta with keyframes replaces them";
    EXPECT_EQ(base.keyframes[0].seq, 70u);
}

// A server reads the format before its own (a rolling upgrade): version 3 is version 4 without the keyframes at
// the end of the body. Older ones are refused with what to do.
TEST(ReplicaCodec, TheFormatBeforeReadsWithoutKeyframesAndOlderOnesAreRefused) {
    const ReplicaData r = sampleReplica(3, true);
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeReplica(r, bytes).isOk());
    std::vector<uint8_t> body;
    ASSERT_NO_FATAL_FAILURE(unpackBody(bytes, body));
    ASSERT_EQ(body.back(), 0) << "no keyframes: the body ends with their flag";
    body.pop_back();
    std::vector<uint8_t> v3;
    ASSERT_TRUE(frameReplicaBody(body.data(), body.size(), true, v3).isOk());
    uint16_t version = 3;
    std::memcpy(v3.data() + 4, &version, 2);
    ReplicaData out;
    const Status s = decodeReplica(v3.data(), v3.size(), out);
    ASSERT_TRUE(s.isOk()) << s.toString();
    EXPECT_FALSE(out.has_keyframes);
    EXPECT_EQ(out.counters.frames_digest, r.counters.frames_digest);
    EXPECT_EQ(out.state.blocks.count(), 3u);
    // The same bytes read as version 4 lack the flag.
    version = 4;
    std::memcpy(v3.data() + 4, &version, 2);
    EXPECT_EQ(decodeReplica(v3.data(), v3.size(), out).code(), StatusCode::kDataLoss);
    version = 2;
    std::memcpy(v3.data() + 4, &version, 2);
    const Status old = decodeReplica(v3.data(), v3.size(), out);
    EXPECT_EQ(old.code(), StatusCode::kUnimplemented);
    EXPECT_NE(old.message().find("run the same facescan version on every server"), std::string::npos) << old.message();
}

TEST(ReplicaCodec, LyingKeyframeCountsAndSizesAreRefusedBeforeAnythingIsAllocated) {
    ReplicaData r = sampleReplica(1, true);
    r.has_keyframes = true;
    r.keyframes = {keyframe(1, 64)};
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeReplica(r, bytes).isOk());
    std::vector<uint8_t> body;
    ASSERT_NO_FATAL_FAILURE(unpackBody(bytes, body));
    // The tail: flag, count, seq, pose (48), size, 64 bytes.
    const size_t count_at = body.size() - (64 + 4 + 48 + 4 + 4);
    const size_t size_at = body.size() - (64 + 4);
    ReplicaData out;
    for (const auto& [at, value, code] : {std::tuple{count_at, uint32_t{1000}, StatusCode::kOutOfRange},
                                          std::tuple{count_at, uint32_t{2}, StatusCode::kDataLoss},
                                          std::tuple{size_at, uint32_t{1} << 30, StatusCode::kOutOfRange},
                                          std::tuple{size_at, uint32_t{65}, StatusCode::kDataLoss}}) {
        std::vector<uint8_t> bad = body;
        std::memcpy(bad.data() + at, &value, 4);
        std::vector<uint8_t> framed;
        ASSERT_TRUE(frameReplicaBody(bad.data(), bad.size(), true, framed).isOk());
        EXPECT_EQ(decodeReplica(framed.data(), framed.size(), out).code(), code) << at << " = " << value;
    }
    // A writer that has more than the format allows says so instead of writing it.
    r.keyframes.assign(kMaxReplicaKeyframes + 1, keyframe(2, 1));
    EXPECT_EQ(encodeReplica(r, bytes).code(), StatusCode::kInvalidArgument);
}

TEST(ClusterCodec, AnnouncementsAndClaimsRoundTripAndBadOnesAreRefused) {
    ServerAnnounceData a;
    a.server_id = "srv-a";
    a.host = "box1";
    a.pid = 42;
    a.max_sessions = 4;
    a.open_sessions = 1;
    a.cpu_load = 0.5f;
    a.joining = false;
    auto back = fromMessage(toMessage(a));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->server_id, "srv-a");
    EXPECT_EQ(back->host, "box1");
    EXPECT_EQ(back->max_sessions, 4u);
    EXPECT_FALSE(back->joining);

    for (const std::string& bad_id : std::vector<std::string>{"", "a b", "../x", "x*", std::string(65, 'x')}) {
        ServerAnnounceData b = a;
        b.server_id = bad_id;
        EXPECT_FALSE(fromMessage(toMessage(b)).isOk()) << bad_id;
    }
    facescan_wire_ServerAnnounce null_strings = toMessage(a);
    null_strings.server_id = nullptr;
    EXPECT_FALSE(fromMessage(null_strings).isOk());
    ServerAnnounceData load = a;
    load.cpu_load = std::nanf("");
    EXPECT_FALSE(fromMessage(toMessage(load)).isOk());

    SessionOwnerData o;
    o.session_id = "scan-1";
    o.owner_id = "srv-a";
    o.standby_id = "srv-b";
    o.epoch = 3;
    o.state = OwnerState::kActive;
    o.resume_seq = 10;
    o.confirmed_seq = 8;
    o.owner_incarnation = 0x8000000000000001ull;  // all 64 bits travel
    auto owner = fromMessage(toMessage(o));
    ASSERT_TRUE(owner.isOk()) << owner.status().toString();
    EXPECT_EQ(owner->standby_id, "srv-b");
    EXPECT_EQ(owner->epoch, 3u);
    EXPECT_EQ(owner->owner_incarnation, 0x8000000000000001ull);
    facescan_wire_SessionOwner bad_state = toMessage(o);
    bad_state.state = static_cast<facescan_wire_OwnerState>(9);
    EXPECT_FALSE(fromMessage(bad_state).isOk());
    SessionOwnerData zero_epoch = o;
    zero_epoch.epoch = 0;
    EXPECT_FALSE(fromMessage(toMessage(zero_epoch)).isOk());
}

TEST(ClusterCodec, LaterEpochsAlwaysClaimMoreStrongly) {
    for (const char* server : {"a", "b", "srv-9"}) {
        for (const char* other : {"a", "b", "srv-9"}) {
            EXPECT_GT(claimStrength(2, server, "s"), claimStrength(1, other, "s"));
        }
    }
    EXPECT_GT(claimStrength(1, "x", "s"), 0);
    EXPECT_EQ(pairHash("srv-a", "s1"), pairHash("srv-a", "s1"));
    EXPECT_NE(pairHash("ab", "c"), pairHash("a", "bc"));
}

}  // namespace
}  // namespace facescan::wire
