// Real Cyclone DDS on the loopback profile, no mocks: a second process publishes frames, this one receives them.
// Each test uses its own domain id (derived from the pid) so parallel ctest runs never see each other.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <vector>

#include "test_domain.hpp"
#include "wire/messages.hpp"
#include "wire/topics.hpp"

namespace facescan::wire {
namespace {

using namespace std::chrono_literals;

using facescan::testing::privateDomain;

// Deterministic payload for frame `seq`, so the receiver can check every byte.
std::vector<uint8_t> payloadFor(uint32_t seq, size_t size) {
    std::vector<uint8_t> bytes(size);
    uint32_t x = seq * 2654435761u + 12345u;
    for (auto& b : bytes) {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        b = static_cast<uint8_t>(x);
    }
    return bytes;
}

constexpr size_t kFrameBytes = 300 * 1024;  // a realistic compressed RGB-D frame
const std::string kSession = "test-session";

// Child process: publishes `count` frames as a recording (every frame must arrive), then exits.
[[noreturn]] void publishFrames(uint32_t domain, uint32_t count, bool exit_abruptly) {
    auto participant = Participant::create({domain, "loopback"});
    if (!participant) _exit(10);
    auto topic = Topic<facescan_wire_RgbdFrame>::create(*participant);
    if (!topic) _exit(11);
    const Qos qos = frameWriterQos(/*every_frame=*/true);
    auto writer = Writer<facescan_wire_RgbdFrame>::create(*topic, &qos);
    if (!writer) _exit(12);
    if (!writer->waitForReaders(1, 20s)) _exit(13);
    for (uint32_t seq = 0; seq < count; ++seq) {
        const std::vector<uint8_t> depth = payloadFor(seq, kFrameBytes);
        facescan_wire_RgbdFrame sample{};
        sample.session_id = stringView(kSession);
        sample.seq = seq;
        sample.capture_time_ns = seq;
        sample.depth_codec = facescan_wire_DEPTH_RVL;
        sample.depth = octetView(depth.data(), depth.size());
        sample.colour_codec = facescan_wire_COLOUR_NONE;
        if (!writer->write(sample).isOk()) _exit(14);
    }
    if (exit_abruptly) raise(SIGKILL);  // a killed agent: no clean shutdown
    if (!writer->waitForAcks(20s).isOk()) _exit(15);
    _exit(0);
}

TEST(DdsTransport, RecordingFramesArriveIntactAndInOrderAcrossProcesses) {
    const uint32_t domain = privateDomain(1);
    constexpr uint32_t kCount = 60;
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) publishFrames(domain, kCount, false);

    auto participant = Participant::create({domain, "loopback"});
    ASSERT_TRUE(participant.isOk()) << participant.status().toString();
    auto topic = Topic<facescan_wire_RgbdFrame>::create(*participant);
    ASSERT_TRUE(topic.isOk()) << topic.status().toString();
    const Qos qos = frameReaderQos();
    auto reader = Reader<facescan_wire_RgbdFrame>::create(*topic, &qos);
    ASSERT_TRUE(reader.isOk()) << reader.status().toString();

    std::vector<uint32_t> received;
    size_t corrupt = 0;
    const auto deadline = std::chrono::steady_clock::now() + 30s;
    while (received.size() < kCount && std::chrono::steady_clock::now() < deadline) {
        reader->waitForData(200ms);
        auto n = reader->take([&](const facescan_wire_RgbdFrame& s, const dds_sample_info_t& info) {
            if (!info.valid_data) return;
            received.push_back(s.seq);
            const std::vector<uint8_t> expected = payloadFor(s.seq, kFrameBytes);
            if (s.depth._length != expected.size() || std::memcmp(s.depth._buffer, expected.data(), expected.size()) ||
                fromDds(s.session_id) != kSession) {
                ++corrupt;
            }
        });
        ASSERT_TRUE(n.isOk()) << n.status().toString();
    }
    int wstatus = 0;
    waitpid(child, &wstatus, 0);
    EXPECT_TRUE(WIFEXITED(wstatus) && WEXITSTATUS(wstatus) == 0) << "publisher exit status " << wstatus;
    ASSERT_EQ(received.size(), kCount);
    EXPECT_EQ(corrupt, 0u);
    for (uint32_t i = 0; i < kCount; ++i) EXPECT_EQ(received[i], i) << "out of order at " << i;
}

TEST(DdsTransport, KilledPublisherIsSeenAsGone) {
    const uint32_t domain = privateDomain(2);
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) publishFrames(domain, 3, /*exit_abruptly=*/true);

    auto participant = Participant::create({domain, "loopback"});
    ASSERT_TRUE(participant.isOk()) << participant.status().toString();
    auto topic = Topic<facescan_wire_RgbdFrame>::create(*participant);
    ASSERT_TRUE(topic.isOk());
    const Qos qos = frameReaderQos();
    auto reader = Reader<facescan_wire_RgbdFrame>::create(*topic, &qos);
    ASSERT_TRUE(reader.isOk());

    int frames = 0;
    bool gone = false;
    const auto deadline = std::chrono::steady_clock::now() + 20s;  // lease is 3 s in the loopback profile
    while (!gone && std::chrono::steady_clock::now() < deadline) {
        reader->waitForData(200ms);
        auto n = reader->take([&](const facescan_wire_RgbdFrame&, const dds_sample_info_t& info) {
            if (info.valid_data) ++frames;
            if (info.instance_state != DDS_IST_ALIVE) gone = true;
        });
        ASSERT_TRUE(n.isOk());
    }
    waitpid(child, nullptr, 0);
    EXPECT_GT(frames, 0);
    EXPECT_TRUE(gone) << "the killed writer's session never became not-alive";
}

