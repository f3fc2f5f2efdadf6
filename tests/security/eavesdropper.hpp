// An unauthenticated participant (no DDS Security) on a test's domain: it reads every facescan topic, and tries
// to disturb a session the way anyone on the LAN could without security: reset and finish commands, frames of its
// own. Built on the wire layer and the server tests' stand-in agent and client (tests/server/test_agent.hpp).
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "test_agent.hpp"
#include "wire/topics.hpp"

namespace facescan::testing {

struct Heard {
    int camera_infos = 0, frames = 0, statuses = 0, snapshots = 0, replies = 0;
    int total() const { return camera_infos + frames + statuses + snapshots + replies; }
    std::string text() const {
        return "heard " + std::to_string(camera_infos) + " camera infos, " + std::to_string(frames) + " frames, " +
               std::to_string(statuses) + " statuses, " + std::to_string(snapshots) + " snapshots, " +
               std::to_string(replies) + " replies";
    }
};

class Eavesdropper {
 public:
    static StatusOr<std::unique_ptr<Eavesdropper>> join(uint32_t domain) {
        std::unique_ptr<Eavesdropper> e(new Eavesdropper());
        ASSIGN_OR_RETURN(e->participant_, wire::Participant::create({domain, "loopback"}));
        ASSIGN_OR_RETURN(e->info_topic_, wire::Topic<facescan_wire_CameraInfo>::create(*e->participant_));
        ASSIGN_OR_RETURN(e->frame_topic_, wire::Topic<facescan_wire_RgbdFrame>::create(*e->participant_));
        ASSIGN_OR_RETURN(e->status_topic_, wire::Topic<facescan_wire_ScanStatus>::create(*e->participant_));
        ASSIGN_OR_RETURN(e->snapshot_topic_, wire::Topic<facescan_wire_MeshSnapshot>::create(*e->participant_));
        ASSIGN_OR_RETURN(e->reply_topic_, wire::Topic<facescan_wire_ScanReply>::create(*e->participant_));
        ASSIGN_OR_RETURN(e->info_reader_, wire::Reader<facescan_wire_CameraInfo>::create(*e->info_topic_));
        ASSIGN_OR_RETURN(e->frame_reader_, wire::Reader<facescan_wire_RgbdFrame>::create(*e->frame_topic_));
        ASSIGN_OR_RETURN(e->status_reader_, wire::Reader<facescan_wire_ScanStatus>::create(*e->status_topic_));
        ASSIGN_OR_RETURN(e->snapshot_reader_, wire::Reader<facescan_wire_MeshSnapshot>::create(*e->snapshot_topic_));
        ASSIGN_OR_RETURN(e->reply_reader_, wire::Reader<facescan_wire_ScanReply>::create(*e->reply_topic_));
        ASSIGN_OR_RETURN(e->client_, TestClient::create(domain));
        return e;
    }

    // Counts what arrives for `window`, or until something of every kind a scan makes (frames, status, meshes)
    // has arrived when `until_all_heard`. With `disturb_session`, every 200 ms it also asks the servers to reset
    // and to finish that session and sends it a frame of garbage.
    Heard listen(std::chrono::milliseconds window, const std::string& disturb_session, bool until_all_heard) {
        Heard heard;
        const auto start = std::chrono::steady_clock::now();
        auto next_disturb = start;
        std::unique_ptr<TestAgent> intruder;
        uint32_t seq = kIntruderSeq;
        while (std::chrono::steady_clock::now() - start < window) {
            if (!disturb_session.empty() && std::chrono::steady_clock::now() >= next_disturb) {
                if (!intruder) {
                    auto made = TestAgent::create(participant_->domainId(), disturb_session,
                                                  recon::Intrinsics{640, 480, 575.8f, 575.8f, 319.5f, 239.5f}, false);
                    if (made.isOk()) intruder = std::move(made).value();
                }
                if (intruder) (void)intruder->sendRawDepth(seq++, std::vector<uint8_t>(4096, 0x5a));
                for (const auto kind : {facescan_wire_CMD_RESET, facescan_wire_CMD_FINISH}) {
                    (void)client_->command(disturb_session, static_cast<uint32_t>(kind), std::chrono::milliseconds(1));
                }
                next_disturb += std::chrono::milliseconds(200);
            }
            heard.camera_infos += count(*info_reader_);
            // Not its own frames (delivered in-process to its own reader): theirs are numbered from kIntruderSeq.
            heard.frames += count(
                *frame_reader_, +[](const facescan_wire_RgbdFrame& f) { return f.seq < kIntruderSeq; });
            heard.statuses += count(*status_reader_);
            heard.snapshots += count(*snapshot_reader_);
            heard.replies += count(*reply_reader_);
            if (until_all_heard && heard.frames > 0 && heard.statuses > 0 && heard.snapshots > 0) break;
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return heard;
    }

    // Whether a server answers this participant's GET_STATUS of `session` within `timeout`.
    bool answered(const std::string& session, std::chrono::milliseconds timeout) {
        return client_->command(session, facescan_wire_CMD_GET_STATUS, timeout).isOk();
    }

 private:
    Eavesdropper() = default;

    static constexpr uint32_t kIntruderSeq = 1'000'000;

    // Samples with data taken from `reader` (that `keep` accepts).
    template <typename T>
    static int count(wire::Reader<T>& reader, bool (*keep)(const T&) = nullptr) {
        int n = 0;
        (void)reader.take(
            [&](const T& sample, const dds_sample_info_t& info) { n += info.valid_data && (!keep || keep(sample)); },
            64);
        return n;
    }

    std::optional<wire::Participant> participant_;
    std::optional<wire::Topic<facescan_wire_CameraInfo>> info_topic_;
    std::optional<wire::Topic<facescan_wire_RgbdFrame>> frame_topic_;
    std::optional<wire::Topic<facescan_wire_ScanStatus>> status_topic_;
    std::optional<wire::Topic<facescan_wire_MeshSnapshot>> snapshot_topic_;
    std::optional<wire::Topic<facescan_wire_ScanReply>> reply_topic_;
    std::optional<wire::Reader<facescan_wire_CameraInfo>> info_reader_;
    std::optional<wire::Reader<facescan_wire_RgbdFrame>> frame_reader_;
    std::optional<wire::Reader<facescan_wire_ScanStatus>> status_reader_;
    std::optional<wire::Reader<facescan_wire_MeshSnapshot>> snapshot_reader_;
    std::optional<wire::Reader<facescan_wire_ScanReply>> reply_reader_;
    std::unique_ptr<TestClient> client_;
};

}  // namespace facescan::testing
