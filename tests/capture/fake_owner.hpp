// A test that plays a session's owning server for the agent's stream (tests/capture): a claim, a frame reader in
// the session's partition, and the CameraInfo reader, on the test's own participant.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "must.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/messages.hpp"
#include "wire/topics.hpp"

namespace facescan::testing {

using namespace std::chrono_literals;

// The session's owning server as the agent sees it: a claim, and a frame reader in the session's partition.
// `reader_samples` > 0 bounds the reader's keep-all history: a reader that never takes then stops acknowledging
// frames, as a server whose intake is stuck.
// `owner_id` (default "owner-SESSION") claims at `epoch`: a later epoch's claim is the stronger, as a takeover's.
struct FakeOwner {
    FakeOwner(uint32_t domain, const std::string& session, int reader_samples = 0, const std::string& owner_id = "",
              uint32_t epoch = 1) {
        data.session_id = session;
        data.owner_id = owner_id.empty() ? "owner-" + session : owner_id;
        data.epoch = epoch;
        data.state = wire::OwnerState::kReady;
        participant.emplace(must(wire::Participant::create({domain, "loopback"})));
        owner_topic.emplace(must(wire::Topic<facescan_wire_SessionOwner>::create(*participant)));
        frame_topic.emplace(must(wire::Topic<facescan_wire_RgbdFrame>::create(*participant)));
        info_topic.emplace(must(wire::Topic<facescan_wire_CameraInfo>::create(*participant)));
        info_reader.emplace(must(wire::Reader<facescan_wire_CameraInfo>::create(*info_topic)));
        wire::Qos qos = wire::frameReaderQos();
        if (reader_samples > 0)
            dds_qset_resource_limits(qos.get(), reader_samples, DDS_LENGTH_UNLIMITED, reader_samples);
        frame_reader.emplace(
            must(wire::Reader<facescan_wire_RgbdFrame>::create(*frame_topic, &qos, wire::sessionPartition(session))));
        const wire::Qos claim_qos = wire::claimWriterQos(wire::claimStrength(epoch, data.owner_id, session));
        claim_writer.emplace(must(wire::Writer<facescan_wire_SessionOwner>::create(*owner_topic, &claim_qos)));
        claim();
    }
    void claim() { EXPECT_TRUE(claim_writer->write(wire::toMessage(data)).isOk()); }
    // Takes frames until the end of the stream (or the timeout; at most `max_frames`, one per `period`): each
    // one's depth, by seq.
    std::vector<std::pair<uint32_t, cv::Mat>> takeUntilEnd(std::chrono::seconds timeout, size_t max_frames = 0,
                                                           std::chrono::milliseconds period = {}) {
        std::vector<std::pair<uint32_t, cv::Mat>> frames;
        wire::DepthDecoder decoder;
        bool ended = false;
        const auto deadline = std::chrono::steady_clock::now() + timeout;
        while (!camera && std::chrono::steady_clock::now() < deadline) {
            (void)info_reader->take([&](const facescan_wire_CameraInfo& m, const dds_sample_info_t& i) {
                if (auto parsed = wire::fromMessage(m); i.valid_data && parsed.isOk()) camera = *parsed;
            });
            std::this_thread::sleep_for(20ms);
        }
        while (camera && !ended && std::chrono::steady_clock::now() < deadline &&
               (max_frames == 0 || frames.size() < max_frames)) {
            frame_reader->waitForData(200ms);
            std::this_thread::sleep_for(period);
            (void)frame_reader->take(
                [&](const facescan_wire_RgbdFrame& m, const dds_sample_info_t& i) {
                    if (!i.valid_data) return;
                    if (m.end_of_stream) {
                        ended = true;
                        end_seq = m.seq;
                        return;
                    }
                    cv::Mat depth;
                    auto codec = wire::depthCodecFromTag(static_cast<uint32_t>(m.depth_codec));
                    ASSERT_TRUE(codec.isOk());
                    ASSERT_TRUE(decoder
                                    .decode(*codec, m.depth._buffer, m.depth._length, camera->intrinsics.width_px,
                                            camera->intrinsics.height_px, depth)
                                    .isOk());
                    frames.emplace_back(m.seq, depth);
                },
                period.count() > 0 ? 1 : 16);
        }
        EXPECT_TRUE(ended || max_frames > 0) << "no end-of-stream sample";
        return frames;
    }

    // (seq, end of stream) of every frame until the end of the stream came (or the timeout), without waiting for
    // the camera or decoding: for a stream that sends none.
    std::vector<std::pair<uint32_t, bool>> takeSeqsUntilEnd(std::chrono::seconds timeout) {
        std::vector<std::pair<uint32_t, bool>> got;
        const auto deadline = std::chrono::steady_clock::now() + timeout;
        bool ended = false;
        while (!ended && std::chrono::steady_clock::now() < deadline) {
            frame_reader->waitForData(100ms);
            (void)frame_reader->take([&](const facescan_wire_RgbdFrame& m, const dds_sample_info_t& i) {
                if (!i.valid_data) return;
                got.emplace_back(m.seq, m.end_of_stream);
                ended = ended || m.end_of_stream;
            });
        }
        return got;
    }

    wire::SessionOwnerData data;
    std::optional<wire::Participant> participant;
    std::optional<wire::Topic<facescan_wire_SessionOwner>> owner_topic;
    std::optional<wire::Topic<facescan_wire_RgbdFrame>> frame_topic;
    std::optional<wire::Topic<facescan_wire_CameraInfo>> info_topic;
    std::optional<wire::Reader<facescan_wire_CameraInfo>> info_reader;
    std::optional<wire::Reader<facescan_wire_RgbdFrame>> frame_reader;
    std::optional<wire::Writer<facescan_wire_SessionOwner>> claim_writer;
    std::optional<wire::CameraInfoData> camera;
    std::optional<uint32_t> end_seq;  // the end of the stream's seq, once it came
};

}  // namespace facescan::testing
