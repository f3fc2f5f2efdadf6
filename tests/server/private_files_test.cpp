// Private files: everything a server writes in its data dir (results, replica log, owner record, lock file) is the
// owner's only, folders 0700 and files 0600, whatever the umask of whoever runs it; what an older version left
// readable is narrowed at start-up; a shared folder such as /tmp is refused rather than made private.
#include "wire/private_files.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "sample_replica.hpp"
#include "service/data_dir_lock.hpp"
#include "service/replica_log.hpp"
#include "service/session_store.hpp"

namespace facescan::service {
namespace {
namespace fs = std::filesystem;

fs::path tempRoot(const std::string& name) {
    const auto dir = fs::temp_directory_path() / ("facescan-private-test-" + std::to_string(getpid()) + "-" + name);
    fs::remove_all(dir);
    return dir;
}

mode_t modeOf(const fs::path& path) {
    struct stat st {};
    EXPECT_EQ(::lstat(path.c_str(), &st), 0) << path;
    return st.st_mode & 07777;
}

// Every folder 0700 and every regular file 0600 under (and including) `dir`; returns how many files it checked.
int expectAllPrivate(const fs::path& dir) {
    EXPECT_EQ(modeOf(dir), 0700u) << dir;
    int files = 0;
    for (const auto& entry : fs::recursive_directory_iterator(dir)) {
        if (entry.is_symlink()) continue;
        if (entry.is_directory()) {
            EXPECT_EQ(modeOf(entry.path()), 0700u) << std::oct << modeOf(entry.path()) << " " << entry.path();
        } else {
            EXPECT_EQ(modeOf(entry.path()), 0600u) << std::oct << modeOf(entry.path()) << " " << entry.path();
            ++files;
        }
    }
    return files;
}

// The umask of a user who never set one (022): without the server's own modes, files would be 0644.
class PrivateFiles : public ::testing::Test {
 protected:
    void SetUp() override { old_umask_ = ::umask(022); }
    void TearDown() override { ::umask(old_umask_); }
    mode_t old_umask_ = 0;
};

TEST_F(PrivateFiles, EverythingTheServerWritesInItsDataDirIsTheOwnersOnly) {
    const fs::path root = tempRoot("writes");
    const fs::path data = root / "site" / "scans";
    ASSERT_TRUE(checkDataDir(data).isOk());
    EXPECT_EQ(modeOf(root), 0700u) << "a missing parent is created private too";
    EXPECT_EQ(modeOf(root / "site"), 0700u);
    auto lock = DataDirLock::acquire(data, "srv-a");
    ASSERT_TRUE(lock.isOk()) << lock.status().toString();

    // A scan in progress: its folder and replica log, as the owner and the standby write them.
    std::string note;
    auto dir = claimSessionDir(data, "scan-1", "srv-a", 1, &note);
    ASSERT_TRUE(dir.isOk()) << dir.status().toString();
    ReplicaLog log(*dir);
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(wire::encodeReplica(testing::sampleReplica(2, true), bytes).isOk());
    ASSERT_TRUE(log.append(bytes, true).isOk());
    wire::ReplicaData delta = testing::sampleReplica(1, false);
    delta.round = 2;
    delta.base_round = 1;
    ASSERT_TRUE(wire::encodeReplica(delta, bytes).isOk());
    ASSERT_TRUE(log.append(bytes, false).isOk());
    // A second owner of the same session at the same epoch writes beside it, in a folder of its own.
    auto twin = claimSessionDir(data, "scan-1", "srv-b", 1, &note);
    ASSERT_TRUE(twin.isOk());
    ASSERT_NE(*twin, *dir);

    // The finished scan's files.
    const std::vector<uint8_t> png = {0x89, 'P', 'N', 'G'};
    SessionFiles files;
    files.trajectory_tum = "0 0 0 0 0 0 0 1\n";
    files.frames_tsv = "# seq\n";
    files.preview_png = &png;
    files.summary_json = "{}\n";
    ASSERT_TRUE(writeSessionFiles(data / "scan-2", files).isOk());

    EXPECT_EQ(expectAllPrivate(data), 8) << "lock, owner.json x2, replica.log, trajectory, frames, preview, summary";
    EXPECT_EQ(modeOf(data / "server.lock"), 0600u);
    EXPECT_EQ(modeOf(*dir / "replica.log"), 0600u);
    fs::remove_all(root);
}

TEST_F(PrivateFiles, WhatAnOlderVersionLeftReadableIsNarrowedAndALinkIsNotFollowed) {
    const fs::path root = tempRoot("narrow");
    const fs::path data = root / "data";
    fs::create_directories(data / "old-scan");
    std::ofstream(data / "old-scan" / "mesh.ply") << "ply";
    std::ofstream(data / "old-scan" / "summary.json") << "{}";
    fs::permissions(data, fs::perms(0755));
    fs::permissions(data / "old-scan", fs::perms(0755));
    fs::permissions(data / "old-scan" / "mesh.ply", fs::perms(0644));
    fs::permissions(data / "old-scan" / "summary.json", fs::perms(0644));
    // Somebody else's file, linked from the data dir: not the server's to change.
    std::ofstream(root / "elsewhere.txt") << "x";
    fs::permissions(root / "elsewhere.txt", fs::perms(0644));
    fs::create_symlink(root / "elsewhere.txt", data / "link.txt");

    auto changed = wire::makeTreePrivate(data);
    ASSERT_TRUE(changed.isOk()) << changed.status().toString();
    EXPECT_EQ(*changed, 4) << "the data dir, the scan's folder and its two files";
    expectAllPrivate(data);
    EXPECT_EQ(modeOf(root / "elsewhere.txt"), 0644u) << "a link's target is left as it is";
    auto again = wire::makeTreePrivate(data);
    ASSERT_TRUE(again.isOk());
    EXPECT_EQ(*again, 0) << "nothing left to change";
    fs::remove_all(root);
}

TEST_F(PrivateFiles, ASharedFolderIsRefusedAsADataDirNotMadePrivate) {
    const fs::path root = tempRoot("shared");
    fs::create_directories(root);
    fs::permissions(root, fs::perms(01777));  // like /tmp
    const Status s = checkDataDir(root);
    ASSERT_FALSE(s.isOk());
    EXPECT_NE(s.message().find("is a shared folder"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("a folder of its own"), std::string::npos) << s.message();
    EXPECT_EQ(modeOf(root), 01777u) << "the shared folder keeps its mode";
    // A folder of its own inside it is fine, and private.
    ASSERT_TRUE(checkDataDir(root / "facescan").isOk());
    EXPECT_EQ(modeOf(root / "facescan"), 0700u);
    // A path through a regular file: the reason, not a crash.
    std::ofstream(root / "file") << "x";
    EXPECT_FALSE(wire::createPrivateDir(root / "file").isOk());
    EXPECT_FALSE(wire::makeFilePrivate(root / "missing").isOk());
    fs::remove_all(root);
}

}  // namespace
}  // namespace facescan::service