TEST(DdsTransport, LateJoinerGetsDurableCameraInfo) {
    const uint32_t domain = privateDomain(3);
    auto participant = Participant::create({domain, "loopback"});
    ASSERT_TRUE(participant.isOk()) << participant.status().toString();
    auto topic = Topic<facescan_wire_CameraInfo>::create(*participant);
    ASSERT_TRUE(topic.isOk());
    auto writer = Writer<facescan_wire_CameraInfo>::create(*topic);
    ASSERT_TRUE(writer.isOk());
    facescan_wire_CameraInfo info{};
    info.session_id = stringView(kSession);
    info.width = 640;
    info.height = 480;
    info.fx = 575.8f;
    const std::string empty;
    info.source = stringView(empty);
    info.agent_host = stringView(empty);
    ASSERT_TRUE(writer->write(info).isOk());

    // The reader is created after the sample was written: transient-local durability must still deliver it.
    auto reader = Reader<facescan_wire_CameraInfo>::create(*topic);
    ASSERT_TRUE(reader.isOk());
    int got = 0;
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    while (got == 0 && std::chrono::steady_clock::now() < deadline) {
        reader->waitForData(200ms);
        (void)reader->take([&](const facescan_wire_CameraInfo& s, const dds_sample_info_t& i) {
            if (i.valid_data && s.width == 640 && fromDds(s.session_id) == kSession) ++got;
        });
    }
    EXPECT_EQ(got, 1);
}

TEST(DdsProfiles, LoadsNamedProfilesAndRejectsUnknownOnes) {
    EXPECT_TRUE(loadProfileXml("loopback").isOk());
    EXPECT_TRUE(loadProfileXml("lan").isOk());
    auto bad = loadProfileXml("wifi");
    ASSERT_FALSE(bad.isOk());
    EXPECT_NE(bad.status().message().find("loopback, lan"), std::string::npos);
    EXPECT_EQ(loadProfileXml("/nonexistent/profile.xml").status().code(), StatusCode::kNotFound);
    EXPECT_FALSE(DomainConfig({300, "loopback"}).validate().isOk());
}

TEST(DdsProfiles, SocketBufferCheckNamesTheSysctlToRaise) {
    // A profile asking for more than any kernel allows by default: the check must say what to change.
    const std::string xml = R"(<Internal><SocketReceiveBufferSize min="64GiB" max="64GiB"/></Internal>)";
    const Status s = checkSocketBuffers(xml);
    ASSERT_FALSE(s.isOk());
    EXPECT_NE(s.message().find("sysctl -w net.core.rmem_max="), std::string::npos) << s.message();
    EXPECT_TRUE(checkSocketBuffers(R"(<SocketReceiveBufferSize min="default"/>)").isOk());
    auto loopback = loadProfileXml("loopback");
    ASSERT_TRUE(loopback.isOk());
    EXPECT_TRUE(checkSocketBuffers(*loopback).isOk()) << "this machine cannot run the loopback profile";
}

TEST(WireMessages, ScanStatusRoundTripsAndAnUnknownStateReadsAsWaiting) {
    ScanStatusData d;
    d.session_id = "s-1";
    d.server_id = "box";
    d.state = facescan_wire_STATE_LOST;
    d.detail = "tracking lost";
    d.frames_received = 7;
    d.frames_integrated = 5;
    d.frames_rejected = 1;
    d.frames_skipped = 2;
    d.frames_dropped = 3;
    d.every_frame = true;
    d.fps = 29.5f;
    d.ms_detect = 1, d.ms_segment = 2, d.ms_filter = 3, d.ms_icp = 4, d.ms_integrate = 5, d.ms_raycast = 6;
    d.ms_mesh = 7;
    d.latency_p95_ms = 23.5f;
    d.snapshot_seq = 9;
    d.updated_ns = 123456789012345;
    d.behind = true;
    d.frames_tracked_only = 11;
    const ScanStatusData back = fromMessage(toMessage(d));
    EXPECT_EQ(back.session_id, "s-1");
    EXPECT_EQ(back.server_id, "box");
    EXPECT_EQ(back.state, facescan_wire_STATE_LOST);
    EXPECT_EQ(back.detail, "tracking lost");
    EXPECT_EQ(back.frames_received + back.frames_integrated + back.frames_rejected + back.frames_skipped +
                  back.frames_dropped,
              18u);
    EXPECT_EQ(back.frames_dropped, 3u);
    EXPECT_TRUE(back.every_frame);
    EXPECT_FLOAT_EQ(back.fps, 29.5f);
    EXPECT_FLOAT_EQ(back.ms_detect + back.ms_segment + back.ms_filter + back.ms_icp + back.ms_integrate +
                        back.ms_raycast + back.ms_mesh,
                    28.0f);
    EXPECT_FLOAT_EQ(back.latency_p95_ms, 23.5f);
    EXPECT_EQ(back.snapshot_seq, 9u);
    EXPECT_EQ(back.updated_ns, 123456789012345);
    EXPECT_TRUE(back.behind);
    EXPECT_EQ(back.frames_tracked_only, 11u);

    facescan_wire_ScanStatus m = toMessage(d);
    m.state = static_cast<facescan_wire_ScanState>(99);  // a state from a newer server
    m.detail = nullptr;                                  // a missing string reads as empty
    const ScanStatusData odd = fromMessage(m);
    EXPECT_EQ(odd.state, facescan_wire_STATE_WAITING);
    EXPECT_TRUE(odd.detail.empty());
}

}  // namespace
}  // namespace facescan::wire
