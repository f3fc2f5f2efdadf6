// The cluster's messages and the replica format: round trips, and every kind of bad input refused with
// a Status that says what is wrong (truncated, corrupt, another format version, values out of range).
#include <gtest/gtest.h>

#include <cstring>

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
    auto owner = fromMessage(toMessage(o));
    ASSERT_TRUE(owner.isOk()) << owner.status().toString();
    EXPECT_EQ(owner->standby_id, "srv-b");
    EXPECT_EQ(owner->epoch, 3u);
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
