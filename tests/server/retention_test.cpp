// Erasure and retention (service/erasure.hpp): erasing a session removes every file of it from the data dir (the
// owner's results, a replica, another owner's files beside them) and leaves a tombstone that keeps a late replica
// or finish from writing it again; --retain-days erases what is older, by file dates set in the past here, with a
// real server that says so in its log and audit trail.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "service/erasure.hpp"
#include "service/server.hpp"
#include "service/session_store.hpp"
#include "test_domain.hpp"
#include "wire/audit_log.hpp"

namespace facescan::service {
namespace {
namespace fs = std::filesystem;
using namespace std::chrono_literals;

fs::path tempDir(const std::string& name) {
    const auto dir = fs::temp_directory_path() / ("facescan-erase-" + std::to_string(getpid()) + "-" + name);
    fs::remove_all(dir);
    fs::create_directories(dir);
    return dir;
}

void write(const fs::path& file, const std::string& text) {
    fs::create_directories(file.parent_path());
    std::ofstream(file) << text;
}

// Every file under `dir` dated `age` ago.
void age(const fs::path& dir, std::chrono::hours ago) {
    const auto when = fs::file_time_type::clock::now() - ago;
    for (const auto& e : fs::recursive_directory_iterator(dir)) fs::last_write_time(e.path(), when);
    fs::last_write_time(dir, when);
}

// A finished session as a server leaves it, with another owner's files beside it and a stale replica.
void finishedSession(const fs::path& data, const std::string& id) {
    for (const char* f : {"mesh.ply", "mesh.drc", "trajectory.txt", "summary.json", "owner.json"}) {
        write(data / id / f, f);
    }
    write(data / id / "srv-b.e2" / "summary.json", "{}");
    write(data / id / "srv-b.e2" / "replica.log", "x");
}

TEST(Erasure, EveryFileOfTheSessionGoesAndItsTombstoneKeepsItFromComingBack) {
    const fs::path data = tempDir("erase");
    finishedSession(data, "s1");
    finishedSession(data, "s2");
    auto report = eraseSession(data, "s1", "asked by a test");
    ASSERT_TRUE(report.isOk()) << report.status().toString();
    EXPECT_TRUE(report->had_files);
    EXPECT_EQ(report->removed,
              (std::vector<std::string>{"s1/mesh.drc", "s1/mesh.ply", "s1/owner.json", "s1/srv-b.e2/replica.log",
                                        "s1/srv-b.e2/summary.json", "s1/summary.json", "s1/trajectory.txt"}));
    EXPECT_FALSE(fs::exists(data / "s1"));
    EXPECT_TRUE(fs::exists(data / "s2" / "mesh.ply")) << "another session is untouched";
    EXPECT_TRUE(isErased(data, "s1"));
    EXPECT_FALSE(isErased(data, "s2"));
    struct stat st {};
    ASSERT_EQ(::stat((data / "@erased" / "s1").c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777, 0600u);
    // A late replica or finish (both claim the folder first) cannot write it again.
    std::string note;
    auto claim = claimSessionDir(data, "s1", "srv-c", 3, &note);
    ASSERT_FALSE(claim.isOk());
    EXPECT_NE(claim.status().message().find("was erased"), std::string::npos) << claim.status().message();
    EXPECT_FALSE(fs::exists(data / "s1"));
    // A session with nothing here still gets its tombstone; a bad id is refused, not made a path.
    auto none = eraseSession(data, "never-here", "asked by a test");
    ASSERT_TRUE(none.isOk());
    EXPECT_FALSE(none->had_files);
    EXPECT_TRUE(isErased(data, "never-here"));
    EXPECT_FALSE(eraseSession(data, "../s2", "x").isOk());
    EXPECT_FALSE(eraseSession(data, "", "x").isOk());
    EXPECT_TRUE(fs::exists(data / "s2" / "mesh.ply"));
    fs::remove_all(data);
}

TEST(Erasure, OnlySessionsWhoseNewestFileIsOlderThanTheLimitAreOld) {
    const fs::path data = tempDir("old");
    finishedSession(data, "old-1");
    age(data / "old-1", 40 * 24h);
    finishedSession(data, "new-1");
    finishedSession(data, "mixed-1");  // an old result, but a file written yesterday: not old yet
    age(data / "mixed-1", 40 * 24h);
    fs::last_write_time(data / "mixed-1" / "summary.json", fs::file_time_type::clock::now() - 24h);
    write(data / "replica-only" / "replica.log", "x");  // a replica left behind
    age(data / "replica-only", 31 * 24h);
    const auto old = sessionsOlderThan(data, std::chrono::hours(30 * 24), fs::file_time_type::clock::now());
    EXPECT_EQ(old, (std::vector<std::string>{"old-1", "replica-only"}));
    EXPECT_TRUE(sessionsOlderThan(data, std::chrono::hours(50 * 24), fs::file_time_type::clock::now()).empty());
    fs::remove_all(data);
}

TEST(Retention, AServerWithRetainDaysErasesOlderScansAtStartAndSaysSo) {
    ServerParams p;
    p.domain = {facescan::testing::privateDomain(40), "loopback"};
    p.data_dir = tempDir("server");
    p.server_id = "retention-server";
    p.join_settle_s = 0.3f;
    p.retain_days = 30;
    finishedSession(p.data_dir, "old-scan");
    age(p.data_dir / "old-scan", 31 * 24h);
    write(p.data_dir / "old-replica" / "replica.log", "not a replica");
    age(p.data_dir / "old-replica", 45 * 24h);
    finishedSession(p.data_dir, "recent-scan");
    age(p.data_dir / "recent-scan", 29 * 24h);
    auto server = Server::create(p);
    ASSERT_TRUE(server.isOk()) << server.status().toString();
    EXPECT_FALSE(fs::exists(p.data_dir / "old-scan"));
    EXPECT_FALSE(fs::exists(p.data_dir / "old-replica")) << "erased before the server tried to resume it";
    EXPECT_TRUE(fs::exists(p.data_dir / "recent-scan" / "mesh.ply"));
    EXPECT_TRUE(isErased(p.data_dir, "old-scan"));
    auto audit = wire::readAuditLog(p.data_dir / "audit.log");
    ASSERT_TRUE(audit.isOk()) << audit.status().toString();
    ASSERT_EQ(audit->size(), 2u);
    for (const wire::AuditRecord& r : *audit) {
        EXPECT_EQ(r.action, "delete");
        EXPECT_EQ(r.identity, "retention 30 days");
        EXPECT_EQ(r.recorder, "server retention-server");
        EXPECT_TRUE(r.outcome.starts_with("ok: removed ")) << r.outcome;
    }
    EXPECT_EQ((*audit)[0].session, "old-replica");
    EXPECT_EQ((*audit)[1].session, "old-scan");
    EXPECT_NE((*audit)[1].outcome.find("7 file(s)"), std::string::npos) << (*audit)[1].outcome;
    (*server)->shutdown();
    server->reset();
    fs::remove_all(p.data_dir);
}

TEST(Retention, RetainDaysIsASettingWithARange) {
    auto parsed = parseServerArgs({"--retain-days", "90"});
    ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
    EXPECT_EQ(parsed->params.retain_days, 90);
    EXPECT_EQ(parseServerArgs({}).value().params.retain_days, 0) << "kept unless the site says otherwise";
    auto bad = parseServerArgs({"--retain-days", "-1"});
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.status().message().find("--retain-days must be in [0, 36500]"), std::string::npos)
        << bad.status().message();
    EXPECT_NE(serverUsage().find("--retain-days N"), std::string::npos);
}

}  // namespace
}  // namespace facescan::service
