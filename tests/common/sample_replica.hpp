// A small, valid session replica (wire/replica_codec.hpp) for the replica tests: a few blocks with a surface-like
// mix of observed and empty voxels, a trajectory, counters. `full` false makes it a delta on round 4.
#pragma once

#include <random>

#include "wire/replica_codec.hpp"

namespace facescan::testing {

inline wire::ReplicaData sampleReplica(int blocks, bool full, const std::string& session = "scan-1",
                                       const std::string& owner = "srv-a") {
    wire::ReplicaData r;
    r.session_id = session;
    r.owner_id = owner;
    r.epoch = 2;
    r.round = full ? 1 : 5;
    r.base_round = full ? 0 : 4;
    r.next_seq = 77;
    r.camera.session_id = r.session_id;
    r.camera.every_frame = true;
    r.camera.source = "synthetic:test";
    r.counters.frames_received = 77;
    r.counters.frames_integrated = 70;
    r.counters.frames_tracked_only = 6;
    r.counters.frames_digest = 0x1234567890abcdefull;
    recon::ReconState& s = r.state;
    s.resolution_vox = 256;
    s.volume_size_m = 0.386f;
    s.trunc_dist_m = 0.005f;
    s.placed = true;
    s.origin_world = {0.1f, -0.2f, 0.5f};
    s.full = full;
    s.generation = 70;
    s.since_generation = full ? 0 : 60;
    s.have_model = true;
    s.frames_integrated = 70;
    s.T_world_camera.translate(Eigen::Vector3f(0.01f, 0.02f, 0.03f));
    s.trajectory_begin = full ? 0 : 60;
    for (int i = 0; i < (full ? 70 : 10); ++i) s.trajectory.emplace_back(i * 33'000'000LL, recon::Pose::Identity());
    std::mt19937 rng(3);
    for (int b = 0; b < blocks; ++b) {
        s.blocks.coords.emplace_back(b % 32, (b / 32) % 32, b / 1024);
        for (int v = 0; v < recon::kBlockVoxels; ++v) {
            recon::Voxel vx;
            if (rng() % 3 == 0) {  // a third observed, like a surface shell
                vx.tsdf = static_cast<float>(rng() % 2001) / 1000.0f - 1.0f;
                vx.weight = static_cast<float>(rng() % 256);
                vx.r = static_cast<uint8_t>(rng());
            }
            s.blocks.voxels.push_back(vx);
        }
    }
    s.total_blocks = full ? blocks : blocks + 100;
    return r;
}

}  // namespace facescan::testing
