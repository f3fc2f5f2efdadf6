#include "service/cluster.hpp"

#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <random>

#include "service/session.hpp"

namespace facescan::service {
namespace {

// Re-announced at least this often (load, uptime). A takeover waits for an announcement from most servers after
// the owner's lapse (Server::witnessed), so this period is part of every takeover's time: at half a second, the
// chaos runs' slowest live resumes missed lease + 2 s by 0.1 s. A few hundred bytes a second per peer.
constexpr int64_t kAnnouncePeriodNs = 250'000'000;

std::string hostName() {
    char name[256] = {};
    if (gethostname(name, sizeof(name) - 1) != 0) return "host";
    return name;
}

int64_t processCpuNs() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return (static_cast<int64_t>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) * 1'000'000'000) +
           static_cast<int64_t>(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1000;
}

// A process of this host that no longer exists (a server killed and restarted here with the same id).
bool deadLocalProcess(const wire::ServerAnnounceData& a) {
    return a.host == hostName() && a.pid != 0 && ::kill(static_cast<pid_t>(a.pid), 0) != 0 && errno == ESRCH;
}

}  // namespace

Claim::Claim(wire::Writer<facescan_wire_SessionOwner> writer, wire::SessionOwnerData record,
             std::function<bool()> progressing)
    : writer_(std::move(writer)), record_(std::move(record)), progressing_(std::move(progressing)) {
    std::lock_guard lk(mutex_);
    publishLocked();
}

wire::SessionOwnerData Claim::record() const {
    std::lock_guard lk(mutex_);
    return record_;
}

bool Claim::changed(const wire::SessionOwnerData& b) const {
    const wire::SessionOwnerData& a = record_;
    return a.owner_id != b.owner_id || a.standby_id != b.standby_id || a.epoch != b.epoch || a.state != b.state ||
           a.resume_seq != b.resume_seq || a.replay_request != b.replay_request || a.confirmed_seq != b.confirmed_seq ||
           a.failovers != b.failovers || a.last_takeover_ms != b.last_takeover_ms;
}

void Claim::publishLocked() {
    if (progressing_ && !progressing_()) return;  // the record keeps the change; a later update publishes it
    record_.updated_ns = realtimeNowNs();
    if (const Status s = writer_.write(wire::toMessage(record_)); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: publishing the owner of '%s': %s\n", record_.session_id.c_str(),
                     s.toString().c_str());
    }
}

void Claim::release() {
    std::lock_guard lk(mutex_);
    record_.state = wire::OwnerState::kReleased;
    publishLocked();
    (void)writer_.dispose(wire::toMessage(record_));
}

wire::Writer<facescan_wire_SessionOwner> Claim::raise(wire::Writer<facescan_wire_SessionOwner> writer, uint32_t epoch,
                                                      uint32_t resume_seq) {
    std::lock_guard lk(mutex_);
    std::swap(writer_, writer);
    record_.epoch = epoch;
    record_.resume_seq = resume_seq;
    publishLocked();
    return writer;
}

Cluster::Cluster(Options options) : options_(std::move(options)) {}

Cluster::~Cluster() = default;

StatusOr<std::unique_ptr<Cluster>> Cluster::create(const wire::Participant& p, const Options& options) {
    RETURN_IF_ERROR(wire::validateServerId(options.server_id));
    std::unique_ptr<Cluster> c(new Cluster(options));
    ASSIGN_OR_RETURN(c->announce_topic_, wire::Topic<facescan_wire_ServerAnnounce>::create(p));
    ASSIGN_OR_RETURN(c->owner_topic_, wire::Topic<facescan_wire_SessionOwner>::create(p));
    const wire::Qos announce_qos = wire::withProgressLiveliness(wire::serverAnnounceQos(), options.lease_s);
    ASSIGN_OR_RETURN(c->announce_writer_,
                     wire::Writer<facescan_wire_ServerAnnounce>::create(*c->announce_topic_, &announce_qos));
    ASSIGN_OR_RETURN(c->announce_reader_, wire::Reader<facescan_wire_ServerAnnounce>::create(*c->announce_topic_));
    ASSIGN_OR_RETURN(c->owner_reader_, wire::Reader<facescan_wire_SessionOwner>::create(*c->owner_topic_));
    std::random_device rd;
    wire::ServerAnnounceData& self = c->self_;
    self.server_id = options.server_id;
    self.host = hostName();
    self.pid = static_cast<uint32_t>(::getpid());
    self.incarnation = (static_cast<uint64_t>(rd()) << 32) ^ rd() ^ static_cast<uint64_t>(steadyNowNs());
    self.started_ns = realtimeNowNs();
    self.max_sessions = static_cast<uint32_t>(options.max_sessions);
    c->joined_after_ns_ = steadyNowNs() + static_cast<int64_t>(options.join_settle_s * 1e9);
    c->cpu_last_ns_ = processCpuNs();
    c->cpu_wall_ns_ = steadyNowNs();
    c->announce(0, 0, /*force=*/true);
    return c;
}

