// facescan-bench transport: an agent-sized RGB-D stream between two processes over Cyclone DDS on loopback.
// Phase 1 (paced): depth + colour at --rate Hz for --seconds, reliable QoS as the agent sends a live camera:
// delivered share, latency p50/p99/max (write to take, same clock), CPU per side. Phase 2 (flat out): keep-all
// with back-pressure as a --rate max recording, frames per second delivered. --security SITE runs both sides with
// DDS Security (the publisher as SITE/agent, the reader as SITE/server): the transport's share of its cost.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>
#include <thread>
#include <vector>

#include "bench_command.hpp"
#include "synth/kinect_simulator.hpp"
#include "wire/messages.hpp"

namespace facescan::bench {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

int64_t nowNs() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

double cpuSeconds(const rusage& u) {
    return u.ru_utime.tv_sec + u.ru_utime.tv_usec * 1e-6 + u.ru_stime.tv_sec + u.ru_stime.tv_usec * 1e-6;
}

struct Options {
    double seconds = 10;
    double rate_hz = 30;
    double flat_out_seconds = 5;
    uint32_t domain = 0;
    int distinct_frames = 30;
    bool json = false;
    std::string security_site;  // a site of deploy/security/site.sh; empty: no DDS Security

    wire::DomainConfig dds(const char* role) const {
        return {domain, "loopback", security_site.empty() ? std::string() : security_site + "/" + role};
    }
};

// Real payloads: synthetic Kinect frames compressed with the agent's default codecs, cycled.
std::vector<wire::EncodedFrame> makePayloads(int count) {
    synth::SequenceParams seq;
    seq.frames = count;
    const synth::KinectSimulator sim(synth::defaultHead(), seq);
    wire::FrameEncoder encoder;
    std::vector<wire::EncodedFrame> payloads(static_cast<size_t>(count));
    recon::RgbdFrame frame;
    cv::Mat raw;
    for (int i = 0; i < count; ++i) {
        sim.render(i, frame);
        recon::depthMetresToRaw(frame.depth_m, 0.0002f, raw);
        if (!encoder.encode(raw, frame.colour_bgr, payloads[static_cast<size_t>(i)]).isOk()) std::exit(3);
    }
    return payloads;
}

// The publishing process: phase 1 paced (live QoS), phase 2 flat out (keep-all). Writes its CPU seconds of the
// paced phase to `cpu_fd`. Exits when done.
[[noreturn]] void publisher(const Options& o, int cpu_fd) {
    const auto payloads = makePayloads(o.distinct_frames);
    auto participant = wire::Participant::create(o.dds("agent"));
    if (!participant) _exit(10);
    auto topic = wire::Topic<facescan_wire_RgbdFrame>::create(*participant);
    if (!topic) _exit(11);
    const std::string session = "bench-transport";
    for (int phase = 0; phase < 2; ++phase) {
        const wire::Qos qos = wire::frameWriterQos(/*every_frame=*/phase == 1);
        auto writer = wire::Writer<facescan_wire_RgbdFrame>::create(*topic, &qos);
        if (!writer || !writer->waitForReaders(1, 20s)) _exit(12);
        std::this_thread::sleep_for(200ms);  // let the reader's side of discovery settle
        rusage before{};
        getrusage(RUSAGE_SELF, &before);
        const auto start = Clock::now();
        const double seconds = phase == 0 ? o.seconds : o.flat_out_seconds;
        for (uint32_t seq = 0;; ++seq) {
            if (phase == 0) std::this_thread::sleep_until(start + std::chrono::duration<double>(seq / o.rate_hz));
            if (Clock::now() - start > std::chrono::duration<double>(seconds)) break;
            wire::EncodedFrame frame = payloads[seq % payloads.size()];
            frame.seq = seq;
            frame.capture_time_ns = nowNs();
            const facescan_wire_RgbdFrame msg = wire::toMessage(session, frame);
            if (!writer->write(msg).isOk()) _exit(13);
        }
        facescan_wire_RgbdFrame end{};
        end.session_id = wire::stringView(session);
        end.end_of_stream = true;
        if (!writer->write(end).isOk()) _exit(14);
        (void)writer->waitForAcks(10s);
        if (phase == 0) {
            rusage after{};
            getrusage(RUSAGE_SELF, &after);
            const double cpu_s = cpuSeconds(after) - cpuSeconds(before);
            if (::write(cpu_fd, &cpu_s, sizeof(cpu_s)) != sizeof(cpu_s)) _exit(15);
        }
        // Wait for the reader to move on before the next phase's writer appears.
        std::this_thread::sleep_for(300ms);
    }
    _exit(0);
}

struct PhaseResult {
    uint32_t received = 0;
    uint32_t max_seq = 0;
    double seconds = 0;
    std::vector<double> latency_ms;
    double megabytes = 0;
};

PhaseResult receive(wire::Reader<facescan_wire_RgbdFrame>& reader, std::chrono::seconds timeout) {
    PhaseResult r;
    bool ended = false;
    Clock::time_point first{};
    const auto deadline = Clock::now() + timeout;
    while (!ended && Clock::now() < deadline) {
        reader.waitForData(100ms);
        (void)reader.take(
            [&](const facescan_wire_RgbdFrame& m, const dds_sample_info_t& info) {
                if (!info.valid_data) return;
                if (m.end_of_stream) {
                    ended = true;
                    return;
                }
                if (r.received == 0) first = Clock::now();
                ++r.received;
                r.max_seq = std::max(r.max_seq, m.seq);
                r.latency_ms.push_back((nowNs() - m.capture_time_ns) * 1e-6);
                r.megabytes += (m.depth._length + m.colour._length) * 1e-6;
            },
            64);
    }
    r.seconds = std::chrono::duration<double>(Clock::now() - first).count();
    std::sort(r.latency_ms.begin(), r.latency_ms.end());
    return r;
}

double percentile(const std::vector<double>& sorted, double p) {
    if (sorted.empty()) return 0;
    return sorted[std::min(sorted.size() - 1, static_cast<size_t>(p * (sorted.size() - 1) + 0.5))];
}

int runTransport(const std::vector<std::string>& args) {
    Options o;
    o.domain = 100 + static_cast<uint32_t>(getpid()) % 120;
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto next = [&]() { return i + 1 < args.size() ? std::stod(args[++i]) : 0.0; };
        if (a == "--help") {
            std::puts(
                "usage: facescan-bench transport [--seconds S] [--rate HZ] [--flat-out-seconds S] [--domain N] "
                "[--security SITE] [--json]\n\nStreams compressed synthetic Kinect frames (depth + colour, the "
                "agent's codecs) between two processes over DDS on the loopback profile.\nPaced phase: delivered "
                "share, latency p50/p99/max, CPU per side. Flat-out phase (keep-all, back-pressure): frames per "
                "second.\n--security SITE: both sides with DDS Security, as SITE/agent and SITE/server "
                "(deploy/security/site.sh init SITE).");
            return 0;
        } else if (a == "--seconds") {
            o.seconds = next();
        } else if (a == "--rate") {
            o.rate_hz = next();
        } else if (a == "--flat-out-seconds") {
            o.flat_out_seconds = next();
        } else if (a == "--domain") {
            o.domain = static_cast<uint32_t>(next());
        } else if (a == "--json") {
            o.json = true;
        } else if (a == "--security" && i + 1 < args.size()) {
            o.security_site = args[++i];
        } else {
            std::fprintf(stderr, "facescan-bench transport: unknown option %s\n", a.c_str());
            return 2;
        }
    }
    if (!(o.seconds > 0 && o.rate_hz > 0 && o.flat_out_seconds > 0) || o.domain > 232) {
        std::fprintf(stderr, "facescan-bench transport: --seconds, --rate, --flat-out-seconds must be > 0\n");
        return 2;
    }

