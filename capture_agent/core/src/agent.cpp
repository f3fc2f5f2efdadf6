#include "capture/agent.hpp"

#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <ctime>
#include <filesystem>
#include <mutex>
#include <optional>
#include <random>
#include <thread>
#include <vector>

#include "capture/owner_link.hpp"
#include "capture/tum_recorder.hpp"
#include "wire/dds_options.hpp"
#include "wire/messages.hpp"
#include "wire/topics.hpp"

namespace facescan::capture {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

// How long the agent's writers keep resending unacknowledged samples once deleted: long enough for a live server
// to acknowledge the end of the stream, short enough that a stuck server does not hold a stopping agent (its
// frames are saved on disk instead).
constexpr std::chrono::milliseconds kWriterLinger{200};
// After a stop, how long the end of the stream may wait for the owner to take it: a server that takes frames
// takes it at once (its reader has room within a frame or two), a stuck one never does.
constexpr float kEndAfterStopS = 0.3f;

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
    if (keep_frames < 8 || keep_frames > 100000) return invalidArgument("--keep-frames must be 8..100000");
    if (!(finish_timeout_s > 0)) return invalidArgument("--finish-timeout must be > 0 seconds");
    if (wait_for_server_s < 0) return invalidArgument("--wait-for-server must be >= 0 seconds");
    if (!(stalled_after_s > 0)) return invalidArgument("--stalled-after must be > 0 seconds");
    if (!sensor.empty()) RETURN_IF_ERROR(recon::findSensorPreset(sensor).status());
    if (roll_deg != wire::CameraInfoData::kRollUnknown && !recon::isRollStepDeg(roll_deg)) {
        return invalidArgument("--roll " + std::to_string(roll_deg) +
                               " cannot be right: auto or 0 to 345 in steps of " + std::to_string(recon::kRollStepDeg) +
                               " (how far the person appears turned clockwise in the image: a phone held in portrait "
                               "90 or 270, upside down 180)");
    }
    if ((depth_min_m != 0 || depth_max_m != 0) && !(depth_min_m > 0 && depth_max_m > depth_min_m)) {
        return invalidArgument("--depth-range " + std::to_string(depth_min_m) + ":" + std::to_string(depth_max_m) +
                               " cannot be right: give MIN:MAX in metres with 0 < MIN < MAX, e.g. 0.2:0.5");
    }
    return depth.validate();
}

Status checkFrameFitsCamera(const wire::CameraInfoData& camera, const CapturedFrame& frame) {
    RETURN_IF_ERROR(camera.checkDepthUnits(frame.depth_raw));
    if (frame.colour_bgr.empty()) return Status::ok();
    const recon::Intrinsics& c = camera.colourIntrinsics();
    if (frame.colour_bgr.cols != c.width_px || frame.colour_bgr.rows != c.height_px) {
        return invalidArgument("the source's colour frames are " + std::to_string(frame.colour_bgr.cols) + "x" +
                               std::to_string(frame.colour_bgr.rows) + " but its camera description says " +
                               std::to_string(c.width_px) + "x" + std::to_string(c.height_px) +
                               ": send depth only (--no-colour) or fix the recording's colour intrinsics");
    }
    return Status::ok();
}

