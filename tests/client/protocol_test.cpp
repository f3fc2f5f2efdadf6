// The client half of the scan protocol (notes/protocol.md) against peers that speak the server half over real
// Cyclone DDS (loopback profile, private domain): every server answers every command, the owner with ok and the
// others with "unknown session"; the client must take the ok even when an error came first, report an error
// only after the grace period, and report "no server" only after its timeout.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <thread>

#include "client/scan_client.hpp"
#include "test_domain.hpp"

namespace facescan::client {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

uint32_t privateDomain(uint32_t salt) { return facescan::testing::privateDomain(salt); }

// One server's side of the command protocol: owns `owned_session`; answers after `delay`. Like a real server it
// publishes ScanStatus from its start (ScanClient::waitForServer looks for that writer).
class ProtocolPeer {
 public:
    ProtocolPeer(uint32_t domain, std::string server_id, std::string owned_session, std::chrono::milliseconds delay)
        : server_id_(std::move(server_id)), owned_(std::move(owned_session)), delay_(delay) {
        auto participant = wire::Participant::create({domain, "loopback"});
        EXPECT_TRUE(participant.isOk()) << participant.status().toString();
        participant_ = std::move(participant).value();
        command_topic_ = std::move(wire::Topic<facescan_wire_ScanCommand>::create(participant_)).value();
        reply_topic_ = std::move(wire::Topic<facescan_wire_ScanReply>::create(participant_)).value();
        reader_ = std::move(wire::Reader<facescan_wire_ScanCommand>::create(command_topic_)).value();
        writer_ = std::move(wire::Writer<facescan_wire_ScanReply>::create(reply_topic_)).value();
        status_topic_ = std::move(wire::Topic<facescan_wire_ScanStatus>::create(participant_)).value();
        status_writer_ = std::move(wire::Writer<facescan_wire_ScanStatus>::create(status_topic_)).value();
        thread_ = std::thread([this] { serve(); });
    }
    ~ProtocolPeer() {
        stop_ = true;
        thread_.join();
    }
    int commandsSeen() const { return commands_seen_; }

 private:
    void serve() {
        while (!stop_) {
            reader_.waitForData(50ms);
            std::vector<std::pair<std::string, std::string>> pending;  // session, request id
            (void)reader_.take([&](const facescan_wire_ScanCommand& c, const dds_sample_info_t& info) {
                if (info.valid_data) pending.emplace_back(wire::fromDds(c.session_id), wire::fromDds(c.request_id));
            });
            for (const auto& [session, request_id] : pending) {
                ++commands_seen_;
                std::this_thread::sleep_for(delay_);
                const bool owns = session == owned_;
                const std::string error = owns ? "" : "unknown session '" + session + "'";
                const std::vector<uint8_t> payload = {'o', 'k'};
                facescan_wire_ScanReply reply{};
                reply.session_id = wire::stringView(session);
                reply.request_id = wire::stringView(request_id);
                reply.server_id = wire::stringView(server_id_);
                reply.kind = facescan_wire_CMD_GET_TRAJECTORY;
                reply.ok = owns;
                reply.error = wire::stringView(error);
                reply.payload = wire::octetView(payload.data(), owns ? payload.size() : 0);
                EXPECT_TRUE(writer_.write(reply).isOk());
            }
        }
    }

