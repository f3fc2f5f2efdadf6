// What the ServerSession tests share (server_test.cpp, server_load_test.cpp): a server's parameters for a test, the
// synthetic sequence its agents send, an agent that has a server take its session, and when a status has settled.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "scratch_dir.hpp"
#include "service/server.hpp"
#include "test_agent.hpp"

namespace facescan::service {

// Removed once the test passed (scratch_dir.hpp).
inline std::filesystem::path tempDataDir(const std::string& name) {
    return testing::scratchDir("facescan-server-data-" + name);
}

inline ServerParams testParams(uint32_t domain, const std::string& name) {
    ServerParams p;
    p.domain = {domain, "loopback"};
    p.data_dir = tempDataDir(name);
    p.server_id = "test-server";
    p.snapshot_hz = 2.0f;
    p.join_settle_s = 0.3f;  // loopback discovery takes milliseconds; a lone server has nobody to wait for
    return p;
}

inline const testing::EncodedSequence& sequence() {
    static const testing::EncodedSequence seq = testing::renderSequence(45);
    return seq;
}

inline std::unique_ptr<testing::TestAgent> makeAgent(uint32_t domain, const std::string& session, bool every_frame,
                                                     bool expect_owner = true) {
    using namespace std::chrono_literals;
    auto agent = testing::TestAgent::create(domain, session, sequence().intrinsics, every_frame);
    EXPECT_TRUE(agent.isOk()) << agent.status().toString();
    if (!agent.isOk()) return nullptr;
    EXPECT_TRUE((*agent)->waitForServer(10s));
    EXPECT_TRUE((*agent)->sendCamera().isOk());
    if (expect_owner) {
        EXPECT_TRUE((*agent)->waitForOwner(10s)) << "no server took session " << session;
    }
    return std::move(agent).value();
}

inline bool settled(const testing::StatusCopy& s) {
    return s.frames_received > 0 &&
           s.frames_integrated + s.frames_tracked_only + s.frames_rejected + s.frames_skipped + s.frames_dropped >=
               s.frames_received;
}

}  // namespace facescan::service
