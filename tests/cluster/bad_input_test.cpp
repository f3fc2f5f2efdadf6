// What the cluster refuses, with the real programs: a new scan under the id of one that finished. Its agent says
// why and stops, and the finished scan's files stay as they were, both while the finished claim is still on the
// domain and after a restart of the server (when only its data dir remembers the scan).
#include <gtest/gtest.h>

#include "cluster_rig.hpp"

namespace facescan::testing {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

void expectRefusedAndUntouched(ClusterRig& rig, const std::string& attempt, const std::string& summary_before) {
    ChildProcess second(
        {FACESCAN_AGENT_BIN, "--profile", "loopback", "--domain", rig.domain(), "--session", "reused", "--source",
         "synthetic:frames=20,subject=builtin,seed=2", "--rate", "max", "--wait-for-server", "60"},
        rig.dir() / ("agent-" + attempt + ".log"));
    EXPECT_EQ(second.wait(60s), 1);
    const std::string log = readText(rig.dir() / ("agent-" + attempt + ".log"));
    EXPECT_NE(log.find("session reused already finished on server 'srv-a'"), std::string::npos) << log;
    EXPECT_NE(log.find("start the agent with another --session"), std::string::npos) << log;
    EXPECT_EQ(readText(rig.dataDir("srv-a") / "reused" / "summary.json"), summary_before);
}

TEST(ClusterBadInput, ANewScanUnderAFinishedSessionsIdIsRefusedAndTheFinishedScanIsKept) {
    ClusterRig rig("reuse", 63);
    rig.startServer("srv-a");
    ASSERT_TRUE(rig.waitForServers(1, 30s));
    rig.startAgent("reused", 30, "max");
    ASSERT_EQ(rig.agent("reused").wait(120s), 0) << readText(rig.agentLog("reused"));
    const fs::path summary = rig.dataDir("srv-a") / "reused" / "summary.json";
    ASSERT_TRUE(waitUntil([&] { return fs::exists(summary); }, 30s));
    const std::string before = readText(summary);
    // The finished claim is still on the domain.
    expectRefusedAndUntouched(rig, "again", before);
    // Restarted, the server knows the scan from its data dir alone.
    rig.server("srv-a").stop();
    rig.startServer("srv-a");
    ASSERT_TRUE(rig.waitForServers(1, 30s));
    expectRefusedAndUntouched(rig, "after-restart", before);
    EXPECT_NE(readText(rig.serverLog("srv-a").string() + ".2")
                  .find("session reused: refused: the id names a scan that "
                        "finished here"),
              std::string::npos)
        << readText(rig.serverLog("srv-a").string() + ".2");
}

}  // namespace
}  // namespace facescan::testing
