#include "test_agent.hpp"

#include <unistd.h>

#include <atomic>
#include <thread>

#include "synth/head_model.hpp"

namespace facescan::testing {
namespace {

constexpr float kDepthUnitsM = 0.001f;  // OpenNI millimetres, as a Kinect agent sends them

int64_t wallNowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

}  // namespace

EncodedSequence renderSequence(int frames, uint64_t seed, float distance_m) {
    synth::SequenceParams sp;
    sp.frames = frames;
    sp.seed = seed;
    sp.distance_m = distance_m;
    // The default motion (a 10 s left-right turn at 30 Hz): a short test sequence sees its first, frontal part.
    const synth::KinectSimulator sim(synth::defaultHead(), sp);
    EncodedSequence out;
    out.intrinsics = sim.intrinsics();
    out.frames.resize(static_cast<size_t>(frames));
    wire::FrameEncoder encoder;
    recon::RgbdFrame frame;
    cv::Mat raw;
    for (int i = 0; i < frames; ++i) {
        sim.render(i, frame);
        recon::depthMetresToRaw(frame.depth_m, kDepthUnitsM, raw);
        wire::EncodedFrame& f = out.frames[static_cast<size_t>(i)];
        if (!encoder.encode(raw, frame.colour_bgr, f).isOk()) f = {};
        f.seq = static_cast<uint32_t>(i);
        f.source_time_ns = frame.timestamp_ns;
    }
    return out;
}

struct TestAgent::Impl {
    std::string session_id;
    wire::CameraInfoData camera;
    std::optional<wire::Participant> participant;
    std::optional<wire::Topic<facescan_wire_CameraInfo>> camera_topic;
    std::optional<wire::Topic<facescan_wire_RgbdFrame>> frame_topic;
    std::optional<wire::Writer<facescan_wire_CameraInfo>> camera_writer;
    std::optional<wire::Writer<facescan_wire_RgbdFrame>> frame_writer;
};

StatusOr<std::unique_ptr<TestAgent>> TestAgent::create(uint32_t domain, const std::string& session_id,
                                                       const recon::Intrinsics& k, bool every_frame) {
    auto agent = std::unique_ptr<TestAgent>(new TestAgent());
    agent->impl_ = std::make_unique<Impl>();
    Impl& m = *agent->impl_;
    m.session_id = session_id;
    m.camera.session_id = session_id;
    m.camera.intrinsics = k;
    m.camera.depth_units_m = kDepthUnitsM;
    m.camera.every_frame = every_frame;
    m.camera.source = "synthetic:test";
    m.camera.agent_host = "test";
    ASSIGN_OR_RETURN(m.participant, wire::Participant::create({domain, "loopback"}));
    ASSIGN_OR_RETURN(m.camera_topic, wire::Topic<facescan_wire_CameraInfo>::create(*m.participant));
    ASSIGN_OR_RETURN(m.frame_topic, wire::Topic<facescan_wire_RgbdFrame>::create(*m.participant));
    ASSIGN_OR_RETURN(m.camera_writer, wire::Writer<facescan_wire_CameraInfo>::create(*m.camera_topic));
    const wire::Qos qos = wire::frameWriterQos(every_frame);
    ASSIGN_OR_RETURN(m.frame_writer, wire::Writer<facescan_wire_RgbdFrame>::create(*m.frame_topic, &qos,
                                                                                   wire::sessionPartition(session_id)));
    return agent;
}

TestAgent::~TestAgent() = default;

bool TestAgent::waitForServer(std::chrono::milliseconds timeout) {
    return impl_->camera_writer->waitForReaders(1, timeout);
}

bool TestAgent::waitForOwner(std::chrono::milliseconds timeout) {
    return impl_->frame_writer->waitForReaders(1, timeout);
}

Status TestAgent::sendCamera() {
    const facescan_wire_CameraInfo msg = wire::toMessage(impl_->camera);
    return impl_->camera_writer->write(msg);
}

Status TestAgent::sendFrame(uint32_t seq, const wire::EncodedFrame& f) {
    facescan_wire_RgbdFrame msg = wire::toMessage(impl_->session_id, f);
    msg.seq = seq;
    msg.capture_time_ns = wallNowNs();
    // A recording's writer blocks while the server's queue is full and times out after 5 s; like the real agent, try
    // again (a loaded test machine can keep a server busy that long), for up to a minute.
    Status written = impl_->frame_writer->write(msg);
    for (int retry = 0; retry < 12 && written.code() == StatusCode::kDeadlineExceeded; ++retry) {
        written = impl_->frame_writer->write(msg);
    }
    return written;
}

Status TestAgent::sendRawDepth(uint32_t seq, const std::vector<uint8_t>& depth_bytes) {
    wire::EncodedFrame f;
    f.depth = depth_bytes;
    f.source_time_ns = seq;
    return sendFrame(seq, f);
}

Status TestAgent::sendEndOfStream(uint32_t seq) {
    const wire::EncodedFrame empty;
    facescan_wire_RgbdFrame msg = wire::toMessage(impl_->session_id, empty);
    msg.seq = seq;
    msg.capture_time_ns = wallNowNs();
    msg.end_of_stream = true;
    return impl_->frame_writer->write(msg);
}

Status TestAgent::stream(const EncodedSequence& seq, int n, float rate_hz, bool end_of_stream) {
    const auto period =
        rate_hz > 0 ? std::chrono::nanoseconds(static_cast<int64_t>(1e9 / rate_hz)) : std::chrono::nanoseconds(0);
    auto next = std::chrono::steady_clock::now();
    for (int i = 0; i < n; ++i) {
        RETURN_IF_ERROR(sendFrame(static_cast<uint32_t>(i), seq.frames[static_cast<size_t>(i) % seq.frames.size()]));
        next += period;
        std::this_thread::sleep_until(next);
    }
    if (end_of_stream) RETURN_IF_ERROR(sendEndOfStream(static_cast<uint32_t>(n)));
    return impl_->frame_writer->waitForAcks(std::chrono::seconds(30));
}

struct TestClient::Impl {
    std::optional<wire::Participant> participant;
    std::optional<wire::Topic<facescan_wire_ScanCommand>> command_topic;
    std::optional<wire::Topic<facescan_wire_ScanReply>> reply_topic;
    std::optional<wire::Topic<facescan_wire_ScanStatus>> status_topic;
    std::optional<wire::Topic<facescan_wire_MeshSnapshot>> snapshot_topic;
    std::optional<wire::Writer<facescan_wire_ScanCommand>> command_writer;
    std::optional<wire::Reader<facescan_wire_ScanReply>> reply_reader;
    std::optional<wire::Reader<facescan_wire_ScanStatus>> status_reader;
    std::optional<wire::Reader<facescan_wire_MeshSnapshot>> snapshot_reader;
    int counter = 0;
};

StatusOr<std::unique_ptr<TestClient>> TestClient::create(uint32_t domain) {
    auto client = std::unique_ptr<TestClient>(new TestClient());
    client->impl_ = std::make_unique<Impl>();
    Impl& m = *client->impl_;
    ASSIGN_OR_RETURN(m.participant, wire::Participant::create({domain, "loopback"}));
    ASSIGN_OR_RETURN(m.command_topic, wire::Topic<facescan_wire_ScanCommand>::create(*m.participant));
    ASSIGN_OR_RETURN(m.reply_topic, wire::Topic<facescan_wire_ScanReply>::create(*m.participant));
    ASSIGN_OR_RETURN(m.status_topic, wire::Topic<facescan_wire_ScanStatus>::create(*m.participant));
    ASSIGN_OR_RETURN(m.snapshot_topic, wire::Topic<facescan_wire_MeshSnapshot>::create(*m.participant));
    ASSIGN_OR_RETURN(m.command_writer, wire::Writer<facescan_wire_ScanCommand>::create(*m.command_topic));
    ASSIGN_OR_RETURN(m.reply_reader, wire::Reader<facescan_wire_ScanReply>::create(*m.reply_topic));
    ASSIGN_OR_RETURN(m.status_reader, wire::Reader<facescan_wire_ScanStatus>::create(*m.status_topic));
    ASSIGN_OR_RETURN(m.snapshot_reader, wire::Reader<facescan_wire_MeshSnapshot>::create(*m.snapshot_topic));
    return client;
}

TestClient::~TestClient() = default;

bool TestClient::waitForServer(std::chrono::milliseconds timeout) {
    return impl_->command_writer->waitForReaders(1, timeout) && impl_->reply_reader->waitForWriters(1, timeout);
}

StatusOr<ReplyCopy> TestClient::command(const std::string& session_id, uint32_t kind, std::chrono::milliseconds timeout,
                                        const std::string* request_id_override) {
    const std::string request_id = request_id_override
                                       ? *request_id_override
                                       : "test-" + std::to_string(getpid()) + "-" + std::to_string(++impl_->counter);
    const std::string client_id = "server_test";
    facescan_wire_ScanCommand cmd{};
    cmd.session_id = wire::stringView(session_id);
    cmd.request_id = wire::stringView(request_id);
    cmd.client_id = wire::stringView(client_id);
    cmd.kind = static_cast<facescan_wire_CommandKind>(kind);
    RETURN_IF_ERROR(impl_->command_writer->write(cmd));
    std::optional<ReplyCopy> got;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!got && std::chrono::steady_clock::now() < deadline) {
        impl_->reply_reader->waitForData(std::chrono::milliseconds(100));
        auto n = impl_->reply_reader->take([&](const facescan_wire_ScanReply& r, const dds_sample_info_t& info) {
            if (!info.valid_data || got || wire::fromDds(r.request_id) != request_id) return;
            ReplyCopy c;
            c.request_id = wire::fromDds(r.request_id);
            c.server_id = wire::fromDds(r.server_id);
            c.error = wire::fromDds(r.error);
            c.ok = r.ok;
            c.kind = static_cast<uint32_t>(r.kind);
            c.vertex_count = r.vertex_count;
            c.triangle_count = r.triangle_count;
            c.payload.assign(r.payload._buffer, r.payload._buffer + r.payload._length);
            got = std::move(c);
        });
        if (!n.isOk()) return n.status();
    }
    if (!got) return deadlineExceeded("no reply to " + request_id);
    return *got;
}

