#include "capture/agent.hpp"

#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <ctime>
#include <mutex>
#include <optional>
#include <random>
#include <thread>
#include <vector>

#include "wire/dds_options.hpp"
#include "wire/messages.hpp"

namespace facescan::capture {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

int64_t wallClockNs() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string hostName() {
    char name[256] = {};
    if (gethostname(name, sizeof(name) - 1) != 0) return "host";
    return name;
}

// A fixed-capacity FIFO of slot indices (no allocation after construction).
class SlotRing {
 public:
    explicit SlotRing(int capacity) : slots_(static_cast<size_t>(capacity)) {}
    bool empty() const { return count_ == 0; }
    void push(int slot) {
        slots_[(head_ + count_) % slots_.size()] = slot;
        ++count_;
    }
    int pop() {
        const int slot = slots_[head_];
        head_ = (head_ + 1) % slots_.size();
        --count_;
        return slot;
    }

 private:
    std::vector<int> slots_;
    size_t head_ = 0;
    size_t count_ = 0;
};

}  // namespace

Status AgentOptions::validate() const {
    RETURN_IF_ERROR(dds.validate());
    if (!session_id.empty()) RETURN_IF_ERROR(wire::validateSessionId(session_id));
    if (rate == RateMode::kFixed && !(rate_hz > 0 && rate_hz <= 1000)) {
        return invalidArgument("--rate must be real, max or a frequency in (0, 1000] Hz");
    }
    if (jpeg_quality < 1 || jpeg_quality > 100) return invalidArgument("--jpeg-quality must be 1..100");
    // Two at least: a live camera drops the oldest queued frame when all slots are taken.
    if (queue_frames < 2 || queue_frames > 64) return invalidArgument("queue_frames must be 2..64");
    if (wait_for_server_s < 0) return invalidArgument("--wait-for-server must be >= 0 seconds");
    return depth.validate();
}

std::string newSessionId() {
    const std::time_t now = std::time(nullptr);
    std::tm tm{};
    localtime_r(&now, &tm);
    char stamp[32];
    std::strftime(stamp, sizeof(stamp), "%Y%m%d-%H%M%S", &tm);
    std::random_device rd;
    char suffix[8];
    std::snprintf(suffix, sizeof(suffix), "%04x", rd() & 0xffffu);
    std::string host = hostName();
    for (char& c : host) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-';
        if (!ok) c = '-';
    }
    if (host.size() > 32) host.resize(32);
    return host + "-" + stamp + "-" + suffix;
}

struct Agent::Impl {
    wire::Participant participant;
    Clock::time_point joined;  // when the participant was created (discovery time is measured from here)
    wire::Topic<facescan_wire_CameraInfo> info_topic;
    wire::Writer<facescan_wire_CameraInfo> info_writer;
    wire::Topic<facescan_wire_RgbdFrame> frame_topic;
    wire::Writer<facescan_wire_RgbdFrame> frame_writer;

    // Camera thread -> publisher hand-over.
    std::mutex mutex;
    std::condition_variable changed;
    std::vector<CapturedFrame> slots;
    std::optional<SlotRing> free_slots;
    std::optional<SlotRing> ready;
    bool capture_done = false;
    bool publisher_done = false;  // the publisher stopped (error or end): the camera thread must stop too
    Status capture_status;
    AgentStats stats;
};

Agent::Agent(AgentOptions options) : options_(std::move(options)) {}
Agent::~Agent() = default;

StatusOr<std::unique_ptr<Agent>> Agent::create(AgentOptions options) {
    RETURN_IF_ERROR(options.validate());
    std::unique_ptr<Agent> agent(new Agent(std::move(options)));
    agent->session_id_ = agent->options_.session_id.empty() ? newSessionId() : agent->options_.session_id;
    ASSIGN_OR_RETURN(agent->source_, openSource(agent->options_.source, agent->options_.source_options));
    if (agent->options_.preload) {
        ASSIGN_OR_RETURN(agent->source_, preloadSource(std::move(agent->source_), agent->options_.preload_progress));
    }

    auto impl = std::make_unique<Impl>();
    ASSIGN_OR_RETURN(impl->participant, wire::Participant::create(agent->options_.dds));
    impl->joined = Clock::now();
    ASSIGN_OR_RETURN(impl->info_topic, wire::Topic<facescan_wire_CameraInfo>::create(impl->participant));
    ASSIGN_OR_RETURN(impl->info_writer, wire::Writer<facescan_wire_CameraInfo>::create(impl->info_topic));
    ASSIGN_OR_RETURN(impl->frame_topic, wire::Topic<facescan_wire_RgbdFrame>::create(impl->participant));
    const wire::Qos frame_qos = wire::frameWriterQos(agent->everyFrame());
    ASSIGN_OR_RETURN(impl->frame_writer, wire::Writer<facescan_wire_RgbdFrame>::create(impl->frame_topic, &frame_qos));
    const int queue = agent->options_.queue_frames;
    impl->slots.resize(static_cast<size_t>(queue));
    impl->free_slots.emplace(queue);
    impl->ready.emplace(queue);
    for (int i = 0; i < queue; ++i) impl->free_slots->push(i);
    agent->impl_ = std::move(impl);
    return agent;
}