bool Cluster::joined() const { return steadyNowNs() >= joined_after_ns_; }

void Cluster::announce(int open_sessions, int standby_sessions, bool force) {
    std::lock_guard lk(mutex_);
    const int64_t now = steadyNowNs();
    const bool joining = now < joined_after_ns_;
    if (!force && open_sessions == last_open_ && standby_sessions == last_standby_ && joining == last_joining_ &&
        now - last_announce_ns_ < kAnnouncePeriodNs) {
        return;
    }
    const int64_t cpu = processCpuNs();
    if (now - cpu_wall_ns_ > 200'000'000) {  // load over at least 0.2 s
        self_.cpu_load =
            static_cast<float>(static_cast<double>(cpu - cpu_last_ns_) / static_cast<double>(now - cpu_wall_ns_));
        cpu_last_ns_ = cpu;
        cpu_wall_ns_ = now;
    }
    self_.open_sessions = static_cast<uint32_t>(open_sessions);
    self_.standby_sessions = static_cast<uint32_t>(standby_sessions);
    self_.joining = joining;
    last_open_ = open_sessions;
    last_standby_ = standby_sessions;
    last_joining_ = joining;
    last_announce_ns_ = now;
    if (const Status s = announce_writer_->write(wire::toMessage(self_)); !s.isOk()) {
        std::fprintf(stderr, "facescan-server: announcing: %s\n", s.toString().c_str());
    }
}

void Cluster::withdraw() {
    std::lock_guard lk(mutex_);
    (void)announce_writer_->dispose(wire::toMessage(self_));
}

Status Cluster::poll() {
    RETURN_IF_ERROR(takeAnnouncements());
    takeOwners();
    return Status::ok();
}

Status Cluster::checkDuplicate(const wire::ServerAnnounceData& other) const {
    if (other.incarnation == self_.incarnation) return Status::ok();  // our own announcement
    if (deadLocalProcess(other)) return Status::ok();                 // our killed predecessor: its lease lapses
    // Whoever started first keeps the id; the other refuses (both see both, so exactly one of them stops).
    const bool other_first = other.started_ns != self_.started_ns ? other.started_ns < self_.started_ns
                                                                  : other.incarnation < self_.incarnation;
    if (!other_first) return Status::ok();
    const double up_s = static_cast<double>(realtimeNowNs() - other.started_ns) * 1e-9;
    char up[32];
    std::snprintf(up, sizeof(up), "%.0f", std::max(0.0, up_s));
    return Status(StatusCode::kAlreadyExists, "another facescan-server named '" + other.server_id +
                                                  "' is already running on " + options_.domain.profile + " domain " +
                                                  std::to_string(options_.domain.domain_id) + " (host " + other.host +
                                                  ", pid " + std::to_string(other.pid) + ", up " + up +
                                                  " s): give this one another --server-id");
}

