// Test-only stand-ins for the agent and the client, speaking the real protocol over real DDS (loopback profile,
// a private domain per test): the agent publishes CameraInfo and synthetic Kinect frames through the wire layer;
// the client sends ScanCommands and reads ScanStatus, MeshSnapshot and ScanReply.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "recon/status.hpp"
#include "synth/kinect_simulator.hpp"
#include "test_domain.hpp"
#include "wire/messages.hpp"

namespace facescan::testing {

// Frames of the synthetic Kinect, rendered and encoded once (rendering at 30 Hz would time the renderer).
struct EncodedSequence {
    recon::Intrinsics intrinsics;
    std::vector<wire::EncodedFrame> frames;
};
// distance_m: camera to the head at rest (0.4 m: the head fills the frame, the slowest frames the loop sees).
EncodedSequence renderSequence(int frames, uint64_t seed = 1, float distance_m = 0.7f);

class TestAgent {
 public:
    static StatusOr<std::unique_ptr<TestAgent>> create(uint32_t domain, const std::string& session_id,
                                                       const recon::Intrinsics& k, bool every_frame);
    ~TestAgent();
    // Waits for a server's CameraInfo reader to match.
    bool waitForServer(std::chrono::milliseconds timeout);
    // After sendCamera: waits until a server owns the session (its frame reader, in the session's partition,
    // matched: frames written before that would reach nobody).
    bool waitForOwner(std::chrono::milliseconds timeout);
    Status sendCamera();
    // Sends frame `f` as sequence number `seq`, stamped with the current wall clock (latency).
    Status sendFrame(uint32_t seq, const wire::EncodedFrame& f);
    // Sends a frame whose depth payload is `depth_bytes` (e.g. garbage).
    Status sendRawDepth(uint32_t seq, const std::vector<uint8_t>& depth_bytes);
    Status sendEndOfStream(uint32_t seq);
    // Sends frames [0, n) paced at rate_hz (0 = as fast as the writer allows), then end of stream if asked.
    Status stream(const EncodedSequence& seq, int n, float rate_hz, bool end_of_stream);

 private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

struct ReplyCopy {
    std::string request_id, server_id, error;
    bool ok = false;
    uint32_t kind = 0, vertex_count = 0, triangle_count = 0;
    std::vector<uint8_t> payload;
};
using StatusCopy = wire::ScanStatusData;
struct SnapshotCopy {
    uint32_t seq = 0, frames_integrated = 0, vertex_count = 0, triangle_count = 0;
    std::vector<uint8_t> draco;
};

class TestClient {
 public:
    static StatusOr<std::unique_ptr<TestClient>> create(uint32_t domain);
    ~TestClient();
    bool waitForServer(std::chrono::milliseconds timeout);
    // Sends a command with a fresh request id (or the given one) and returns the first reply carrying it.
    StatusOr<ReplyCopy> command(const std::string& session_id, uint32_t kind,
                                std::chrono::milliseconds timeout = std::chrono::seconds(20),
                                const std::string* request_id_override = nullptr);
    // Polls ScanStatus of `session_id` until pred holds; returns the last status seen (or nullopt).
    std::optional<StatusCopy> waitForStatus(const std::string& session_id,
                                            const std::function<bool(const StatusCopy&)>& pred,
                                            std::chrono::milliseconds timeout);
    std::optional<SnapshotCopy> waitForSnapshot(const std::string& session_id, std::chrono::milliseconds timeout);

 private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace facescan::testing
