// On the wire: every UDP payload on loopback is captured with a raw packet socket while the real agent streams
// frames whose depth bytes spell a known pattern (a TUM folder of pattern images, raw16 depth codec, no colour)
// to the real server. With DDS Security the pattern never appears in clear; without it, it does (so the check
// can fail). Capturing needs CAP_NET_RAW (root, as CI runs); elsewhere the test skips and says so.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <linux/if_ether.h>
#include <net/if.h>
#include <netinet/ip.h>
#include <netinet/udp.h>
#include <netpacket/packet.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string_view>
#include <thread>

#include "child_process.hpp"
#include "site_fixture.hpp"
#include "test_domain.hpp"

namespace {

namespace fs = std::filesystem;
namespace ft = facescan::testing;
using namespace std::chrono_literals;

// 16 bytes, 8 little-endian depth pixels, repeated along every row of every frame.
constexpr std::string_view kPattern = "FaceScanSecret!!";
constexpr int kWidth = 320, kHeight = 240, kFrames = 3;

// A TUM RGB-D folder (depth only) whose every depth image repeats kPattern.
void writePatternSequence(const fs::path& dir) {
    fs::create_directories(dir / "depth");
    cv::Mat depth(kHeight, kWidth, CV_16UC1);
    for (int y = 0; y < kHeight; ++y) {
        for (int x = 0; x < kWidth; ++x) {
            const size_t i = (static_cast<size_t>(x) * 2) % kPattern.size();
            depth.at<uint16_t>(y, x) =
                static_cast<uint16_t>(static_cast<uint8_t>(kPattern[i]) | (static_cast<uint8_t>(kPattern[i + 1]) << 8));
        }
    }
    std::ofstream list(dir / "depth.txt");
    for (int f = 0; f < kFrames; ++f) {
        const std::string name = "depth/" + std::to_string(f) + ".png";
        ASSERT_TRUE(cv::imwrite((dir / name).string(), depth));
        list << f / 30.0 << " " << name << "\n";
    }
}

// UDP payloads to and from one DDS domain's ports on the loopback interface, taken by a raw packet socket.
class LoopbackCapture {
 public:
    // errno of the socket when it cannot be opened (EPERM without CAP_NET_RAW).
    int open(uint32_t domain) {
        // RTPS port mapping: 7400 + 250 * domain, plus offsets up to 10 + 2 * 120 + 1 (participant indices).
        port_lo_ = static_cast<uint16_t>(7400 + 250 * domain);
        port_hi_ = static_cast<uint16_t>(port_lo_ + 251);
        fd_ = ::socket(AF_PACKET, SOCK_DGRAM, htons(ETH_P_IP));
        if (fd_ < 0) return errno;
        sockaddr_ll where{};
        where.sll_family = AF_PACKET;
        where.sll_protocol = htons(ETH_P_IP);
        where.sll_ifindex = static_cast<int>(if_nametoindex("lo"));
        if (::bind(fd_, reinterpret_cast<sockaddr*>(&where), sizeof(where)) != 0) return errno;
        const int buffer = 32 << 20;
        ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUFFORCE, &buffer, sizeof(buffer));
        const timeval wait{0, 100'000};
        ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &wait, sizeof(wait));
        thread_ = std::thread([this] { run(); });
        return 0;
    }
    ~LoopbackCapture() {
        stop();
        if (fd_ >= 0) ::close(fd_);
    }
    void stop() {
        stop_ = true;
        if (thread_.joinable()) thread_.join();
    }
    size_t payloadBytes() const { return bytes_; }
    size_t datagrams() const { return datagrams_; }
    size_t patternHits() const { return hits_; }

 private:
    void run() {
        std::vector<uint8_t> packet(1 << 17);
        while (!stop_) {
            const ssize_t n = ::recv(fd_, packet.data(), packet.size(), 0);
            if (n < static_cast<ssize_t>(sizeof(iphdr))) continue;
            const auto* ip = reinterpret_cast<const iphdr*>(packet.data());
            const size_t ip_len = ip->ihl * 4u;
            if (ip->version != 4 || ip->protocol != IPPROTO_UDP || static_cast<size_t>(n) < ip_len + sizeof(udphdr)) {
                continue;
            }
            const auto* udp = reinterpret_cast<const udphdr*>(packet.data() + ip_len);
            const uint16_t src = ntohs(udp->source), dst = ntohs(udp->dest);
            if (!inRange(src) && !inRange(dst)) continue;
            const size_t udp_len = std::min<size_t>(ntohs(udp->len), static_cast<size_t>(n) - ip_len);
            if (udp_len < sizeof(udphdr)) continue;
            const std::string_view payload(reinterpret_cast<const char*>(udp) + sizeof(udphdr),
                                           udp_len - sizeof(udphdr));
            bytes_ += payload.size();
            ++datagrams_;
            for (size_t at = payload.find(kPattern); at != std::string_view::npos;
                 at = payload.find(kPattern, at + 1)) {
                ++hits_;
            }
        }
    }
    bool inRange(uint16_t port) const { return port >= port_lo_ && port <= port_hi_; }