    std::string server_id_, owned_;
    std::chrono::milliseconds delay_;
    wire::Participant participant_;
    wire::Topic<facescan_wire_ScanCommand> command_topic_;
    wire::Topic<facescan_wire_ScanReply> reply_topic_;
    wire::Reader<facescan_wire_ScanCommand> reader_;
    wire::Writer<facescan_wire_ScanReply> writer_;
    wire::Topic<facescan_wire_ScanStatus> status_topic_;
    wire::Writer<facescan_wire_ScanStatus> status_writer_;
    std::atomic<bool> stop_{false};
    std::atomic<int> commands_seen_{0};
    std::thread thread_;
};

std::unique_ptr<ScanClient> makeClient(uint32_t domain, std::chrono::milliseconds timeout) {
    ClientConfig config;
    config.domain = {domain, "loopback"};
    config.timeout = timeout;
    auto client = ScanClient::connect(config);
    EXPECT_TRUE(client.isOk()) << client.status().toString();
    return client.isOk() ? std::move(client).value() : nullptr;
}

TEST(ClientProtocol, OkFromTheOwnerWinsOverAnEarlierErrorFromAnotherServer) {
    const uint32_t domain = privateDomain(1);
    ProtocolPeer other(domain, "other", "not-this-one", 0ms);
    ProtocolPeer owner(domain, "owner", "scan-1", 200ms);  // answers after the other one
    auto client = makeClient(domain, 10s);
    ASSERT_TRUE(client);
    auto reply = client->request("scan-1", facescan_wire_CMD_GET_TRAJECTORY);
    ASSERT_TRUE(reply.isOk()) << reply.status().toString();
    EXPECT_TRUE(reply->ok);
    EXPECT_EQ(reply->server_id, "owner");
    EXPECT_EQ(reply->payload, (std::vector<uint8_t>{'o', 'k'}));
    EXPECT_EQ(other.commandsSeen(), 1);
}

TEST(ClientProtocol, UnknownSessionIsNotFoundAfterTheGracePeriodNotTheTimeout) {
    const uint32_t domain = privateDomain(2);
    ProtocolPeer peer(domain, "only", "scan-1", 0ms);
    auto client = makeClient(domain, 10s);
    ASSERT_TRUE(client);
    ASSERT_TRUE(client->waitForServer().isOk());
    const auto start = Clock::now();
    auto reply = client->request("nobody", facescan_wire_CMD_GET_MESH);
    const auto took = Clock::now() - start;
    ASSERT_FALSE(reply.isOk());
    EXPECT_EQ(reply.status().code(), StatusCode::kNotFound);
    EXPECT_EQ(reply.status().message(), "unknown session 'nobody'");
    EXPECT_GE(took, 450ms);  // the grace: another server might still own it
    EXPECT_LT(took, 3s);
}

// A client that only reads (the viewer's live feed): no command endpoints, so a server sees no command from it,
// and a command is refused at once instead of waiting for a server.
TEST(ClientProtocol, AReadOnlyClientSendsNoCommands) {
    const uint32_t domain = privateDomain(5);
    ProtocolPeer peer(domain, "only", "scan-1", 0ms);
    ClientConfig config;
    config.domain = {domain, "loopback"};
    config.commands = false;
    auto client = ScanClient::connect(config);
    ASSERT_TRUE(client.isOk()) << client.status().toString();
    const auto start = Clock::now();
    auto reply = (*client)->request("scan-1", facescan_wire_CMD_RESET);
    EXPECT_LT(Clock::now() - start, 100ms);
    ASSERT_FALSE(reply.isOk());
    EXPECT_EQ(reply.status().code(), StatusCode::kUnavailable);
    EXPECT_NE(reply.status().message().find("only reads"), std::string::npos) << reply.status().message();
    std::map<std::string, SessionStatus> statuses;
    std::vector<MeshSnapshotData> snapshots;
    EXPECT_TRUE((*client)->poll(10ms, statuses, kAllSessions, &snapshots).isOk());
    std::this_thread::sleep_for(300ms);
    EXPECT_EQ(peer.commandsSeen(), 0);
}

TEST(ClientProtocol, NoServerIsDeadlineExceededWithTheDomainAndProfile) {
    const uint32_t domain = privateDomain(3);
    auto client = makeClient(domain, 700ms);
    ASSERT_TRUE(client);
    const auto start = Clock::now();
    auto reply = client->request("scan-1", facescan_wire_CMD_GET_STATUS);
    const auto took = Clock::now() - start;
    ASSERT_FALSE(reply.isOk());
    EXPECT_EQ(reply.status().code(), StatusCode::kDeadlineExceeded);
    EXPECT_EQ(reply.status().message(), noServerMessage({domain, "loopback"}));
    EXPECT_NE(reply.status().message().find("domain " + std::to_string(domain) + " (profile loopback)"),
              std::string::npos);
    EXPECT_GE(took, 650ms);
    EXPECT_LT(took, 3s);
}

TEST(ClientProtocol, SessionsListsEveryLiveScanStatus) {
    const uint32_t domain = privateDomain(4);
    ProtocolPeer peer(domain, "srv", "b", 0ms);  // a server: answers commands
    auto participant = wire::Participant::create({domain, "loopback"});
    ASSERT_TRUE(participant.isOk());
    auto topic = wire::Topic<facescan_wire_ScanStatus>::create(*participant);
    ASSERT_TRUE(topic.isOk());
    auto writer = wire::Writer<facescan_wire_ScanStatus>::create(*topic);
    ASSERT_TRUE(writer.isOk());
    const std::string empty, server = "srv";
    for (const std::string id : {"b", "a"}) {
        facescan_wire_ScanStatus s{};
        s.session_id = wire::stringView(id);
        s.server_id = wire::stringView(server);
        s.detail = wire::stringView(empty);
        s.state = id == "a" ? facescan_wire_STATE_FINISHED : facescan_wire_STATE_SCANNING;
        s.frames_integrated = id == "a" ? 300 : 42;
        ASSERT_TRUE(writer->write(s).isOk());
    }
    auto client = makeClient(domain, 10s);  // a late joiner: durability must deliver both
    ASSERT_TRUE(client);
    auto sessions = client->sessions(1000ms);
    ASSERT_TRUE(sessions.isOk()) << sessions.status().toString();
    ASSERT_EQ(sessions->size(), 2u);
    EXPECT_EQ((*sessions)[0].session_id, "a");
    EXPECT_EQ((*sessions)[0].state, facescan_wire_STATE_FINISHED);
    EXPECT_EQ((*sessions)[0].frames_integrated, 300u);
    EXPECT_EQ((*sessions)[1].session_id, "b");
    EXPECT_EQ((*sessions)[1].frames_integrated, 42u);
}

}  // namespace
}  // namespace facescan::client
