// facescan-agent: runs beside the camera; reads frames, compresses them and streams them to facescan-server.
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include "capture/agent.hpp"
#include "facescan/version.hpp"
#include "recon/face_pipeline.hpp"
#include "wire/dds_options.hpp"

namespace {

std::atomic<bool> g_stop{false};
// The first SIGINT or SIGTERM stops the agent in order (within about 2 s: the stream's end told, unconfirmed
// frames saved); a second one ends it at once, for an operator who will not wait.
void onSignal(int) {
    if (!g_stop.exchange(true)) return;
    constexpr char kMessage[] = "facescan-agent: second signal: exiting at once\n";
    (void)!::write(STDERR_FILENO, kMessage, sizeof(kMessage) - 1);
    ::_exit(130);
}

void installSignalHandlers() {
    struct sigaction action {};
    action.sa_handler = onSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = 0;  // no SA_RESETHAND: the second signal must reach onSignal too
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
}

constexpr const char* kUsage = R"(usage: facescan-agent [options]

Reads RGB-D frames from a camera or a recording, compresses depth losslessly and colour as JPEG, and streams
them to facescan-server over DDS. Prints a status line every second; Ctrl-C or SIGTERM ends the stream within
2 s, whatever the server does (a second Ctrl-C at once), and saves a recording's unconfirmed frames (--save-dir).
When the scan is erased on the domain (facescan delete), the agent stops the same way but drops the frames it
kept for it, saves none (and deletes a save under way), and says so.

options:
  --source SRC          where frames come from (default: openni2)
                          openni2[:URI]          the first OpenNI2 camera, or the one with this URI
                          oni:FILE               an OpenNI2 recording, every frame in order
                          tum:DIR                a TUM RGB-D folder
                          mkv:FILE               an Azure Kinect or Orbbec Femto recording (.mkv): depth,
                                                 MJPEG colour, the calibration; undistorted to a pinhole
                          bag:FILE               an Intel RealSense recording (.bag, librealsense's ROS
                                                 layout): depth, colour, camera_info, extrinsics
                          synthetic[:k=v,...]    the virtual Kinect filming a head scan; keys: scenario
                                                 (gentle|wide|chin|gap|occluder), frames, distance (m),
                                                 yaw, pitch (deg), period (frames), seed, noise (0/1),
                                                 subject (auto|builtin|scan|PATH); all keys: an unknown
                                                 key's error lists them
  --sensor NAME         the camera, when the source cannot tell (recordings) or tells wrong: its working range,
                        kind and depth noise, from which every stage takes its limits; one of kinect-v1, xtion,
                        astra, realsense-d415, azure-kinect, truedepth (default: what the device reports; a
                        source that cannot tell: kinect-v1)
  --depth-range MIN:MAX the camera's working range in metres, over the sensor's (e.g. 0.2:0.5)
  --roll auto|DEG       how the camera is held: how far the person appears turned clockwise in the image,
                        0 to 345 degrees in steps of 15 (a phone in portrait: 90 or 270; upside down: 180;
                        at a slant: the nearest step, e.g. 30); the server uses it unless its own --roll is
                        set (default auto: the server finds it from the frames). Servers from before slants
                        were handled take only quarter turns and reject a slant: update them first
  --session ID          session id (default: a fresh unique id, printed at start)
  --frames N            stop after N frames (default: all)
  --rate real|max|HZ    real: the source's own rate (default); max: as fast as the server takes them, with no
                        frame lost (recordings); HZ: a fixed rate
  --jpeg-quality Q      colour JPEG quality 1-100 (default 90)
  --no-colour           send depth only
  --preload             read the whole recording into memory first (tum:, oni:, mkv:, bag:, synthetic), then
                        stream it at its rate: the agent then costs only its encoding, as on a capture PC of its
                        own (memory: about 1.5 MB per VGA frame with colour)
  --hold-until FILE     after opening (and preloading) the source, wait until FILE exists before announcing the
                        session: several agents then start streaming together (tests/bench/server_realtime.sh)
  --depth-codec NAME    lossless depth codec: packed-delta-zstd (default), delta-zstd, rvl-zstd, rvl, zstd,
                        raw16, png (`facescan-bench codecs` compares them on your frames)
  --tum-depth-scale S   raw depth units per metre of tum: sources (default 5000; Kinect millimetres: 1000)
  --depth-scale S       raw depth units per metre of mkv: and bag: recordings, over what the recording says
                        (mkv: millimetres, 1000; bag: its Depth Units option)
  --wait-for-server S   give up when no server takes the session within S seconds (default: wait forever)
  --keep-frames N       recording frames kept until the owning server confirms them (replicated to its
                        standby or on its disk), to resend after a takeover; when full, the agent waits
                        (default 300)
  --finish-timeout S    after the last frame, wait at most S seconds for the server to finish (default 120)
  --stalled-after S     report a server that has taken no frame for S seconds while the agent waits on it
                        (default 10); the agent keeps waiting for it or for another server to take over
  --save-dir DIR        where a recording's frames that no server confirmed are saved when the agent stops
                        before its scan finished: DIR/SESSION, a TUM folder that --source tum: replays
                        (default: $XDG_STATE_HOME/facescan/unconfirmed, else
                        ~/.local/state/facescan/unconfirmed)
)";
constexpr const char* kUsageEnd = R"(  --version             print the version and the git commit it was built from
  --help                this text

