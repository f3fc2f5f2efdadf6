// The agent's SessionStream in this process against owners played by the test (claims and frame readers on a private
// loopback domain): what the owner receives when a takeover cuts a recording frame's write short.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <optional>
#include <thread>
#include <vector>

#include "capture/owner_link.hpp"
#include "fake_owner.hpp"
#include "must.hpp"
#include "test_domain.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/messages.hpp"
#include "wire/topics.hpp"

namespace facescan::capture {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

using facescan::testing::FakeOwner;
using facescan::testing::must;

// Incompressible bytes: the writer's history fills after a few frames that nobody acknowledges.
wire::EncodedFrame recordingFrame(uint32_t seq) {
    wire::EncodedFrame f;
    f.seq = seq;
    f.depth.resize(256 * 1024);
    uint32_t x = 2463534242u + seq;
    for (uint8_t& b : f.depth) {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        b = static_cast<uint8_t>(x);
    }
    return f;
}

// The owner stops taking frames, and a new owner takes the session over while the agent's write of its last frame
// waits: that frame stays kept, unwritten. The end of the stream must come after it. Numbered after the frames
// written alone, the end had that frame's number, and every later owner dropped it as a duplicate: the recording
// was never finished.
TEST(SessionStream, AnEndAfterAFrameWhoseWriteATakeoverCutShortComesAfterThatFrame) {
    const uint32_t domain = facescan::testing::privateDomain(11);
    const std::string session = "endseq-" + std::to_string(getpid());
    auto participant = must(wire::Participant::create({domain, "loopback"}));
    auto frame_topic = must(wire::Topic<facescan_wire_RgbdFrame>::create(participant));
    wire::Qos qos = wire::frameWriterQos(/*every_frame=*/true);
    dds_qset_reliability(qos.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(kFrameWriteBlocking.count()));
    auto writer =
        must(wire::Writer<facescan_wire_RgbdFrame>::create(frame_topic, &qos, wire::sessionPartition(session)));
    SessionStream stream(must(OwnerLink::create(participant, session)), writer, session, /*every_frame=*/true,
                         /*keep_frames=*/256, /*stalled_after_s=*/60, "the test's domain", [](const std::string&) {});

    std::optional<FakeOwner> stuck(std::in_place, domain, session, /*reader_samples=*/1, "srv-stuck", 1);
    stuck->claim();
    const std::atomic<bool> stop{false};
    ASSERT_TRUE(stream.waitUntilServed(stop, 30).isOk());
    // The stuck owner's reader fills, then the writer's history: one write waits. The new owner claims then, with
    // a reader made at that moment, as a server's is when it takes a session over.
    std::optional<FakeOwner> next;
    const auto now_ns = [] {
        return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
    };
    std::atomic<int64_t> waiting_since_ns{0};
    std::atomic<bool> claimed{false};
    std::thread takeover([&] {
        const auto deadline = Clock::now() + 60s;
        while (Clock::now() < deadline) {
            const int64_t since = waiting_since_ns.load();
            if (since != 0 && now_ns() - since > 1'000'000'000) {
                claimed = true;  // before the claim: the send it cuts short is the last one
                next.emplace(domain, session, /*reader_samples=*/0, "srv-next", 2);
                next->claim();
                return;
            }
            std::this_thread::sleep_for(20ms);
        }
    });
    uint32_t last = 0;
    for (uint32_t seq = 0; seq < 200 && !claimed; ++seq) {
        waiting_since_ns = now_ns();
        ASSERT_TRUE(stream.send(recordingFrame(seq), /*end_of_stream=*/false, stop, 60).isOk());
        waiting_since_ns = 0;
        last = seq;
    }
    takeover.join();
    ASSERT_TRUE(claimed) << "no frame write waited on the stuck owner";
    stuck.reset();  // the old owner gives the session up: its reader goes
    const uint32_t end_seq = stream.nextSeq();
    EXPECT_EQ(end_seq, last + 1) << "the end of the stream must follow the last frame, " << last;
    wire::EncodedFrame end;
    end.seq = end_seq;
    std::thread finish([&] { EXPECT_TRUE(stream.send(end, /*end_of_stream=*/true, stop, 60).isOk()); });
    const auto got = next->takeSeqsUntilEnd(60s);
    finish.join();
    // The new owner gets every frame from the first (nothing confirmed), the one cut short included, then the end.
    ASSERT_FALSE(got.empty());
    ASSERT_TRUE(got.back().second) << "no end of the stream";
    ASSERT_EQ(got.size(), last + 2u);
    for (uint32_t i = 0; i <= last; ++i) EXPECT_EQ(got[i], std::make_pair(i, false));
    EXPECT_EQ(got.back().first, last + 1);
}

}  // namespace
}  // namespace facescan::capture