StatusOr<recon::SensorModel> AgentOptions::resolveSensor(const SourceInfo& source) const {
    recon::SensorModel s = source.sensor;
    if (!sensor.empty()) {
        ASSIGN_OR_RETURN(const recon::SensorPreset preset, recon::findSensorPreset(sensor));
        s = preset.sensor;
    }
    if (depth_min_m > 0) s.min_depth_m = depth_min_m;
    if (depth_max_m > 0) s.max_depth_m = depth_max_m;
    RETURN_IF_ERROR(s.validate());
    return s;
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

StatusOr<std::filesystem::path> Agent::saveUnconfirmed(const std::vector<wire::EncodedFrame>& kept,
                                                       const std::vector<const CapturedFrame*>& queued,
                                                       const std::function<void(const std::string&)>& on_event) {
    if (kept.empty() && queued.empty()) return std::filesystem::path();
    const std::filesystem::path parent =
        options_.save_dir.empty() ? defaultSaveDir() : std::filesystem::path(options_.save_dir);
    ASSIGN_OR_RETURN(const std::filesystem::path dir, createFreshDir(parent, session_id_));
    // The camera as the stream described it (--sensor and --depth-range included), so a replay describes it too.
    SourceInfo info = source_->info();
    ASSIGN_OR_RETURN(info.sensor, options_.resolveSensor(info));
    info.sensor_known = info.sensor_known || !options_.sensor.empty() || options_.depth_min_m > 0;
    ASSIGN_OR_RETURN(TumRecorder recorder, TumRecorder::create(dir, info, options_.jpeg_quality));
    for (const wire::EncodedFrame& f : kept) RETURN_IF_ERROR(recorder.add(f));
    for (const CapturedFrame* f : queued) RETURN_IF_ERROR(recorder.add(*f));
    const uint32_t first = kept.empty() ? queued.front()->index : kept.front().seq;
    const uint32_t last = queued.empty() ? kept.back().seq : queued.back()->index;
    on_event("saved the " + std::to_string(recorder.frames()) + " frames no server confirmed (frames " +
             std::to_string(first) + "-" + std::to_string(last) + " of session " + session_id_ + ") to " +
             dir.string() + ": replay them with --source tum:" + dir.string() + " --rate max");
    return dir;
}

struct Agent::Impl {
    wire::Participant participant;
    Clock::time_point joined;  // when the participant was created (discovery time is measured from here)
    wire::Topic<facescan_wire_CameraInfo> info_topic;
    wire::Writer<facescan_wire_CameraInfo> info_writer;
    wire::Topic<facescan_wire_RgbdFrame> frame_topic;
    wire::Writer<facescan_wire_RgbdFrame> frame_writer;  // in the session's partition: only its owner reads it
    std::optional<OwnerLink> link;
    // `facescan delete` on the domain: requests to erase a session (read for this agent's session only).
    std::optional<wire::Topic<facescan_wire_EraseRequest>> erase_topic;
    std::optional<wire::Reader<facescan_wire_EraseRequest>> erase_reader;
    std::string erase_unavailable;  // why this agent cannot hear erasures (said once at the start)

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
    wire::DomainConfig dds = agent->options_.dds;
    dds.writer_linger = kWriterLinger;
    ASSIGN_OR_RETURN(impl->participant, wire::Participant::create(dds));
    impl->joined = Clock::now();
    ASSIGN_OR_RETURN(impl->info_topic, wire::Topic<facescan_wire_CameraInfo>::create(impl->participant));
    ASSIGN_OR_RETURN(impl->info_writer, wire::Writer<facescan_wire_CameraInfo>::create(impl->info_topic));
    ASSIGN_OR_RETURN(impl->frame_topic, wire::Topic<facescan_wire_RgbdFrame>::create(impl->participant));
    wire::Qos frame_qos = wire::frameWriterQos(agent->everyFrame());
    // Short blocks, retried: a write that waits on the owner looks at the stop flag and the claim in between.
    dds_qset_reliability(frame_qos.get(), DDS_RELIABILITY_RELIABLE, DDS_MSECS(kFrameWriteBlocking.count()));
    ASSIGN_OR_RETURN(impl->frame_writer,
                     wire::Writer<facescan_wire_RgbdFrame>::create(impl->frame_topic, &frame_qos,
                                                                   wire::sessionPartition(agent->session_id_)));
    ASSIGN_OR_RETURN(impl->link, OwnerLink::create(impl->participant, agent->session_id_));
    // An identity enrolled before agents read erasures may not: the agent still scans, and says what it misses.
    if (auto topic = wire::Topic<facescan_wire_EraseRequest>::create(impl->participant); topic.isOk()) {
        impl->erase_topic.emplace(std::move(*topic));
        if (auto reader = wire::Reader<facescan_wire_EraseRequest>::create(*impl->erase_topic); reader.isOk()) {
            impl->erase_reader.emplace(std::move(*reader));
        } else {
            impl->erase_unavailable = reader.status().message();
        }
    } else {
        impl->erase_unavailable = topic.status().message();
    }
    const int queue = agent->options_.queue_frames;
    impl->slots.resize(static_cast<size_t>(queue));
    impl->free_slots.emplace(queue);
    impl->ready.emplace(queue);
    for (int i = 0; i < queue; ++i) impl->free_slots->push(i);
    agent->impl_ = std::move(impl);
    return agent;
}

std::string Agent::erasureRequested() {
    if (!impl_->erase_reader) return {};
    std::string by;
    auto n = impl_->erase_reader->take([&](const facescan_wire_EraseRequest& m, const dds_sample_info_t& info) {
        if (info.valid_data && wire::fromDds(m.session_id) == session_id_) by = wire::fromDds(m.client_id);
    });
    if (!n.isOk()) return {};
    return by;
}

Status Agent::run(const std::atomic<bool>& external_stop, const std::function<void(const std::string&)>& on_event,
                  const std::function<void(const AgentStats&)>& on_stats) {
    Impl& s = *impl_;
    if (!s.erase_unavailable.empty()) {
        on_event("WARNING: this agent cannot hear facescan delete (" + s.erase_unavailable +
                 "): with DDS Security, enrol its identity again (site.sh add) so that it may read erasures");
    }
    // `stop` is Ctrl-C (the caller's flag) or an erasure of this session on the domain, watched here.
    std::atomic<bool> stop{false}, erased{false}, watching{true};
    std::string erased_by;  // written before `erased` is set
    std::thread watcher([&] {
        while (watching) {
            if (external_stop) stop = true;
            if (!erased) {
                if (std::string by = erasureRequested(); !by.empty()) {
                    erased_by = std::move(by);
                    erased = true;
                    stop = true;
                }
            }
            std::this_thread::sleep_for(50ms);
        }
    });
    struct JoinWatcher {
        std::atomic<bool>& watching;
        std::thread& thread;
        ~JoinWatcher() {
            watching = false;
            thread.join();
        }
    } join_watcher{watching, watcher};
    auto say_erased = [&](size_t dropped) {
        on_event("session " + session_id_ + " was erased on the domain (facescan delete, asked by " + erased_by +
                 "): dropped the " + std::to_string(dropped) + " frame(s) this agent kept for it and saved none");
    };
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
    ASSIGN_OR_RETURN(camera.sensor, options_.resolveSensor(info));
    camera.colour_intrinsics =
        info.colour_registered ? recon::Intrinsics{0, 0, 0.0f, 0.0f, 0.0f, 0.0f} : info.colour_intrinsics;
    camera.T_colour_depth = info.colour_registered ? recon::Pose::Identity() : info.T_colour_depth;
    camera.roll_deg = options_.roll_deg;
    RETURN_IF_ERROR(camera.validate());
    // Written again as the recording's owners and confirmations change, always with this first timestamp: the
    // servers order the sessions they place by it.
    const dds_time_t camera_written_at = dds_time();
    RETURN_IF_ERROR(s.info_writer.writeAt(wire::toMessage(camera), camera_written_at));
    // Written again every second: a server takes a scan over on this agent's word only when it has heard from the
    // agent since the owner's lease lapsed (a server cut off from the network still sees every writer alive until
    // Cyclone's lease on its participant lapses, seconds later under load), and a server that hears from no agent
    // and no peer knows it is cut off.
    auto last_announced = Clock::now();
    auto announce = [&] {
        last_announced = Clock::now();
        if (const Status w = s.info_writer.writeAt(wire::toMessage(camera), camera_written_at); !w.isOk()) {
            on_event("WARNING: cannot tell the servers how far session " + session_id_ + " got: " + w.toString());
        }
    };

    // Nothing is read from the source until a server owns the session, so a recording loses no frame while we wait.
    const std::string where = options_.dds.describe();
    SessionStream stream(std::move(*s.link), s.frame_writer, session_id_, every_frame,
                         static_cast<size_t>(options_.keep_frames), options_.stalled_after_s, where, on_event);
    // After a moment with no server at all, say why none may answer (a secured domain, most often).
    stream.onNoServer([&] { return wire::noPeerHint(options_.dds, s.participant.otherParticipants()); });
    stream.onWait([&] {
        if (Clock::now() - last_announced >= 1s) announce();
    });
    if (const Status served = stream.waitUntilServed(stop, options_.wait_for_server_s); !served.isOk()) {
        if (served.code() != StatusCode::kDeadlineExceeded) return served;
        char seconds[32];
        std::snprintf(seconds, sizeof(seconds), "%g", options_.wait_for_server_s);
        return deadlineExceeded("no facescan-server appeared on " + where + " within " + seconds +
                                " s to take session " + session_id_ +
                                ": start one with the same --profile, --domain and --security; " +
                                wire::noPeerHint(options_.dds, s.participant.otherParticipants()));
    }
    if (erased) {
        say_erased(0);
        return Status::ok();
    }
    if (stop) return Status::ok();
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
            if (n == 0 && got.isOk() && *got) {
                // The first frame against the camera's description: wrong units or a colour camera of another
                // size are stopped here, with one line, before the server scans anything from them.
                if (Status fits = checkFrameFitsCamera(camera, s.slots[static_cast<size_t>(slot)]); !fits.isOk())
                    got = std::move(fits);
            }
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
    auto report = [&](bool force) {
        // An owner that stops serving (or a new one) is told at once, not at the next second: a server weighs the
        // agent's word before it takes the scan over, and would wait for it.
        if (const uint32_t serving = stream.servingEpoch(); serving != camera.serving_epoch) {
            camera.serving_epoch = serving;
            announce();
        }
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
        const StreamState st = stream.state();
        snapshot.servers = st.servers;
        snapshot.owner = st.owner;
        snapshot.standby = st.standby;
        snapshot.epoch = st.epoch;
        snapshot.takeovers = st.takeovers;
        snapshot.replayed = st.replayed;
        snapshot.kept = st.kept;
        snapshot.waiting = st.waiting;
        snapshot.digest = st.digest;
        if (every_frame) {
            // What a server that restarted after the owner's claim went must know (the message's comment).
            camera.followed_epoch = st.followed_epoch;
            camera.dropped_before_seq = st.dropped_before;
        }
        announce();
        on_stats(snapshot);
        last_report = now;
        interval_bytes = 0;
        interval_frames = 0;
    };

    stream.onWait([&] { report(false); });
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
        // To the session's owner; waits while there is none (a takeover), resends what a new owner needs.
        const Status written = stream.send(encoded, /*end_of_stream=*/false, stop);
        if (!written.isOk()) {
            result = written;
            break;
        }
        if (stop) break;
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
    // From the stop on, every wait below is cut to what is left of kStopBudgetS.
    const auto stopped_at = Clock::now();
    const bool stopped = stop;
    auto budget_left_s = [&] {
        return std::max(0.05f, kStopBudgetS - std::chrono::duration<float>(Clock::now() - stopped_at).count());
    };

    // Tell the server the stream ended (also after Ctrl-C or a camera failure), and wait until it finished the
    // scan: a recording's kept frames are still needed if its owner dies before that.
    wire::EncodedFrame end;
    end.seq = stream.nextSeq();
    end.capture_time_ns = wallClockNs();
    const std::atomic<bool> no_stop{false};
    // After a stop: a moment to hand the end of the stream to an owner, not forever (the stop itself would
    // interrupt the send at once).
    Status end_status = stream.send(end, /*end_of_stream=*/true, stopped ? no_stop : stop,
                                    stopped ? std::min(budget_left_s(), kEndAfterStopS) : 0.0f);
    bool told_end = end_status.isOk();
    if (stopped && !told_end) {
        // A stuck or missing owner: it cannot finish the scan either, so nothing is waited for.
        on_event("the server was not told that the stream ended: " + end_status.message());
        end_status = Status::ok();
    }
    // An erased scan is not waited for: nothing of it is kept for a new owner.
    if (told_end && !erased && !stream.waitFinished(stop, options_.finish_timeout_s, budget_left_s())) {
        if (!stop) {
            end_status = deadlineExceeded("the server did not finish session " + session_id_ + " within " +
                                          std::to_string(static_cast<int>(options_.finish_timeout_s)) + " s");
        }
    }
    report(true);
    if (erased) {
        // Nothing of an erased scan stays with the agent: the kept and queued frames go with it, unsaved.
        std::vector<wire::EncodedFrame> kept = every_frame ? stream.unconfirmed() : std::vector<wire::EncodedFrame>{};
        size_t queued = 0;
        while (!s.ready->empty()) {
            s.ready->pop();
            ++queued;
        }
        say_erased(kept.size() + queued);
    } else if (every_frame && !stream.finished()) {
        // The frames kept for the owner, then the captured ones still queued for the publisher.
        std::vector<wire::EncodedFrame> kept = stream.unconfirmed();
        std::vector<const CapturedFrame*> queued;
        while (!s.ready->empty()) queued.push_back(&s.slots[static_cast<size_t>(s.ready->pop())]);
        auto saved = saveUnconfirmed(kept, queued, on_event);
        if (!saved.isOk()) {
            on_event("could not save the frames no server confirmed: " + saved.status().toString());
            if (end_status.isOk()) end_status = saved.status();
        } else if (!saved->empty()) {
            // An erasure that came while saving: what was just written goes too.
            if (!erased) std::this_thread::sleep_for(100ms);  // the watcher's next look at the domain
            if (erased) {
                std::error_code ec;
                const auto removed = std::filesystem::remove_all(*saved, ec);
                on_event("session " + session_id_ + " was erased on the domain while its frames were saved (asked by " +
                         erased_by + "): " +
                         (ec ? "could NOT delete " + saved->string() + ": " + ec.message() + " (delete it by hand)"
                             : "deleted " + saved->string() + " (" + std::to_string(removed) + " file(s))"));
            }
        }
    }

    if (!s.capture_status.isOk()) return s.capture_status;
    RETURN_IF_ERROR(result);
    return end_status;
}

}  // namespace facescan::capture
