// A server in this test process and a test client that sees it: the set-up the server tests share.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <memory>

#include "service/server.hpp"
#include "test_agent.hpp"

namespace facescan::service {

struct Rig {
    std::unique_ptr<Server> server;
    std::unique_ptr<testing::TestClient> client;
};

inline Rig makeRig(const ServerParams& params) {
    Rig rig;
    auto server = Server::create(params);
    EXPECT_TRUE(server.isOk()) << server.status().toString();
    if (server.isOk()) rig.server = std::move(server).value();
    auto client = testing::TestClient::create(params.domain.domain_id);
    EXPECT_TRUE(client.isOk()) << client.status().toString();
    if (client.isOk()) rig.client = std::move(client).value();
    if (rig.client) {
        EXPECT_TRUE(rig.client->waitForServer(std::chrono::seconds(10)));
    }
    return rig;
}

}  // namespace facescan::service
