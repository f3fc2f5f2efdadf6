// Replication of the reconstructor's state: deltas merged on a "standby" equal the owner's full state
// bit for bit, a reconstructor restored from it continues the scan like the original, and states that do not
// fit (another volume, a gap, a bad value) are refused.
#include <gtest/gtest.h>

#include <cstring>

#include "recon/reconstructor.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::recon {
namespace {

struct Scene {
    synth::KinectSimulator sim;
    explicit Scene(int frames) : sim(synth::builtinHead(), params(frames)) {}
    static synth::SequenceParams params(int frames) {
        synth::SequenceParams sp;
        sp.frames = frames;
        return sp;
    }
    void feed(Reconstructor& r, int i) const {
        RgbdFrame frame;
        synth::FrameTruth truth;
        sim.render(i, frame, &truth);
        const cv::Mat mask = truth.label == static_cast<uint8_t>(synth::PixelLabel::kHead);
        (void)r.processFrame(frame, mask);
    }
};

// The fast preset (fewer ICP iterations) on the face volume: a coarser cube (3 mm voxels) does not track.
ReconParams smallVolume() { return ReconParams::fast(); }

void expectSameVoxels(const ReconState& a, const ReconState& b) {
    ASSERT_EQ(a.blocks.count(), b.blocks.count());
    // Block order may differ (pool order vs merge order): compare by coordinates.
    for (size_t i = 0; i < a.blocks.count(); ++i) {
        size_t j = 0;
        while (j < b.blocks.count() && b.blocks.coords[j] != a.blocks.coords[i]) ++j;
        ASSERT_LT(j, b.blocks.count()) << "block missing";
        EXPECT_EQ(0, std::memcmp(&a.blocks.voxels[i * kBlockVoxels], &b.blocks.voxels[j * kBlockVoxels],
                                 kBlockVoxels * sizeof(Voxel)));
    }
}

// fuse_every > 1 (a loaded server's last economy step): the trajectory holds every tracked frame, so it outgrows
// the fused-frame count, and a delta's trajectory_begin with it.
void replicateAndRestore(int fuse_every) {
    const Scene scene(40);
    ReconParams params = smallVolume();
    params.fuse_every = fuse_every;
    Reconstructor owner(scene.sim.intrinsics(), params);
    ASSERT_TRUE(owner.initStatus().isOk());
    ReconState standby, delta;
    size_t delta_blocks = 0, full_blocks = 0;
    for (int i = 0; i < 20; ++i) {
        scene.feed(owner, i);
        if (i % 5 != 4) continue;  // a replica every 5 frames
        owner.captureState(standby.generation, standby.trajectorySize(), delta);
        if (i == 4) {
            EXPECT_TRUE(delta.full);
        }
        ASSERT_TRUE(mergeState(standby, delta).isOk());
        if (!delta.full) {
            delta_blocks += delta.blocks.count();
            full_blocks += static_cast<size_t>(delta.total_blocks);
        }
    }
    EXPECT_LT(delta_blocks, full_blocks) << "deltas should carry only the blocks that changed";
    ReconState full;
    owner.captureState(0, 0, full);
    expectSameVoxels(full, standby);
    EXPECT_EQ(standby.frames_integrated, owner.framesIntegrated());
    ASSERT_EQ(standby.trajectory.size(), owner.trajectory().size());
    EXPECT_TRUE(standby.T_world_camera.isApprox(owner.lastPose()));

    Reconstructor restored(scene.sim.intrinsics(), params);
    ASSERT_TRUE(restored.restoreState(standby).isOk());
    EXPECT_EQ(restored.framesIntegrated(), owner.framesIntegrated());
    for (int i = 20; i < 40; ++i) {
        scene.feed(owner, i);
        scene.feed(restored, i);
    }
    EXPECT_EQ(restored.framesIntegrated(), owner.framesIntegrated());
    ASSERT_EQ(restored.trajectory().size(), owner.trajectory().size());
    float worst_m = 0;
    for (size_t i = 0; i < owner.trajectory().size(); ++i) {
        const Pose d = owner.trajectory()[i].second.inverse() * restored.trajectory()[i].second;
        worst_m = std::max(worst_m, d.translation().norm());
    }
    EXPECT_LT(worst_m, 0.0005f) << "the restored scan drifted from the original";
    if (fuse_every > 1) {
        EXPECT_EQ(owner.trajectory().size(), 40u) << "every frame tracked";
        EXPECT_LE(owner.framesIntegrated(), 40 / fuse_every + 2) << "one tracked frame in fuse_every fused";
    }
}

TEST(ReconState, DeltasMergedOnAStandbyEqualTheFullStateAndARestoredScanContinuesLikeTheOriginal) {
    replicateAndRestore(1);
}

TEST(ReconState, AScanThatFusesEveryOtherFrameReplicatesAndRestoresToo) { replicateAndRestore(2); }

// The server hands last round's capture back in to reuse its buffers: a delta captured into a state that held a
// full one equals the same delta captured into a fresh state (no block or pose of the full one left over).
TEST(ReconState, ACaptureIntoAUsedStateEqualsOneIntoAFreshState) {
    const Scene scene(12);
    Reconstructor owner(scene.sim.intrinsics(), smallVolume());
    ASSERT_TRUE(owner.initStatus().isOk());
    for (int i = 0; i < 8; ++i) scene.feed(owner, i);
    ReconState used;
    owner.captureState(0, 0, used);
    const uint64_t since = used.generation;
    const size_t trajectory_from = used.trajectorySize();
    for (int i = 8; i < 10; ++i) scene.feed(owner, i);
    ReconState fresh;
    owner.captureState(since, trajectory_from, fresh);
    owner.captureState(since, trajectory_from, used);
    ASSERT_FALSE(fresh.full);
    EXPECT_FALSE(used.full);
    EXPECT_LT(fresh.blocks.count(), static_cast<size_t>(fresh.total_blocks)) << "a delta should be smaller";
    EXPECT_EQ(used.blocks.coords, fresh.blocks.coords);
    ASSERT_EQ(used.blocks.voxels.size(), fresh.blocks.voxels.size());
    EXPECT_EQ(0, std::memcmp(used.blocks.voxels.data(), fresh.blocks.voxels.data(),
                             fresh.blocks.voxels.size() * sizeof(Voxel)));
    EXPECT_EQ(used.trajectory_begin, fresh.trajectory_begin);
    EXPECT_EQ(used.trajectory.size(), fresh.trajectory.size());
    EXPECT_EQ(used.generation, fresh.generation);
}

TEST(ReconState, StatesThatDoNotFitAreRefused) {
    const Scene scene(6);
    Reconstructor owner(scene.sim.intrinsics(), smallVolume());
    for (int i = 0; i < 6; ++i) scene.feed(owner, i);
    ReconState full, delta;
    owner.captureState(0, 0, full);
    ASSERT_TRUE(full.validate().isOk());

    // Another volume.
    ReconParams coarse = ReconParams::fast();
    coarse.tsdf.resolution_vox = 128;
    Reconstructor other(scene.sim.intrinsics(), coarse);
    EXPECT_FALSE(other.restoreState(full).isOk());
    // A delta that skips a generation.
    ReconState base = full;
    base.generation -= 1;
    owner.captureState(full.generation, full.trajectorySize(), delta);
    EXPECT_FALSE(mergeState(base, delta).isOk());
    // Impossible values.
    ReconState bad = full;
    bad.blocks.voxels[3].tsdf = 7.0f;
    EXPECT_FALSE(bad.validate().isOk());
    bad = full;
    bad.blocks.coords.push_back(bad.blocks.coords.front());
    bad.blocks.voxels.resize(bad.blocks.voxels.size() + kBlockVoxels);
    ++bad.total_blocks;
    EXPECT_FALSE(bad.validate().isOk()) << "a duplicate block must be refused";
    bad = full;
    bad.T_world_camera.matrix()(0, 3) = std::nanf("");
    EXPECT_FALSE(bad.validate().isOk());
    // A reset in between makes the next capture full.
    owner.reset();
    owner.captureState(full.generation, full.trajectorySize(), delta);
    EXPECT_TRUE(delta.full);
}

}  // namespace
}  // namespace facescan::recon

namespace facescan::recon {
namespace {

// Live mode after a takeover: frames of the gap never arrive. A restored reconstructor must track across a gap
// exactly as well as one that never stopped (the restore itself must not cost tracking).
TEST(ReconState, ARestoredReconstructorTracksAcrossAGapLikeTheOriginal) {
    const Scene scene(50);
    const ReconParams params = smallVolume();
    for (const int gap : {5, 20}) {  // one the tracker bridges, one it does not (the head turned too far)
        Reconstructor original(scene.sim.intrinsics(), params);
        for (int i = 0; i < 20; ++i) scene.feed(original, i);
        ReconState full;
        original.captureState(0, 0, full);
        Reconstructor restored(scene.sim.intrinsics(), params);
        ASSERT_TRUE(restored.restoreState(full).isOk());
        for (int i = 20 + gap; i < 20 + gap + 6; ++i) {
            scene.feed(original, i);
            scene.feed(restored, i);
        }
        std::printf("gap %d: original %d integrated, restored %d\n", gap, original.framesIntegrated(),
                    restored.framesIntegrated());
        EXPECT_EQ(restored.framesIntegrated(), original.framesIntegrated()) << "gap " << gap;
    }
}

}  // namespace
}  // namespace facescan::recon