    int fd_ = -1;
    uint16_t port_lo_ = 0, port_hi_ = 0;
    std::thread thread_;
    std::atomic<bool> stop_{false};
    std::atomic<size_t> bytes_{0}, datagrams_{0}, hits_{0};
};

struct WireRun {
    int agent_exit = -1;
    std::string agent_log;
    size_t bytes = 0, datagrams = 0, hits = 0;
};

// The real server and agent on `domain` (secured when `site` is given) while the capture runs.
WireRun streamPattern(uint32_t domain, const fs::path& sequence, const fs::path& dir, const ft::TempSite* site,
                      const std::string& tag) {
    WireRun run;
    LoopbackCapture capture;
    const int error = capture.open(domain);
    if (error != 0) {
        run.agent_log = std::string("cannot capture on lo: ") + std::strerror(error);
        return run;
    }
    std::vector<std::string> dds{"--profile", "loopback", "--domain", std::to_string(domain)};
    std::vector<std::string> server_args{FACESCAN_SERVER_BIN, "--data-dir", (dir / (tag + "_data")).string()};
    std::vector<std::string> agent_args{FACESCAN_AGENT_BIN,
                                        "--source",
                                        "tum:" + sequence.string(),
                                        "--depth-codec",
                                        "raw16",
                                        "--no-colour",
                                        "--rate",
                                        "max",
                                        "--wait-for-server",
                                        "30",
                                        "--session",
                                        tag + "-" + std::to_string(::getpid())};
    server_args.insert(server_args.end(), dds.begin(), dds.end());
    agent_args.insert(agent_args.end(), dds.begin(), dds.end());
    if (site) {
        server_args.insert(server_args.end(), {"--security", site->identity("server").string()});
        agent_args.insert(agent_args.end(), {"--security", site->identity("agent").string()});
    }
    ft::ChildProcess server(server_args, dir / (tag + "_server.log"));
    ft::ChildProcess agent(agent_args, dir / (tag + "_agent.log"));
    run.agent_exit = agent.wait(60s);
    server.stop();
    capture.stop();
    run.agent_log = ft::readText(dir / (tag + "_agent.log"));
    run.bytes = capture.payloadBytes();
    run.datagrams = capture.datagrams();
    run.hits = capture.patternHits();
    return run;
}

TEST(SecureWire, AKnownFramePatternAppearsInClearWithoutSecurityAndNeverWithIt) {
    {
        const int probe = ::socket(AF_PACKET, SOCK_DGRAM, htons(ETH_P_IP));
        if (probe < 0) {
            GTEST_SKIP() << "capturing loopback packets needs CAP_NET_RAW (" << std::strerror(errno)
                         << "): run the tests as root, as CI does";
        }
        ::close(probe);
    }
    ft::TempSite site("wire");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const fs::path sequence = site.root() / "pattern";
    writePatternSequence(sequence);
    const size_t frame_bytes = static_cast<size_t>(kWidth) * kHeight * 2;

    const WireRun plain = streamPattern(ft::privateDomain(1), sequence, site.root(), nullptr, "plain");
    ASSERT_EQ(plain.agent_exit, 0) << plain.agent_log;
    EXPECT_GE(plain.bytes, kFrames * frame_bytes) << "the frames were not captured";
    EXPECT_GT(plain.hits, 0u) << "without security the frame bytes are on the wire in clear";

    const WireRun secure = streamPattern(ft::privateDomain(2), sequence, site.root(), &site, "secure");
    ASSERT_EQ(secure.agent_exit, 0) << secure.agent_log;
    EXPECT_NE(secure.agent_log.find("server found"), std::string::npos) << secure.agent_log;
    EXPECT_GE(secure.bytes, kFrames * frame_bytes) << "the (encrypted) frames were not captured";
    EXPECT_EQ(secure.hits, 0u) << "the pattern was seen in clear with DDS Security on";
    std::printf(
        "on the wire: without security %zu datagrams, %zu bytes, pattern seen %zu times; with security %zu "
        "datagrams, %zu bytes, pattern seen %zu times\n",
        plain.datagrams, plain.bytes, plain.hits, secure.datagrams, secure.bytes, secure.hits);
}

}  // namespace
