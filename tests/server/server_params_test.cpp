// Parameters of facescan-server: config file and flags map onto the recon core's Params structs, with errors
// that name the key, the file and the line. And the data-dir writer: atomic files, nothing half-written, and what a
// finish cut off by a kill left removed when the server starts.
#include "service/server_params.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "sample_replica.hpp"
#include "scratch_dir.hpp"
#include "service/replica_log.hpp"
#include "service/session.hpp"
#include "service/session_store.hpp"

namespace facescan::service {
namespace {

// Removed once the test passed (scratch_dir.hpp).
std::filesystem::path tempDir(const std::string& name) {
    return testing::scratchDir("facescan-server-test-" + name, /*create=*/true);
}

TEST(ServerParams, DefaultsAreMeyersAndValid) {
    auto parsed = parseServerArgs({});
    ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
    EXPECT_FALSE(parsed->help);
    const ServerParams& p = parsed->params;
    EXPECT_EQ(p.preset, "face");
    EXPECT_EQ(p.recon.tsdf.resolution_vox, 256);
    EXPECT_NEAR(p.recon.tsdf.volume_size_m, 0.386f, 1e-6f);
    EXPECT_FLOAT_EQ(p.snapshot_hz, 1.0f);
    EXPECT_EQ(p.data_dir, std::filesystem::path("facescan-data"));
    EXPECT_FALSE(p.server_id.empty());
}

TEST(ServerParams, ConfigFileThenFlagsOverride) {
    const auto dir = tempDir("config");
    const auto file = dir / "server.conf";
    std::ofstream(file) << "# a comment\n"
                           "tsdf.resolution_vox = 128\n"
                           "tsdf.voxel_size_m = 0.002   # 2 mm voxels: a 0.256 m cube\n"
                           "icp.iterations0 = 7\n"
                           "max_sessions = 3\n"
                           "snapshot_hz = 2\n";
    auto parsed =
        parseServerArgs({"--config", file.string(), "--snapshot-hz", "0.5", "--domain=42", "--profile", "loopback",
                         "--set", "filter.sigma_depth_m=0.03", "--keep-finished", "3", "--keep-finished-s=30"});
    ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
    const ServerParams& p = parsed->params;
    EXPECT_EQ(p.recon.tsdf.resolution_vox, 128);
    EXPECT_NEAR(p.recon.tsdf.volume_size_m, 0.256f, 1e-6f);
    EXPECT_EQ(p.recon.icp.iterations[0], 7);
    EXPECT_EQ(p.max_sessions, 3);
    EXPECT_FLOAT_EQ(p.snapshot_hz, 0.5f);  // the flag wins over the file
    EXPECT_EQ(p.domain.domain_id, 42u);
    EXPECT_EQ(p.domain.profile, "loopback");
    EXPECT_FLOAT_EQ(p.recon.filter.sigma_depth_m, 0.03f);
    EXPECT_EQ(p.keep_finished, 3);
    EXPECT_FLOAT_EQ(p.keep_finished_s, 30.0f);
}

TEST(ServerParams, SecurityIsAFlagAndAConfigKey) {
    auto flag = parseServerArgs({"--security", "/etc/facescan/site/server"});
    ASSERT_TRUE(flag.isOk()) << flag.status().toString();
    EXPECT_EQ(flag->params.domain.security, "/etc/facescan/site/server");
    auto key = parseServerArgs({"--set", "security=/srv/id"});
    ASSERT_TRUE(key.isOk()) << key.status().toString();
    EXPECT_EQ(key->params.domain.security, "/srv/id");
    EXPECT_TRUE(parseServerArgs({})->params.domain.security.empty());
    EXPECT_FALSE(parseServerArgs({"--security", ""}).isOk());
}

TEST(ServerParams, PresetFastChangesTheReconParams) {
    auto fast = parseServerArgs({"--preset", "fast"});
    ASSERT_TRUE(fast.isOk()) << fast.status().toString();
    EXPECT_EQ(fast->params.preset, "fast");
    const recon::ReconParams expected = recon::ReconParams::fast();
    EXPECT_EQ(fast->params.recon.icp.iterations, expected.icp.iterations);
    EXPECT_FALSE(parseServerArgs({"--preset", "slow"}).isOk());
}

TEST(ServerParams, BadInputGivesClearErrors) {
    auto unknown_flag = parseServerArgs({"--frobnicate", "1"});
    ASSERT_FALSE(unknown_flag.isOk());
    EXPECT_NE(unknown_flag.status().message().find("--frobnicate"), std::string::npos);

    auto missing = parseServerArgs({"--max-sessions"});
    ASSERT_FALSE(missing.isOk());
    EXPECT_NE(missing.status().message().find("needs a value"), std::string::npos);

    auto not_number = parseServerArgs({"--snapshot-hz", "fast"});
    ASSERT_FALSE(not_number.isOk());
    EXPECT_NE(not_number.status().message().find("snapshot_hz"), std::string::npos);

    auto negative_keep = parseServerArgs({"--keep-finished", "-1"});
    ASSERT_FALSE(negative_keep.isOk());
    EXPECT_NE(negative_keep.status().message().find("--keep-finished"), std::string::npos);

    auto out_of_range = parseServerArgs({"--max-sessions", "0"});
    ASSERT_FALSE(out_of_range.isOk());
    EXPECT_NE(out_of_range.status().message().find("--max-sessions"), std::string::npos);

    // A recon core value that its own validate() rejects is reported at start, not at the first frame.
    auto bad_recon = parseServerArgs({"--set", "tsdf.trunc_dist_m=-1"});
    ASSERT_FALSE(bad_recon.isOk());
    EXPECT_NE(bad_recon.status().message().find("recon parameters"), std::string::npos);

    const auto dir = tempDir("badconfig");
    std::ofstream(dir / "a.conf") << "tsdf.resolution_vox = 128\nnot_a_key = 3\n";
    auto bad_key = parseServerArgs({"--config", (dir / "a.conf").string()});
    ASSERT_FALSE(bad_key.isOk());
    EXPECT_NE(bad_key.status().message().find("a.conf:2"), std::string::npos) << bad_key.status().message();
    EXPECT_NE(bad_key.status().message().find("not_a_key"), std::string::npos);

    std::ofstream(dir / "b.conf") << "tsdf.resolution_vox 128\n";
    EXPECT_FALSE(parseServerArgs({"--config", (dir / "b.conf").string()}).isOk());
    EXPECT_EQ(parseServerArgs({"--config", (dir / "none.conf").string()}).status().code(), StatusCode::kNotFound);
    EXPECT_TRUE(parseServerArgs({"--help"})->help);
}

// The finished model's options: flags and config keys, presets, and a budget below a head refused at start.
TEST(ServerParams, FinishingOptionsAreFlagsAndConfigKeys) {
    auto defaults = parseServerArgs({});
    ASSERT_TRUE(defaults.isOk());
    EXPECT_EQ(defaults->params.finish.max_triangles, 0);
    EXPECT_EQ(defaults->params.finish.keep, recon::KeepParts::kHead);
    EXPECT_EQ(defaults->params.finish.close, recon::ClosingMode::kNone);
    auto set = parseServerArgs({"--max-triangles", "web", "--keep", "all", "--close", "holes", "--crop",
                                "-0.2,-0.2,0.3,0.2,0.2,1", "--set", "finish.max_hole_m=0.01"});
    ASSERT_TRUE(set.isOk()) << set.status().toString();
    EXPECT_EQ(set->params.finish.max_triangles, 20000);
    EXPECT_EQ(set->params.finish.keep, recon::KeepParts::kAll);
    EXPECT_EQ(set->params.finish.close, recon::ClosingMode::kHoles);
    ASSERT_TRUE(set->params.finish.crop_m.has_value());
    EXPECT_FLOAT_EQ(set->params.finish.crop_m->min().z(), 0.3f);
    EXPECT_FLOAT_EQ(set->params.finish.max_hole_m, 0.01f);
    auto too_few = parseServerArgs({"--max-triangles", "100"});
    ASSERT_FALSE(too_few.isOk());
    EXPECT_NE(too_few.status().message().find("at least 500"), std::string::npos) << too_few.status().message();
    EXPECT_NE(too_few.status().message().find("--max-triangles"), std::string::npos) << too_few.status().message();
    auto bad_close = parseServerArgs({"--close", "sometimes"});
    ASSERT_FALSE(bad_close.isOk());
    EXPECT_NE(bad_close.status().message().find("none, holes or watertight"), std::string::npos);
    EXPECT_FALSE(parseServerArgs({"--crop", "1,2,3"}).isOk());
    EXPECT_FALSE(parseServerArgs({"--set", "finish.max_hole_m=-1"}).isOk());
}

TEST(ServerParams, RollIsAFlagAndAConfigKey) {
    auto defaults = parseServerArgs({});
    ASSERT_TRUE(defaults.isOk());
    EXPECT_EQ(defaults->params.face.roll_deg, recon::FacePipelineParams::kRollAuto);
    auto portrait = parseServerArgs({"--roll", "90"});
    ASSERT_TRUE(portrait.isOk()) << portrait.status().toString();
    EXPECT_EQ(portrait->params.face.roll_deg, 90);
    auto set = parseServerArgs({"--set", "face.roll=180"});
    ASSERT_TRUE(set.isOk()) << set.status().toString();
    EXPECT_EQ(set->params.face.roll_deg, 180);
    auto slant = parseServerArgs({"--roll", "30"});
    ASSERT_TRUE(slant.isOk()) << slant.status().toString();
    EXPECT_EQ(slant->params.face.roll_deg, 30);
    auto bad = parseServerArgs({"--roll", "40"});
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.status().message().find("auto or 0 to 345 degrees in steps of 15"), std::string::npos)
        << bad.status().message();
    EXPECT_NE(bad.status().message().find("--roll"), std::string::npos) << bad.status().message();
}

// The agent's --roll (CameraInfo's hint) sets the session's roll while the server's own is auto; the server's
// face.roll, when set, wins; no hint leaves it to be found from the frames (upright until then).
TEST(ServerParams, TheAgentsRollHintIsUsedUnlessTheServerSetsItsOwn) {
    wire::CameraInfoData camera;
    camera.session_id = "rolled";
    const auto server_auto = parseServerArgs({});
    const auto server_90 = parseServerArgs({"--roll", "90"});
    ASSERT_TRUE(server_auto.isOk() && server_90.isOk());

    camera.roll_deg = 180;
    auto hinted = SessionEngine::build(server_auto->params, camera, nullptr);
    ASSERT_TRUE(hinted.isOk()) << hinted.status().toString();
    EXPECT_EQ(hinted->pipeline->roll().degrees(), 180);
    EXPECT_NE(hinted->camera_line.find("roll 180 deg (the agent's --roll)"), std::string::npos) << hinted->camera_line;

    auto overridden = SessionEngine::build(server_90->params, camera, nullptr);
    ASSERT_TRUE(overridden.isOk()) << overridden.status().toString();
    EXPECT_EQ(overridden->pipeline->roll().degrees(), 90);
    EXPECT_NE(overridden->camera_line.find("roll 90 deg (face.roll)"), std::string::npos) << overridden->camera_line;

    camera.roll_deg = 30;  // a phone held at a slant
    auto slanted = SessionEngine::build(server_auto->params, camera, nullptr);
    ASSERT_TRUE(slanted.isOk()) << slanted.status().toString();
    EXPECT_EQ(slanted->pipeline->roll().degrees(), 30);
    EXPECT_NE(slanted->camera_line.find("roll 30 deg (the agent's --roll)"), std::string::npos) << slanted->camera_line;

    camera.roll_deg = wire::CameraInfoData::kRollUnknown;
    auto found = SessionEngine::build(server_auto->params, camera, nullptr);
    ASSERT_TRUE(found.isOk()) << found.status().toString();
    EXPECT_EQ(found->pipeline->roll().degrees(), 0);
    EXPECT_EQ(found->camera_line.find("roll"), std::string::npos) << found->camera_line;
}

TEST(SessionStore, WritesAtomicallyAndLeavesNoTemporaryFiles) {
    const auto dir = tempDir("store");
    const auto path = dir / "summary.json";
    ASSERT_TRUE(writeFileAtomic(path, std::string("{\"a\": 1}\n")).isOk());
    ASSERT_TRUE(writeFileAtomic(path, std::string("{\"a\": 2}\n")).isOk());  // replaces, never appends
    std::ifstream in(path);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(text, "{\"a\": 2}\n");
    EXPECT_FALSE(std::filesystem::exists(dir / "summary.json.tmp"));
    // A directory that cannot be written: an error, and no file under the final name.
    EXPECT_FALSE(writeFileAtomic(dir / "missing" / "x.txt", std::string("x")).isOk());
    EXPECT_FALSE(std::filesystem::exists(dir / "missing" / "x.txt"));
}

TEST(ServerParams, ShippedConfigFileParsesAndPointsAtTheStateDirectory) {
    // deploy/config/server.conf is /etc/facescan/server.conf of the .deb: it must load, and keep the data where the
    // systemd unit lets the service write.
    auto parsed =
        parseServerArgs({"--config", std::string(FACESCAN_SOURCE_DIR) + "/deploy/config/server.conf", "--check"});
    ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
    EXPECT_TRUE(parsed->check);
    EXPECT_EQ(parsed->params.data_dir, "/var/lib/facescan");
    EXPECT_EQ(parsed->params.domain.profile, "lan");
    EXPECT_EQ(parsed->params.preset, "face");
}

TEST(SessionStore, DataDirIsCreatedAndProvedWritableOrRefusedWithTheReason) {
    const auto dir = tempDir("datadir");
    ASSERT_TRUE(checkDataDir(dir / "new" / "scans").isOk());
    EXPECT_TRUE(std::filesystem::is_directory(dir / "new" / "scans"));
    EXPECT_TRUE(std::filesystem::is_empty(dir / "new" / "scans")) << "the write probe must not stay behind";
    // Under a regular file nothing can be created (even as root).
    std::ofstream(dir / "file") << "x";
    const Status s = checkDataDir(dir / "file" / "scans");
    EXPECT_FALSE(s.isOk());
    EXPECT_NE(s.message().find("data dir " + (dir / "file" / "scans").string()), std::string::npos) << s.message();
}

TEST(SessionStore, JsonEscapesQuotesAndControlCharacters) {
    EXPECT_EQ(jsonEscape("a\"b\\c\nd\x01"), "a\\\"b\\\\c\\nd\\u0001");
}

// Split brain: two servers that could not see each other both owned a session, and their data dirs
// are one (a shared folder). Neither may write over the other's files; owner.json says whose they are.
TEST(SessionStore, TwoOwnersOfOneSessionNeverShareAFolder) {
    const auto data = tempDir("owners");
    std::string note;
    auto a = claimSessionDir(data, "s", "srv-a", 1, &note);
    ASSERT_TRUE(a.isOk());
    EXPECT_EQ(*a, data / "s");
    EXPECT_TRUE(note.empty());
    // The standby took over (epoch 2): the folder is its own now, and owner.json remembers the previous owner.
    auto b = claimSessionDir(data, "s", "srv-b", 2, &note);
    ASSERT_TRUE(b.isOk());
    EXPECT_EQ(*b, data / "s");
    const auto owner = readSessionOwner(data / "s");
    ASSERT_TRUE(owner);
    EXPECT_EQ(owner->first, "srv-b");
    EXPECT_EQ(owner->second, 2u);
    // The old owner, cut off, writes its result later (epoch 1): beside the new owner's files, and says so.
    auto stale = claimSessionDir(data, "s", "srv-a", 1, &note);
    ASSERT_TRUE(stale.isOk());
    EXPECT_EQ(*stale, data / "s" / "srv-a.e1");
    EXPECT_NE(note.find("belongs to server 'srv-b'"), std::string::npos) << note;
    EXPECT_EQ(readSessionOwner(data / "s")->first, "srv-b") << "the new owner's record must stay";
    EXPECT_EQ(readSessionOwner(*stale)->first, "srv-a");
    // The same epoch from another server (two claims that met): beside as well.
    auto twin = claimSessionDir(data, "s", "srv-c", 2, &note);
    ASSERT_TRUE(twin.isOk());
    EXPECT_EQ(*twin, data / "s" / "srv-c.e2");
}

// A server killed while it wrote a finished scan restarts: the files of that finish (no summary.json, no replica
// to continue from) are an incomplete result beside the one the next owner writes, and go. Everything else stays:
// finished scans, resumable ones, other servers' folders, folders it cannot read as a session's.
TEST(SessionStore, AFinishCutOffByAKillIsRemovedWhenTheServerStartsAndNothingElseIs) {
    const auto data = tempDir("cutoff");
    const auto write = [](const std::filesystem::path& file, const std::string& text) {
        std::filesystem::create_directories(file.parent_path());
        std::ofstream(file) << text;
    };
    const auto owner = [&](const std::filesystem::path& dir, const std::string& server, int epoch) {
        write(dir / "owner.json", "{\"server_id\": \"" + server + "\", \"epoch\": " + std::to_string(epoch) + "}\n");
    };
    // Cut off: mesh and Draco written, a half-written trajectory's temporary, no summary.
    owner(data / "cut", "srv-a", 2);
    for (const char* f : {"mesh.ply", "mesh.drc", "trajectory.txt.tmp"}) write(data / "cut" / f, f);
    // Cut off beside another owner's finished files: the sub-folder goes, the other's files stay.
    owner(data / "beside", "srv-b", 3);
    for (const char* f : {"mesh.ply", "summary.json"}) write(data / "beside" / f, f);
    owner(data / "beside" / "srv-a.e2", "srv-a", 2);
    write(data / "beside" / "srv-a.e2" / "mesh.ply", "x");
    // Finished here; resumable here; cut off on another server (a shared folder); no owner record.
    owner(data / "done", "srv-a", 1);
    for (const char* f : {"mesh.ply", "summary.json"}) write(data / "done" / f, f);
    owner(data / "resumable", "srv-a", 1);
    for (const char* f : {"mesh.ply", "replica.log"}) write(data / "resumable" / f, f);
    owner(data / "theirs", "srv-b", 1);
    write(data / "theirs" / "mesh.ply", "x");
    write(data / "unknown" / "mesh.ply", "x");

    const std::vector<InterruptedFinish> cut = removeInterruptedFinishes(data, "srv-a");
    ASSERT_EQ(cut.size(), 2u);
    EXPECT_EQ(cut[0].dir, data / "beside" / "srv-a.e2");
    EXPECT_EQ(cut[0].removed, (std::vector<std::string>{"mesh.ply"}));
    EXPECT_EQ(cut[1].dir, data / "cut");
    EXPECT_EQ(cut[1].removed, (std::vector<std::string>{"mesh.drc", "mesh.ply", "trajectory.txt.tmp"}));
    EXPECT_FALSE(std::filesystem::exists(data / "cut")) << "nothing else was in it";
    EXPECT_FALSE(std::filesystem::exists(data / "beside" / "srv-a.e2"));
    EXPECT_TRUE(std::filesystem::exists(data / "beside" / "mesh.ply"));
    EXPECT_EQ(readSessionOwner(data / "beside")->first, "srv-b");
    for (const char* kept : {"done/mesh.ply", "done/summary.json", "resumable/mesh.ply", "resumable/replica.log",
                             "theirs/mesh.ply", "unknown/mesh.ply"}) {
        EXPECT_TRUE(std::filesystem::exists(data / kept)) << kept;
    }
    EXPECT_TRUE(removeInterruptedFinishes(data, "srv-a").empty()) << "once is enough";
    EXPECT_TRUE(removeInterruptedFinishes(data / "missing", "srv-a").empty());
}

// Restart recovery: the data dir's replica log resumes from its last complete round, whatever a crash tore.
TEST(ReplicaLog, ATornTailIsSkippedAndTheRoundsBeforeItAreResumed) {
    const auto dir = tempDir("replica-log");
    ReplicaLog log(dir);
    wire::ReplicaData full = testing::sampleReplica(3, true);
    full.owner_id = "srv-a";
    wire::ReplicaData delta = testing::sampleReplica(1, false);
    delta.owner_id = "srv-a";
    delta.round = 2;
    delta.base_round = 1;
    delta.state.since_generation = full.state.generation;
    delta.state.generation = full.state.generation + 5;
    delta.state.trajectory_begin = full.state.trajectorySize();
    delta.state.total_blocks = 4;
    delta.state.blocks.coords[0] = Eigen::Vector3i(30, 30, 30);  // a new block
    delta.next_seq = 90;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(wire::encodeReplica(full, bytes).isOk());
    ASSERT_TRUE(log.append(bytes, true).isOk());
    ASSERT_TRUE(wire::encodeReplica(delta, bytes).isOk());
    ASSERT_TRUE(log.append(bytes, false).isOk());
    std::string warning;
    auto back = loadReplicaLog(dir, &warning);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_TRUE(warning.empty()) << warning;
    EXPECT_EQ(back->round, 2u);
    EXPECT_EQ(back->next_seq, 90u);
    EXPECT_EQ(back->state.blocks.count(), 4u);
    // A crash in the middle of the next append: half a record at the end.
    {
        std::ofstream torn(dir / "replica.log", std::ios::binary | std::ios::app);
        torn.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size() / 2));
    }
    back = loadReplicaLog(dir, &warning);
    ASSERT_TRUE(back.isOk());
    EXPECT_EQ(back->round, 2u) << "the complete rounds are kept";
    EXPECT_NE(warning.find("resuming from round 2"), std::string::npos) << warning;
    EXPECT_EQ(loadReplicaLog(tempDir("no-log"), nullptr).status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace facescan::service