Status Agent::run(const std::atomic<bool>& stop, const std::function<void(const std::string&)>& on_event,
                  const std::function<void(const AgentStats&)>& on_stats) {
    Impl& s = *impl_;
    const SourceInfo& info = source_->info();
    const bool every_frame = everyFrame();

    wire::CameraInfoData camera;
    camera.session_id = session_id_;
    camera.intrinsics = info.intrinsics;
    camera.depth_units_m = info.depth_units_m;
    camera.colour_registered = info.colour_registered;
    camera.rate_hz = info.rate_hz;
    camera.every_frame = every_frame;
    camera.expected_frames = static_cast<uint32_t>(std::max(0, info.expected_frames));
    camera.source = info.description;
    camera.agent_host = hostName();
    RETURN_IF_ERROR(camera.validate());
    RETURN_IF_ERROR(s.info_writer.write(wire::toMessage(camera)));

    // Nothing is read from the source until a server listens, so a recording loses no frame while we wait.
    const std::string where = options_.dds.describe();
    if (!s.frame_writer.waitForReaders(1, 300ms)) {
        on_event("waiting for a facescan-server on " + where + " ...");
        const auto waiting_since = Clock::now();
        const auto deadline = waiting_since + std::chrono::duration<float>(options_.wait_for_server_s);
        bool hinted = false;
        while (!s.frame_writer.waitForReaders(1, 200ms)) {
            if (stop) return Status::ok();
            // Discovery takes a moment; after that, say why no server may answer (a secured domain, most often).
            if (!hinted && Clock::now() - waiting_since > 2s) {
                on_event("no facescan-server answers: " +
                         wire::noPeerHint(options_.dds, s.participant.otherParticipants()));
                hinted = true;
            }
            if (options_.wait_for_server_s > 0 && Clock::now() > deadline) {
                char seconds[32];
                std::snprintf(seconds, sizeof(seconds), "%g", options_.wait_for_server_s);
                return deadlineExceeded("no facescan-server appeared on " + where + " within " + seconds +
                                        " s: start one with the same --profile, --domain and --security; " +
                                        wire::noPeerHint(options_.dds, s.participant.otherParticipants()));
            }
        }
    }
    // Discovery time from joining the domain (with DDS Security: authentication handshakes and key exchange too).
    char found_after[48];
    std::snprintf(found_after, sizeof(found_after), "server found %.2f s after joining the domain",
                  std::chrono::duration<double>(Clock::now() - s.joined).count());
    on_event(std::string(found_after) + ": streaming session " + session_id_ +
             (every_frame ? " (every frame)" : " (live)"));

    // The camera thread: reads frames, paces recordings, never waits on the network in live mode.
    const bool paced = options_.rate == RateMode::kFixed || (options_.rate == RateMode::kReal && info.is_recording);
    const double rate_hz = options_.rate == RateMode::kFixed ? options_.rate_hz : info.rate_hz;
    const auto start = Clock::now();
    std::thread camera_thread([&] {
        uint32_t n = 0;
        while (!stop) {
            int slot = -1;
            {
                std::unique_lock lock(s.mutex);
                if (s.publisher_done) break;
                if (every_frame) {
                    // Timed waits: `stop` is set from a signal handler, which cannot notify a condition variable.
                    while (s.free_slots->empty() && !stop && !s.publisher_done) s.changed.wait_for(lock, 100ms);
                    if (stop || s.publisher_done) break;
                    slot = s.free_slots->pop();
                } else if (!s.free_slots->empty()) {
                    slot = s.free_slots->pop();
                } else {
                    slot = s.ready->pop();  // the network fell behind: the oldest queued frame is worth least
                    ++s.stats.dropped;
                }
            }
            if (paced) std::this_thread::sleep_until(start + std::chrono::duration<double>(n / rate_hz));
            auto got = source_->next(s.slots[static_cast<size_t>(slot)]);
            std::lock_guard lock(s.mutex);
            if (!got.isOk() || !*got) {
                if (!got.isOk()) s.capture_status = got.status();
                s.free_slots->push(slot);
                break;
            }
            s.ready->push(slot);
            ++s.stats.captured;
            ++n;
            s.changed.notify_all();
        }
        std::lock_guard lock(s.mutex);
        s.capture_done = true;
        s.changed.notify_all();
    });

    // The publisher: compress and write; report once a second.
    wire::ColourJpegParams jpeg;
    jpeg.quality = options_.jpeg_quality;
    wire::FrameEncoder encoder(options_.depth, jpeg);
    wire::EncodedFrame encoded;
    Status result;
    double raw_bytes = 0, sent_bytes = 0, interval_bytes = 0;
    uint32_t interval_frames = 0;
    auto last_report = Clock::now();
    bool server_lost = false;
    auto report = [&](bool force) {
        const auto now = Clock::now();
        const double dt = std::chrono::duration<double>(now - last_report).count();
        if (!force && dt < 1.0) return;
        AgentStats snapshot;
        {
            std::lock_guard lock(s.mutex);
            snapshot = s.stats;
        }
        snapshot.elapsed_s = std::chrono::duration<double>(now - start).count();
        snapshot.fps = dt > 0 ? interval_frames / dt : 0;
        snapshot.bytes_per_s = dt > 0 ? interval_bytes / dt : 0;
        snapshot.ratio = sent_bytes > 0 ? raw_bytes / sent_bytes : 0;
        snapshot.servers = s.frame_writer.matchedReaders();
        on_stats(snapshot);
        last_report = now;
        interval_bytes = 0;
        interval_frames = 0;
    };

    while (result.isOk()) {
        int slot = -1;
        {
            std::unique_lock lock(s.mutex);
            s.changed.wait_for(lock, 100ms, [&] { return !s.ready->empty() || s.capture_done; });
            if (s.ready->empty()) {
                if (s.capture_done) break;
                lock.unlock();
                report(false);
                continue;
            }
            slot = s.ready->pop();
        }
        const CapturedFrame& frame = s.slots[static_cast<size_t>(slot)];
        encoded.seq = frame.index;
        encoded.capture_time_ns = wallClockNs();
        encoded.source_time_ns = frame.timestamp_ns;
        const Status encode_status = encoder.encode(frame.depth_raw, frame.colour_bgr, encoded);
        raw_bytes += static_cast<double>(frame.depth_raw.total() * 2 + frame.colour_bgr.total() * 3);
        {
            std::lock_guard lock(s.mutex);
            s.free_slots->push(slot);
            s.changed.notify_all();
        }
        if (!encode_status.isOk()) {
            result = encode_status;
            break;
        }
        // A recording must not be sent into the void: wait for a server to come back.
        while (every_frame && s.frame_writer.matchedReaders() == 0 && !stop) {
            if (!server_lost) on_event("server lost: waiting for a facescan-server on " + where + " ...");
            server_lost = true;
            std::this_thread::sleep_for(200ms);
        }
        if (server_lost && s.frame_writer.matchedReaders() > 0) {
            on_event("server back: resuming");
            server_lost = false;
        }
        const facescan_wire_RgbdFrame msg = wire::toMessage(session_id_, encoded);
        Status written = s.frame_writer.write(msg);
        // Back-pressure: a keep-all writer times out when the server has not taken frames for a while.
        while (written.code() == StatusCode::kDeadlineExceeded && !stop) written = s.frame_writer.write(msg);
        if (!written.isOk() && !stop) {
            result = written;
            break;
        }
        {
            std::lock_guard lock(s.mutex);
            ++s.stats.published;
        }
        sent_bytes += static_cast<double>(encoded.bytes());
        interval_bytes += static_cast<double>(encoded.bytes());
        ++interval_frames;
        report(false);
    }

    {
        // Stop the camera thread (it may be waiting for a free slot after a publisher error).
        std::lock_guard lock(s.mutex);
        s.publisher_done = true;
        s.changed.notify_all();
    }
    camera_thread.join();
    report(true);

    // Tell the server the stream ended (also after Ctrl-C or a camera failure), and let it acknowledge.
    facescan_wire_RgbdFrame end{};
    end.session_id = wire::stringView(session_id_);
    end.seq = s.stats.captured;
    end.capture_time_ns = wallClockNs();
    end.end_of_stream = true;
    const Status end_status = s.frame_writer.write(end);
    if (end_status.isOk()) (void)s.frame_writer.waitForAcks(5s);

    if (!s.capture_status.isOk()) return s.capture_status;
    RETURN_IF_ERROR(result);
    return end_status;
}

}  // namespace facescan::capture
