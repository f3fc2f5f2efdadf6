// The audit trail's file (wire/audit_log.hpp): records from two writers (a server and a viewer, or two threads)
// never interleave, the file is the owner's only and only grows, fields with tabs and newlines survive, and a line
// that is not a record is refused with its number.
#include "wire/audit_log.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include "scratch_dir.hpp"

namespace facescan::wire {
namespace {

// In a folder of the test's own, removed once the test passed (scratch_dir.hpp).
std::filesystem::path tempFile(const std::string& name) {
    return facescan::testing::scratchDir("facescan-audit-" + name, /*create=*/true) / name;
}

TEST(AuditLog, TwoWritersAppendWholeRecordsToAPrivateFileThatOnlyGrows) {
    const auto path = tempFile("two-writers.log");
    const mode_t old_umask = ::umask(022);
    auto server = AuditLog::open(path);
    auto viewer = AuditLog::open(path);
    ::umask(old_umask);
    ASSERT_TRUE(server.isOk() && viewer.isOk());
    struct stat st {};
    ASSERT_EQ(::stat(path.c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777, 0600u);
    constexpr int kEach = 200;
    auto write = [](AuditLog& log, const std::string& who) {
        for (int i = 0; i < kEach; ++i) {
            ASSERT_TRUE(log.append({0, "get_mesh", "s-" + std::to_string(i), who, "ok", "test"}).isOk());
        }
    };
    std::thread a(write, std::ref(**server), "client a@host:1:1");
    std::thread b(write, std::ref(**viewer), "login alice");
    a.join();
    b.join();
    auto records = readAuditLog(path);
    ASSERT_TRUE(records.isOk()) << records.status().toString();
    ASSERT_EQ(records->size(), 2u * kEach);
    int from_a = 0;
    for (const AuditRecord& r : *records) {
        EXPECT_TRUE(r.identity == "client a@host:1:1" || r.identity == "login alice") << r.identity;
        from_a += r.identity == "login alice" ? 0 : 1;
    }
    EXPECT_EQ(from_a, kEach);
    // Reopening appends: the earlier records stay.
    server = AuditLog::open(path);
    ASSERT_TRUE(server.isOk());
    ASSERT_TRUE((*server)->append({0, "reset", "s-x", "client c", "ok", "test"}).isOk());
    EXPECT_EQ(readAuditLog(path)->size(), 2u * kEach + 1);
}

TEST(AuditLog, FieldsWithTabsAndNewlinesSurviveAndBadLinesAreRefusedWithTheirNumber) {
    AuditRecord r{1'764'140'580'123'000'000,   "download ply", "scan-1", "login a\tb",
                  "error: no\nserver \\ here", "viewer pc"};
    const std::string line = formatAuditRecord(r);
    EXPECT_EQ(line.find('\n'), std::string::npos);
    EXPECT_TRUE(line.starts_with("2025-11-26T07:03:00.123Z\tdownload ply\tscan-1\t")) << line;
    auto back = parseAuditRecord(line);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_EQ(back->time_ns, r.time_ns);
    EXPECT_EQ(back->identity, r.identity);
    EXPECT_EQ(back->outcome, r.outcome);
    EXPECT_EQ(back->recorder, r.recorder);

    const auto path = tempFile("bad.log");
    std::ofstream(path) << "# a comment\n"
                        << line << "\n"
                        << "not a record\n";
    auto read = readAuditLog(path);
    ASSERT_FALSE(read.isOk());
    EXPECT_NE(read.status().message().find("line 3"), std::string::npos) << read.status().message();
    EXPECT_EQ(readAuditLog(tempFile("missing.log")).status().code(), StatusCode::kNotFound);
    EXPECT_FALSE(parseAuditRecord("yesterday\tget_mesh\ts\tc\tok\tr").isOk());
}

}  // namespace
}  // namespace facescan::wire