    // Fork before any DDS or OpenCV thread exists in this process.
    int cpu_pipe[2];
    if (::pipe(cpu_pipe) != 0) return 1;
    const pid_t child = fork();
    if (child < 0) return 1;
    if (child == 0) publisher(o, cpu_pipe[1]);
    ::close(cpu_pipe[1]);

    auto participant = wire::Participant::create(o.dds("server"));
    if (!participant) {
        std::fprintf(stderr, "transport: %s\n", participant.status().toString().c_str());
        return 1;
    }
    auto topic = wire::Topic<facescan_wire_RgbdFrame>::create(*participant);
    const wire::Qos qos = wire::frameReaderQos();
    auto reader = wire::Reader<facescan_wire_RgbdFrame>::create(*topic, &qos);
    if (!topic || !reader) return 1;

    rusage self_before{};
    getrusage(RUSAGE_SELF, &self_before);
    const auto paced_timeout = std::chrono::seconds(static_cast<int>(o.seconds) + 60);
    const PhaseResult paced = receive(*reader, paced_timeout);
    rusage self_paced{};
    getrusage(RUSAGE_SELF, &self_paced);
    const PhaseResult flat = receive(*reader, std::chrono::seconds(static_cast<int>(o.flat_out_seconds) + 60));

    int status = 0;
    rusage child_usage{};
    wait4(child, &status, 0, &child_usage);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        std::fprintf(stderr, "transport: publisher failed (status %d)\n", status);
        return 1;
    }
    double writer_cpu_s = 0;
    if (::read(cpu_pipe[0], &writer_cpu_s, sizeof(writer_cpu_s)) != sizeof(writer_cpu_s)) writer_cpu_s = 0;
    ::close(cpu_pipe[0]);
    const double writer_cpu = writer_cpu_s / std::max(paced.seconds, 1e-9);
    const uint32_t sent = paced.max_seq + 1;
    const double delivered = sent > 0 ? 100.0 * paced.received / sent : 0;
    const double reader_cpu = (cpuSeconds(self_paced) - cpuSeconds(self_before)) / std::max(paced.seconds, 1e-9);
    // The publisher's CPU covers payload preparation and both phases; report per second of the whole run.
    const double flat_fps = flat.seconds > 0 ? flat.received / flat.seconds : 0;
    const double mean_mb = paced.received ? paced.megabytes / paced.received : 0;

    std::printf("transport: two processes, DDS loopback profile, domain %u, %s\n", o.domain,
                o.security_site.empty() ? "no DDS Security" : ("DDS Security (site " + o.security_site + ")").c_str());
    std::printf("  paced %.0f Hz for %.0f s: %u of %u frames delivered (%.1f %%), %.2f MB/frame, %.1f Mbit/s\n",
                o.rate_hz, o.seconds, paced.received, sent, delivered, mean_mb,
                paced.seconds > 0 ? paced.megabytes * 8 / paced.seconds : 0);
    std::printf("  latency write->take: p50 %.2f ms, p99 %.2f ms, max %.2f ms\n", percentile(paced.latency_ms, 0.5),
                percentile(paced.latency_ms, 0.99), paced.latency_ms.empty() ? 0 : paced.latency_ms.back());
    std::printf(
        "  CPU while paced: reader %.1f %% of a core, writer %.1f %%; publisher %.1f s in all (incl. payload "
        "prep)\n",
        100 * reader_cpu, 100 * writer_cpu, cpuSeconds(child_usage));
    std::printf("  flat out (keep-all, back-pressure): %u frames in %.2f s = %.0f frames/s\n", flat.received,
                flat.seconds, flat_fps);
    if (o.json) {
        std::printf(
            "{\"delivered\": %.2f, \"p50_ms\": %.3f, \"p99_ms\": %.3f, \"max_ms\": %.3f, \"fps\": %.1f, "
            "\"reader_cpu\": %.3f, \"writer_cpu\": %.3f, \"publisher_cpu_s\": %.2f, \"frame_mb\": %.3f}\n",
            delivered, percentile(paced.latency_ms, 0.5), percentile(paced.latency_ms, 0.99),
            paced.latency_ms.empty() ? 0 : paced.latency_ms.back(), flat_fps, reader_cpu, writer_cpu,
            cpuSeconds(child_usage), mean_mb);
    }
    return delivered >= 100.0 ? 0 : 1;
}

FACESCAN_BENCH_COMMAND("transport", "agent-sized RGB-D stream between two processes over DDS (loopback)", runTransport);

}  // namespace
}  // namespace facescan::bench