Status Cluster::takeAnnouncements() {
    Status refusal;
    std::lock_guard lk(mutex_);
    auto n = announce_reader_->take(
        [&](const facescan_wire_ServerAnnounce& m, const dds_sample_info_t& info) {
            const std::string id = wire::fromDds(m.server_id);  // keys are valid in invalid samples too
            if (!info.valid_data) {
                if (auto it = peers_.find(id); it != peers_.end() && info.instance_state != DDS_IST_ALIVE) {
                    it->second.alive = false;
                    it->second.seen_ns = steadyNowNs();
                }
                return;
            }
            auto a = wire::fromMessage(m);
            if (!a.isOk()) {
                std::fprintf(stderr, "facescan-server: ignoring an announcement: %s\n", a.status().message().c_str());
                return;
            }
            if (a->server_id == options_.server_id && info.instance_state == DDS_IST_ALIVE && refusal.isOk()) {
                refusal = checkDuplicate(*a);
            }
            if (a->protocol_version != wire::kClusterProtocolVersion && a->server_id != options_.server_id) {
                int64_t& logged = incompatible_logged_[a->server_id];
                if (logged == 0) {
                    std::fprintf(stderr,
                                 "facescan-server: server '%s' (%s) speaks cluster protocol %u, this one %u: it is "
                                 "not used as a peer; run the same facescan version on every server\n",
                                 a->server_id.c_str(), a->software.c_str(), a->protocol_version,
                                 wire::kClusterProtocolVersion);
                    logged = 1;
                }
            }
            if (a->server_id == options_.server_id && a->incarnation != self_.incarnation) return;
            PeerView& p = peers_[a->server_id];
            if (p.announce.incarnation != a->incarnation) {
                p.previous_incarnation = p.announce.incarnation;
                p.previous_heard_ns = p.heard_ns;
                p.incarnation_since_ns = steadyNowNs();
            }
            p.announce = std::move(*a);
            p.alive = info.instance_state == DDS_IST_ALIVE;
            p.seen_ns = p.heard_ns = steadyNowNs();
        },
        256);
    if (!n.isOk()) std::fprintf(stderr, "facescan-server: %s\n", n.status().toString().c_str());
    return refusal;
}

void Cluster::takeOwners() {
    std::lock_guard lk(mutex_);
    auto n = owner_reader_->take(
        [&](const facescan_wire_SessionOwner& m, const dds_sample_info_t& info) {
            const std::string id = wire::fromDds(m.session_id);
            if (!info.valid_data) {
                if (auto it = owners_.find(id); it != owners_.end() && info.instance_state != DDS_IST_ALIVE) {
                    it->second.alive = false;
                    it->second.disposed = info.instance_state == DDS_IST_NOT_ALIVE_DISPOSED;
                    it->second.seen_ns = steadyNowNs();
                }
                return;
            }
            auto o = wire::fromMessage(m);
            if (!o.isOk()) {
                std::fprintf(stderr, "facescan-server: ignoring a claim: %s\n", o.status().message().c_str());
                return;
            }
            OwnerView& v = owners_[id];
            v.data = std::move(*o);
            v.alive = info.instance_state == DDS_IST_ALIVE;
            v.disposed = info.instance_state == DDS_IST_NOT_ALIVE_DISPOSED;
            v.seen_ns = steadyNowNs();
        },
        1024);
    if (!n.isOk()) std::fprintf(stderr, "facescan-server: %s\n", n.status().toString().c_str());
}

int Cluster::othersAlive() const {
    std::lock_guard lk(mutex_);
    int n = 0;
    for (const auto& [id, p] : peers_) n += p.alive && id != options_.server_id ? 1 : 0;
    return n;
}

namespace {
constexpr int64_t kForgetNs = 600'000'000'000;  // a server gone this long is no longer counted
}  // namespace

int Cluster::othersKnown() const {
    std::lock_guard lk(mutex_);
    const int64_t now = steadyNowNs();
    int n = 0;
    for (const auto& [id, p] : peers_) n += id != options_.server_id && (p.alive || now - p.seen_ns < kForgetNs);
    return n;
}

int Cluster::othersHeardSince(int64_t since_ns) const {
    std::lock_guard lk(mutex_);
    int n = 0;
    for (const auto& [id, p] : peers_) n += id != options_.server_id && p.alive && p.heard_ns >= since_ns ? 1 : 0;
    return n;
}

bool Cluster::seesMajority() const {
    std::lock_guard lk(mutex_);
    const int64_t now = steadyNowNs();
    int alive = 0, known = 0;
    for (const auto& [id, p] : peers_) {
        if (p.alive) ++alive;
        if (p.alive || now - p.seen_ns < kForgetNs) ++known;
    }
    return 2 * alive > known;
}

std::vector<PeerView> Cluster::peers() const {
    std::lock_guard lk(mutex_);
    std::vector<PeerView> out;
    for (const auto& [id, p] : peers_) out.push_back(p);
    return out;
}

bool Cluster::serverAlive(const std::string& server_id) const {
    std::lock_guard lk(mutex_);
    const auto it = peers_.find(server_id);
    return it != peers_.end() && it->second.alive;
}