exit codes: 0 done, 1 error (source, network, DDS Security), 2 bad usage)";

int usageError(const std::string& message) {
    std::fprintf(stderr, "facescan-agent: %s\n(see facescan-agent --help)\n", message.c_str());
    return 2;
}

bool parseInt(const std::string& text, long lo, long hi, long& out) {
    char* end = nullptr;
    out = std::strtol(text.c_str(), &end, 10);
    return end && *end == '\0' && !text.empty() && out >= lo && out <= hi;
}

}  // namespace

int main(int argc, char** argv) {
    using namespace facescan;
    capture::AgentOptions options;
    std::string hold_until;  // --hold-until: announce the session once this file exists
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
        long n = 0;
        if (arg == "--help" || arg == "-h") {
            std::printf("%s%s%s\n", kUsage, wire::ddsOptionsHelp(24).c_str(), kUsageEnd);
            return 0;
        } else if (arg == "--version") {
            printVersion("facescan-agent");
            return 0;
        } else if (arg == "--no-colour" || arg == "--no-color") {
            options.source_options.colour = false;
            continue;
        } else if (arg == "--preload") {
            options.preload = true;
            continue;
        } else if (arg == "--hold-until") {
            const char* v = value();
            if (v == nullptr || *v == '\0') return usageError("--hold-until takes a file path");
            hold_until = v;
            continue;
        }
        const char* v = value();
        if (!v) return usageError(arg + " needs a value");
        const std::string text = v;
        if (arg == "--source") {
            options.source = text;
        } else if (arg == "--sensor") {
            if (const auto preset = recon::findSensorPreset(text); !preset.isOk())
                return usageError(preset.status().message());
            options.sensor = text;
        } else if (arg == "--depth-range") {
            char* end = nullptr;
            const float lo = std::strtof(text.c_str(), &end);
            const float hi = end && *end == ':' ? std::strtof(end + 1, &end) : 0.0f;
            if (!end || *end != '\0' || !(lo > 0 && hi > lo && hi <= 20)) {
                return usageError(
                    "--depth-range takes MIN:MAX in metres with 0 < MIN < MAX <= 20, e.g. 0.2:0.5; got '" + text + "'");
            }
            options.depth_min_m = lo;
            options.depth_max_m = hi;
        } else if (arg == "--roll") {
            const auto roll = recon::parseRoll(text);
            if (!roll.isOk()) return usageError("--roll: " + roll.status().message());
            options.roll_deg = *roll;
        } else if (arg == "--session") {
            options.session_id = text;
        } else if (arg == "--frames") {
            if (!parseInt(text, 1, 100'000'000, n)) return usageError("--frames takes a positive count");
            options.source_options.max_frames = static_cast<int>(n);
        } else if (arg == "--rate") {
            if (text == "real") {
                options.rate = capture::RateMode::kReal;
            } else if (text == "max") {
                options.rate = capture::RateMode::kMax;
            } else {
                options.rate = capture::RateMode::kFixed;
                options.rate_hz = std::strtof(text.c_str(), nullptr);
            }
        } else if (arg == "--jpeg-quality") {
            if (!parseInt(text, 1, 100, n)) return usageError("--jpeg-quality takes 1-100");
            options.jpeg_quality = static_cast<int>(n);
        } else if (arg == "--depth-codec") {
            const auto codec = wire::depthCodecFromName(text);
            if (!codec) return usageError("unknown depth codec '" + text + "'");
            options.depth.codec = *codec;
        } else if (arg == "--tum-depth-scale") {
            const float per_m = std::strtof(text.c_str(), nullptr);
            if (!(per_m > 0)) return usageError("--tum-depth-scale takes raw units per metre, e.g. 5000");
            options.source_options.tum_depth_units_m = 1.0f / per_m;
        } else if (arg == "--depth-scale") {
            const float per_m = std::strtof(text.c_str(), nullptr);
            if (!(per_m >= 100 && per_m <= 1e6))
                return usageError("--depth-scale takes raw units per metre, e.g. 1000");
            options.source_options.recording_depth_units_m = 1.0f / per_m;
        } else if (arg == "--wait-for-server") {
            options.wait_for_server_s = std::strtof(text.c_str(), nullptr);
        } else if (arg == "--keep-frames") {
            if (!parseInt(text, 8, 100000, n)) return usageError("--keep-frames takes 8-100000");
            options.keep_frames = static_cast<int>(n);
        } else if (arg == "--finish-timeout") {
            options.finish_timeout_s = std::strtof(text.c_str(), nullptr);
        } else if (arg == "--stalled-after") {
            options.stalled_after_s = std::strtof(text.c_str(), nullptr);
        } else if (arg == "--save-dir") {
            if (text.empty()) return usageError("--save-dir takes a folder");
            options.save_dir = text;
        } else if (wire::isDdsOption(arg)) {
            if (const Status s = wire::applyDdsOption(options.dds, arg, text); !s.isOk())
                return usageError(s.message());
        } else {
            return usageError("unknown option " + arg);
        }
    }
    if (const Status s = options.validate(); !s.isOk()) return usageError(s.message());

    if (options.preload) {
        // A line per tenth of the recording (or per 100 frames when its length is unknown).
        options.preload_progress = [last_tenth = -1](int done, int expected) mutable {
            if (expected <= 0) {
                if (done % 100 == 0) std::printf("facescan-agent: preloading, %d frames so far\n", done);
            } else if (const int tenth = 10 * done / expected; tenth != last_tenth) {
                last_tenth = tenth;
                std::printf("facescan-agent: preloading %d of %d frames\n", done, expected);
            }
            std::fflush(stdout);
        };
    }
    auto agent = capture::Agent::create(options);
    if (!agent.isOk()) {
        std::fprintf(stderr, "facescan-agent: %s\n", agent.status().toString().c_str());
        return agent.status().code() == StatusCode::kInvalidArgument ? 2 : 1;
    }
    const capture::SourceInfo& info = (*agent)->sourceInfo();
    std::printf("facescan-agent: session %s\n", (*agent)->sessionId().c_str());
    std::printf("facescan-agent: %s\n", wire::securitySummary(options.dds).c_str());
    std::printf("facescan-agent: source %s, %dx%d, %.1f Hz%s%s\n", info.description.c_str(), info.intrinsics.width_px,
                info.intrinsics.height_px, info.rate_hz, info.has_colour ? ", colour" : ", depth only",
                info.expected_frames > 0 ? (", " + std::to_string(info.expected_frames) + " frames").c_str() : "");
    if (auto sensor = options.resolveSensor(info); sensor.isOk()) {
        std::printf("facescan-agent: camera %s (%s), %.2f-%.2f m%s\n", sensor->name.c_str(),
                    recon::sensorFamilyName(sensor->family), sensor->min_depth_m, sensor->max_depth_m,
                    options.sensor.empty() && !info.sensor_known ? " (the source cannot tell: --sensor NAME)" : "");
    }
    std::fflush(stdout);

    uint64_t last_digest = 0;
    installSignalHandlers();
    if (!hold_until.empty()) {
        // Nothing is announced yet, so no server has taken the session: holding costs no frame.
        std::printf("facescan-agent: ready; holding until %s exists\n", hold_until.c_str());
        std::fflush(stdout);
        std::error_code ec;
        while (!g_stop && !std::filesystem::exists(hold_until, ec))
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        if (g_stop) {
            std::printf("facescan-agent: stopped (signal) before streaming\n");
            return 0;
        }
    }
    const Status status = (*agent)->run(
        g_stop,
        [](const std::string& event) {
            std::printf("facescan-agent: %s\n", event.c_str());
            std::fflush(stdout);
        },
        [&](const capture::AgentStats& st) {
            // The owner, or why nothing is sent (no server alive, a takeover under way): the operator sees it here.
            std::string link = st.waiting.empty() ? "owner " + (st.owner.empty() ? std::string("-") : st.owner) +
                                                        (st.standby.empty() ? "" : " (standby " + st.standby + ")")
                                                  : "WAITING: " + st.waiting;
            if ((*agent)->everyFrame()) link += " | kept " + std::to_string(st.kept);
            if (st.takeovers > 0) {
                link += " | takeovers " + std::to_string(st.takeovers) + ", resent " + std::to_string(st.replayed);
            }
            std::printf("frames %u | %.1f fps | %.2f Mbit/s | ratio %.1f:1 | dropped %u | servers %d | %s\n",
                        st.published, st.fps, st.bytes_per_s * 8e-6, st.ratio, st.dropped, st.servers, link.c_str());
            std::fflush(stdout);
            last_digest = st.digest;
        });

    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    const double cpu_s =
        usage.ru_utime.tv_sec + usage.ru_utime.tv_usec * 1e-6 + usage.ru_stime.tv_sec + usage.ru_stime.tv_usec * 1e-6;
    std::printf("facescan-agent: %s; cpu %.2f s; frames digest %016llx\n", g_stop ? "stopped (signal)" : "stream ended",
                cpu_s, static_cast<unsigned long long>(last_digest));
    if (!status.isOk()) {
        std::fprintf(stderr, "facescan-agent: %s\n", status.toString().c_str());
        return 1;
    }
    return 0;
}