std::optional<StatusCopy> TestClient::waitForStatus(const std::string& session_id,
                                                    const std::function<bool(const StatusCopy&)>& pred,
                                                    std::chrono::milliseconds timeout) {
    std::optional<StatusCopy> last;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
        impl_->status_reader->waitForData(std::chrono::milliseconds(100));
        bool done = false;
        (void)impl_->status_reader->take([&](const facescan_wire_ScanStatus& s, const dds_sample_info_t& info) {
            if (!info.valid_data || wire::fromDds(s.session_id) != session_id) return;
            StatusCopy c = wire::fromMessage(s);
            last = c;
            if (pred(c)) done = true;
        });
        if (done) return last;
    }
    return std::nullopt;
}

std::optional<SnapshotCopy> TestClient::waitForSnapshot(const std::string& session_id,
                                                        std::chrono::milliseconds timeout) {
    std::optional<SnapshotCopy> got;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!got && std::chrono::steady_clock::now() < deadline) {
        impl_->snapshot_reader->waitForData(std::chrono::milliseconds(100));
        (void)impl_->snapshot_reader->take([&](const facescan_wire_MeshSnapshot& s, const dds_sample_info_t& info) {
            if (!info.valid_data || wire::fromDds(s.session_id) != session_id) return;
            SnapshotCopy c;
            c.seq = s.seq;
            c.frames_integrated = s.frames_integrated;
            c.vertex_count = s.vertex_count;
            c.triangle_count = s.triangle_count;
            c.draco.assign(s.draco._buffer, s.draco._buffer + s.draco._length);
            got = std::move(c);
        });
    }
    return got;
}

}  // namespace facescan::testing