bool Cluster::diedOnThisHost(const std::string& server_id) const {
    std::lock_guard lk(mutex_);
    const auto it = peers_.find(server_id);
    return it != peers_.end() && deadLocalProcess(it->second.announce);
}

bool Cluster::replaced(const std::string& server_id, uint64_t incarnation) const {
    // Both processes alive and in view would alternate in peers_ (each announces four times a second), and the second
    // would restart the count each time: a second of the new one alone means the old one is silent. It is not
    // merely cut off from this server: the new one could only start once the old one had let go of the id.
    constexpr int64_t kAloneNs = 1'000'000'000;
    if (incarnation == 0) return false;
    std::lock_guard lk(mutex_);
    const auto it = peers_.find(server_id);
    return it != peers_.end() && it->second.alive && it->second.announce.incarnation != incarnation &&
           steadyNowNs() - it->second.incarnation_since_ns >= kAloneNs;
}

int64_t Cluster::lastHeard(const std::string& server_id, uint64_t incarnation) const {
    std::lock_guard lk(mutex_);
    const auto it = peers_.find(server_id);
    if (it == peers_.end() || incarnation == 0) return 0;
    if (it->second.announce.incarnation == incarnation) return it->second.heard_ns;
    return it->second.previous_incarnation == incarnation ? it->second.previous_heard_ns : 0;
}

int64_t Cluster::lastHeard(const std::string& server_id) const {
    std::lock_guard lk(mutex_);
    const auto it = peers_.find(server_id);
    return it == peers_.end() ? 0 : it->second.heard_ns;
}

std::vector<ServerLoad> Cluster::liveLoads() const {
    std::lock_guard lk(mutex_);
    std::map<std::string, int> open;
    for (const auto& [id, o] : owners_) {
        const bool holds = o.data.state == wire::OwnerState::kClaiming || o.data.state == wire::OwnerState::kReady ||
                           o.data.state == wire::OwnerState::kActive;
        if (o.alive && holds) ++open[o.data.owner_id];
    }
    std::vector<ServerLoad> out;
    for (const auto& [id, p] : peers_) {
        const wire::ServerAnnounceData& a = p.announce;
        if (!p.alive || a.joining || a.protocol_version != wire::kClusterProtocolVersion) {
            continue;
        }
        out.push_back({id, static_cast<int>(a.max_sessions), open[id], static_cast<int>(a.standby_sessions)});
    }
    return out;
}

std::optional<OwnerView> Cluster::owner(const std::string& session_id) const {
    std::lock_guard lk(mutex_);
    const auto it = owners_.find(session_id);
    if (it == owners_.end()) return std::nullopt;
    return it->second;
}

std::map<std::string, OwnerView> Cluster::owners() const {
    std::lock_guard lk(mutex_);
    return owners_;
}

std::string Cluster::responder() const {
    const std::vector<ServerLoad> live = liveLoads();
    std::string lowest = joined() ? options_.server_id : std::string();
    for (const ServerLoad& s : live) {
        if (lowest.empty() || s.server_id < lowest) lowest = s.server_id;
    }
    return lowest;
}

StatusOr<wire::Writer<facescan_wire_SessionOwner>> Cluster::claimWriter(uint32_t epoch,
                                                                        const std::string& session_id) const {
    const wire::Qos qos = wire::withClaimLiveliness(
        wire::claimWriterQos(wire::claimStrength(epoch, options_.server_id, session_id)), options_.lease_s);
    return wire::Writer<facescan_wire_SessionOwner>::create(*owner_topic_, &qos);
}

StatusOr<wire::Writer<facescan_wire_SessionOwner>> Cluster::raise(Claim& claim, uint32_t epoch, uint32_t resume_seq) {
    ASSIGN_OR_RETURN(auto writer, claimWriter(epoch, claim.record().session_id));
    return claim.raise(std::move(writer), epoch, resume_seq);
}

StatusOr<std::unique_ptr<Claim>> Cluster::claim(const wire::SessionOwnerData& initial) {
    ASSIGN_OR_RETURN(auto writer, claimWriter(initial.epoch, initial.session_id));
    wire::SessionOwnerData record = initial;
    record.owner_incarnation = self_.incarnation;  // which process of this id holds it (Cluster::replaced)
    return std::make_unique<Claim>(std::move(writer), std::move(record), options_.progressing);
}

}  // namespace facescan::service
