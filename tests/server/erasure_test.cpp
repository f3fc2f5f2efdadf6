// `facescan delete` across servers (service/erasure_service.hpp), with the real facescan binary and servers in
// this process on a private loopback domain: a finished scan whose parts lie in two servers' data dirs is erased
// from both, each report says what went; a third server that was down erases its copy when it starts (the request
// is passed on by the live ones); a running scan is refused unless --force, which finishes it and erases it; the
// audit trails record each erasure with the client that asked.
#include "service/erasure.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include "child_process.hpp"
#include "run_command.hpp"
#include "service/server.hpp"
#include "test_agent.hpp"
#include "test_domain.hpp"
#include "wire/audit_log.hpp"

namespace facescan::service {
namespace {
namespace fs = std::filesystem;
using namespace std::chrono_literals;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

ServerParams params(uint32_t domain, const std::string& id) {
    ServerParams p;
    p.domain = {domain, "loopback"};
    p.data_dir = fs::temp_directory_path() / ("facescan-delete-" + std::to_string(getpid()) + "-" + id);
    p.server_id = id;
    p.join_settle_s = 0.5f;
    return p;
}

void write(const fs::path& file, const std::string& text) {
    fs::create_directories(file.parent_path());
    std::ofstream(file) << text;
}

// What a scan leaves in a data dir: the owner's results, or a replica left beside another owner's.
void scanFiles(const fs::path& data, const std::string& id, const std::string& owner) {
    for (const char* f : {"mesh.ply", "mesh.drc", "trajectory.txt", "summary.json"}) write(data / id / f, f);
    write(data / id / "owner.json", "{\"server_id\": \"" + owner + "\", \"epoch\": 1}\n");
}

testing::CommandRun cli(uint32_t domain, const std::string& args) {
    return testing::runCommand(std::string(FACESCAN_CLI) + " " + args + " --profile loopback --domain " +
                               std::to_string(domain) + " --timeout 15 2>&1");
}

std::vector<wire::AuditRecord> deletes(const fs::path& data) {
    std::vector<wire::AuditRecord> out;
    auto all = wire::readAuditLog(data / "audit.log");
    if (all.isOk()) {
        for (const auto& r : *all) {
            if (r.action == "delete") out.push_back(r);
        }
    }
    return out;
}

TEST(Erasure, DeleteErasesAScanFromEveryServerAndAServerThatWasDownWhenItReturns) {
    const uint32_t domain = testing::privateDomain(41);
    const ServerParams a = params(domain, "srv-a"), b = params(domain, "srv-b"), c = params(domain, "srv-c");
    for (const auto& p : {a, b, c}) fs::remove_all(p.data_dir);
    scanFiles(a.data_dir, "gone-1", "srv-a");
    write(a.data_dir / "gone-1" / "srv-b.e2" / "summary.json", "{}");  // the other owner's part, beside
    scanFiles(b.data_dir, "gone-1", "srv-b");
    write(b.data_dir / "gone-1" / "srv-a.e1" / "replica.log", "an unfinished replica, beside");
    scanFiles(c.data_dir, "gone-1", "srv-c");  // on a server that is down during the delete
    scanFiles(a.data_dir, "kept-1", "srv-a");
    auto server_a = Server::create(a);
    auto server_b = Server::create(b);
    ASSERT_TRUE(server_a.isOk() && server_b.isOk()) << server_a.status().toString() << server_b.status().toString();

    const auto run = cli(domain, "delete gone-1");
    EXPECT_EQ(run.exit_code, 0) << run.out;
    EXPECT_TRUE(contains(run.out, "srv-a: removed 6 file(s):")) << run.out;
    EXPECT_TRUE(contains(run.out, "  gone-1/srv-b.e2/summary.json")) << run.out;
    EXPECT_TRUE(contains(run.out, "srv-b: removed 6 file(s):")) << run.out;
    EXPECT_TRUE(contains(run.out, "  gone-1/srv-a.e1/replica.log")) << run.out;
    EXPECT_TRUE(contains(run.out, "gone-1: erased on 2 of 2 server(s)")) << run.out;
    for (const auto& p : {a, b}) {
        EXPECT_FALSE(fs::exists(p.data_dir / "gone-1")) << p.server_id;
        EXPECT_TRUE(isErased(p.data_dir, "gone-1")) << p.server_id;
        const auto records = deletes(p.data_dir);
        ASSERT_EQ(records.size(), 1u) << p.server_id << ": one record, however often the request is passed on";
        EXPECT_EQ(records[0].session, "gone-1");
        EXPECT_TRUE(records[0].identity.starts_with("client ")) << records[0].identity;
        EXPECT_EQ(records[0].outcome, "ok: removed 6 file(s)");
    }
    EXPECT_TRUE(fs::exists(a.data_dir / "kept-1" / "mesh.ply")) << "only the scan asked for";
    // The scan's commands find nothing any more.
    const auto mesh = cli(domain, "mesh gone-1 -o " + (a.data_dir.parent_path() / "x.ply").string());
    EXPECT_NE(mesh.exit_code, 0) << mesh.out;

    // The server that was down comes back: the live servers pass the request on, and it erases its copy.
    auto server_c = Server::create(c);
    ASSERT_TRUE(server_c.isOk()) << server_c.status().toString();
    for (int i = 0; i < 200 && fs::exists(c.data_dir / "gone-1"); ++i) std::this_thread::sleep_for(50ms);
    EXPECT_FALSE(fs::exists(c.data_dir / "gone-1"));
    EXPECT_TRUE(isErased(c.data_dir, "gone-1"));
    ASSERT_EQ(deletes(c.data_dir).size(), 1u);
    EXPECT_EQ(deletes(c.data_dir)[0].outcome, "ok: removed 5 file(s)");

    // A server restarted after the delete with the scan's files back (a copy, a late write): its own tombstone
    // keeps them from being written again, and the live servers' requests erase them.
    server_a->reset();
    scanFiles(a.data_dir, "gone-1", "srv-a");
    server_a = Server::create(a);
    ASSERT_TRUE(server_a.isOk()) << server_a.status().toString();
    for (int i = 0; i < 200 && fs::exists(a.data_dir / "gone-1"); ++i) std::this_thread::sleep_for(50ms);
    EXPECT_FALSE(fs::exists(a.data_dir / "gone-1"));

    server_c->reset();
    server_b->reset();
    server_a->reset();
    for (const auto& p : {a, b, c}) fs::remove_all(p.data_dir);
}

TEST(Erasure, ARunningScanIsRefusedUnlessForceWhichFinishesAndErasesIt) {
    const uint32_t domain = testing::privateDomain(42);
    const ServerParams a = params(domain, "srv-live");
    fs::remove_all(a.data_dir);
    auto server = Server::create(a);
    ASSERT_TRUE(server.isOk()) << server.status().toString();
    static const testing::EncodedSequence seq = testing::renderSequence(30);
    auto agent = testing::TestAgent::create(domain, "live-9", seq.intrinsics, false);
    ASSERT_TRUE(agent.isOk()) << agent.status().toString();
    ASSERT_TRUE((*agent)->waitForServer(10s));
    ASSERT_TRUE((*agent)->sendCamera().isOk());
    // Live: a loaded server skips frames (the newest wins), so two seconds of them, not a handful, before the
    // first snapshot is asked for.
    ASSERT_TRUE((*agent)->stream(seq, 60, 30.0f, /*end_of_stream=*/false).isOk());
    auto watcher = testing::TestClient::create(domain);
    ASSERT_TRUE(watcher.isOk());
    ASSERT_TRUE((*watcher)->waitForSnapshot("live-9", 10s)) << "a snapshot while scanning (the check below can fail)";

    const auto refused = cli(domain, "delete live-9");
    EXPECT_EQ(refused.exit_code, 1) << refused.out;
    EXPECT_TRUE(contains(refused.out, "is still being scanned on srv-live")) << refused.out;
    EXPECT_TRUE(contains(refused.out, "--force")) << refused.out;
    EXPECT_FALSE(isErased(a.data_dir, "live-9"));

    const auto forced = cli(domain, "delete live-9 --force");
    EXPECT_EQ(forced.exit_code, 0) << forced.out;
    EXPECT_TRUE(contains(forced.out, "finished live-9 on srv-live (--force)")) << forced.out;
    EXPECT_TRUE(contains(forced.out, "srv-live: removed")) << forced.out;
    EXPECT_FALSE(fs::exists(a.data_dir / "live-9"));
    EXPECT_TRUE(isErased(a.data_dir, "live-9"));
    // Nor is its geometry still on the domain: a client that joins now gets no snapshot of it.
    auto late = testing::TestClient::create(domain);
    ASSERT_TRUE(late.isOk());
    ASSERT_TRUE((*late)->waitForServer(10s));
    EXPECT_FALSE((*late)->waitForSnapshot("live-9", 3s)) << "the erased scan's last snapshot is still served";
    agent->reset();
    server->reset();
    fs::remove_all(a.data_dir);
}

// The real facescan-agent streaming a recording (--rate max: it keeps the frames the owner has not confirmed)
// hears `facescan delete --force` of its session (finished, then erased): it stops at once instead of streaming
// its thousands of frames on, drops what it kept, saves nothing, and says so.
TEST(Erasure, ARecordingAgentDropsTheFramesItKeptForAnErasedScan) {
    const uint32_t domain = testing::privateDomain(44);
    const ServerParams a = params(domain, "srv-agent");
    fs::remove_all(a.data_dir);
    const fs::path save_dir = a.data_dir.string() + "-agent-saves";
    fs::remove_all(save_dir);
    auto server = Server::create(a);
    ASSERT_TRUE(server.isOk()) << server.status().toString();
    const std::string session = "agent-erased-" + std::to_string(getpid());
    const fs::path log = a.data_dir.string() + "-agent.log";
    // Far more frames than the test waits for: without the erasure the agent would stream for minutes.
    testing::ChildProcess agent(
        {FACESCAN_AGENT_BIN, "--session", session, "--source", "synthetic:frames=20000,subject=builtin,seed=1",
         "--rate", "max", "--save-dir", save_dir.string(), "--wait-for-server", "20", "--profile", "loopback",
         "--domain", std::to_string(domain)},
        log);
    for (int i = 0; i < 200 && !contains(testing::readText(log), "streaming session"); ++i)
        std::this_thread::sleep_for(100ms);
    ASSERT_TRUE(contains(testing::readText(log), "streaming session")) << testing::readText(log);
    std::this_thread::sleep_for(1s);  // frames on their way, some kept unconfirmed

    const auto asked = cli(domain, "delete --force " + session);
    EXPECT_EQ(asked.exit_code, 0) << asked.out;
    EXPECT_TRUE(contains(asked.out, "srv-agent: removed")) << asked.out;
    const int exit_code = agent.wait(20s);
    const std::string out = testing::readText(log);
    EXPECT_EQ(exit_code, 0) << out;
    EXPECT_TRUE(contains(out, "session " + session + " was erased on the domain (facescan delete, asked by ")) << out;
    EXPECT_TRUE(contains(out, "frame(s) this agent kept for it and saved none")) << out;
    EXPECT_FALSE(contains(out, "saved the")) << out;
    std::error_code ec;
    EXPECT_TRUE(!fs::exists(save_dir, ec) || fs::is_empty(save_dir, ec)) << "the agent saved frames of an erased scan";
    server->reset();
    fs::remove_all(a.data_dir);
    fs::remove_all(save_dir);
    fs::remove(log);
}

// During a cluster run: an owner, a standby holding the scan's replica in memory and on disk. After the delete
// (--force: it was still running) no file, replica or memory copy of it is left on either, and the standby
// restarted afterwards does not bring it back.
TEST(Erasure, DeleteDuringAClusterRunLeavesNoCopyOnOwnerOrStandby) {
    const uint32_t domain = testing::privateDomain(43);
    ServerParams a = params(domain, "srv-one"), b = params(domain, "srv-two");
    for (ServerParams* p : {&a, &b}) {
        fs::remove_all(p->data_dir);
        p->replica_interval_s = 0.2f;
    }
    auto server_a = Server::create(a);
    auto server_b = Server::create(b);
    ASSERT_TRUE(server_a.isOk() && server_b.isOk());
    static const testing::EncodedSequence seq = testing::renderSequence(30);
    auto agent = testing::TestAgent::create(domain, "clu-1", seq.intrinsics, false);
    ASSERT_TRUE(agent.isOk()) << agent.status().toString();
    ASSERT_TRUE((*agent)->waitForServer(10s));
    ASSERT_TRUE((*agent)->sendCamera().isOk());
    ASSERT_TRUE((*agent)->stream(seq, 30, 30.0f, /*end_of_stream=*/false).isOk());
    // One of them stands by for the scan: its replica in memory, and the owner's (and the standby's) on disk.
    Server* standby = nullptr;
    for (int i = 0; i < 200 && !standby; ++i) {
        if ((*server_a)->standbySessions() == 1) standby = server_a->get();
        if ((*server_b)->standbySessions() == 1) standby = server_b->get();
        if (!standby) std::this_thread::sleep_for(50ms);
    }
    ASSERT_TRUE(standby) << "no standby took the scan's replica";
    const ServerParams& sp = standby == server_a->get() ? a : b;
    const ServerParams& op = standby == server_a->get() ? b : a;
    for (int i = 0; i < 100 && !fs::exists(op.data_dir / "clu-1" / "replica.log"); ++i)
        std::this_thread::sleep_for(50ms);
    ASSERT_TRUE(fs::exists(op.data_dir / "clu-1" / "replica.log")) << "the owner's replica on disk";

    const auto run = cli(domain, "delete clu-1 --force");
    EXPECT_EQ(run.exit_code, 0) << run.out;
    EXPECT_TRUE(contains(run.out, "finished clu-1 on " + op.server_id)) << run.out;
    EXPECT_TRUE(contains(run.out, "clu-1: erased on 2 of 2 server(s)")) << run.out;
    for (int i = 0; i < 100 && (*server_a)->standbySessions() + (*server_b)->standbySessions() > 0; ++i) {
        std::this_thread::sleep_for(50ms);
    }
    EXPECT_EQ(standby->standbySessions(), 0) << "the standby's replica in memory";
    EXPECT_EQ((*server_a)->openSessions() + (*server_b)->openSessions(), 0);
    const auto listed = [&] {
        for (const auto* server : {server_a->get(), server_b->get()}) {
            for (const auto& s : server->sessions()) {
                if (s.session_id == "clu-1") return true;
            }
        }
        return false;
    };
    for (int i = 0; i < 60 && listed(); ++i) std::this_thread::sleep_for(50ms);  // the status thread's next tick
    EXPECT_FALSE(listed()) << "its record is still in a server's memory";
    for (const ServerParams* p : {&a, &b}) {
        EXPECT_FALSE(fs::exists(p->data_dir / "clu-1")) << p->server_id;
        EXPECT_TRUE(isErased(p->data_dir, "clu-1")) << p->server_id;
    }
    // The standby restarts: nothing of the scan comes back, in its data dir or its list.
    (standby == server_a->get() ? server_a : server_b)->reset();
    auto again = Server::create(sp);
    ASSERT_TRUE(again.isOk()) << again.status().toString();
    std::this_thread::sleep_for(1s);
    EXPECT_FALSE(fs::exists(sp.data_dir / "clu-1"));
    for (const auto& s : (*again)->sessions()) EXPECT_NE(s.session_id, "clu-1");
    agent->reset();
    again->reset();
    server_a->reset();
    server_b->reset();
    for (const ServerParams* p : {&a, &b}) fs::remove_all(p->data_dir);
}

}  // namespace
}  // namespace facescan::service
