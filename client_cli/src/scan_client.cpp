// The client side of the scan protocol over DDS (notes/protocol.md).
#include "client/scan_client.hpp"

#include <unistd.h>

#include <random>
#include <set>
#include <thread>

#include "wire/dds_options.hpp"
#include "wire/security.hpp"

namespace facescan::client {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

std::vector<uint8_t> copyBytes(const dds_sequence_octet& seq) {
    if (!seq._buffer || seq._length == 0) return {};
    return std::vector<uint8_t>(seq._buffer, seq._buffer + seq._length);
}

SessionStatus fromMessage(const facescan_wire_ScanStatus& m) {
    SessionStatus s;
    static_cast<wire::ScanStatusData&>(s) = wire::fromMessage(m);
    return s;
}

milliseconds remaining(Clock::time_point deadline) {
    return std::max(milliseconds(0), std::chrono::duration_cast<milliseconds>(deadline - Clock::now()));
}

// The source time stamp DDS puts on a sample is the writer's wall clock.
int64_t wallNowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
        .count();
}

}  // namespace

// Where a keyed sample came from: its writer, and when it was written (the writer's clock).
struct SampleOrigin {
    dds_instance_handle_t writer = 0;
    int64_t source_ns = 0;
};

const char* scanStateName(facescan_wire_ScanState state) {
    switch (state) {
        case facescan_wire_STATE_WAITING: return "WAITING";
        case facescan_wire_STATE_SCANNING: return "SCANNING";
        case facescan_wire_STATE_LOST: return "LOST";
        case facescan_wire_STATE_FINISHED: return "FINISHED";
        case facescan_wire_STATE_REFUSED: return "REFUSED";
    }
    return "UNKNOWN";
}

const char* commandKindName(facescan_wire_CommandKind kind) {
    switch (kind) {
        case facescan_wire_CMD_RESET: return "reset";
        case facescan_wire_CMD_FINISH: return "finish";
        case facescan_wire_CMD_GET_MESH: return "get mesh";
        case facescan_wire_CMD_GET_TRAJECTORY: return "get trajectory";
        case facescan_wire_CMD_GET_PREVIEW: return "get preview";
        case facescan_wire_CMD_GET_STATUS: return "get status";
    }
    return "unknown command";
}

std::string noServerMessage(const wire::DomainConfig& domain) {
    return "no server answered on domain " + std::to_string(domain.domain_id) + " (profile " + domain.profile +
           "): is facescan-server running? " + wire::noPeerHint(domain);
}

Status ClientConfig::validate() const {
    RETURN_IF_ERROR(domain.validate());
    if (timeout.count() <= 0) return invalidArgument("timeout must be positive");
    if (grace.count() < 0 || discovery_settle.count() < 0) return invalidArgument("grace and settle must be >= 0");
    return Status::ok();
}

struct ScanClient::Endpoints {
    explicit Endpoints(wire::Participant p) : participant(std::move(p)) {}

    // Declared first so that it is destroyed last (deleting a participant deletes its children).
    wire::Participant participant;
    // Made on first request (never in a client that only reads: ClientConfig::commands): a read-only identity
    // (DDS Security role viewer) may not even create the command topics, yet watches.
    std::optional<wire::Topic<facescan_wire_ScanCommand>> command_topic;
    std::optional<wire::Topic<facescan_wire_ScanReply>> reply_topic;
    std::optional<wire::Writer<facescan_wire_ScanCommand>> command_writer;
    std::optional<wire::Reader<facescan_wire_ScanReply>> reply_reader;
    std::optional<wire::Topic<facescan_wire_ScanStatus>> status_topic;
    std::optional<wire::Reader<facescan_wire_ScanStatus>> status_reader;
    std::optional<wire::Topic<facescan_wire_MeshSnapshot>> snapshot_topic;
    std::optional<wire::Reader<facescan_wire_MeshSnapshot>> snapshot_reader;
    std::optional<wire::WaitSet> followed;  // the status and snapshot readers: poll wakes for either
    std::map<dds_instance_handle_t, std::string> status_instances;  // for not-alive notices, which carry no data
    std::optional<wire::Topic<facescan_wire_ServerAnnounce>> announce_topic;
    std::optional<wire::Reader<facescan_wire_ServerAnnounce>> announce_reader;
    std::optional<wire::Topic<facescan_wire_SessionOwner>> owner_topic;
    std::optional<wire::Reader<facescan_wire_SessionOwner>> owner_reader;
    std::optional<wire::Topic<facescan_wire_EraseRequest>> erase_topic;
    std::optional<wire::Reader<facescan_wire_EraseRequest>> erase_reader;
    std::set<std::string> erased;  // sessions takeErased() has reported
    std::map<std::string, ServerInfo> servers;
    std::map<std::string, SampleOrigin> server_writers;  // each server's latest announcement: writer and stamp
    std::map<std::string, OwnerInfo> owners;
    bool server_seen = false;          // a server's ScanStatus writer is matched
    bool command_server_seen = false;  // a server's command endpoints are matched
};

ScanClient::ScanClient(ClientConfig config) : config_(std::move(config)) {}
ScanClient::~ScanClient() = default;

StatusOr<std::unique_ptr<ScanClient>> ScanClient::connect(const ClientConfig& config) {
    RETURN_IF_ERROR(config.validate());
    std::unique_ptr<ScanClient> client(new ScanClient(config));
    ASSIGN_OR_RETURN(wire::Participant participant, wire::Participant::create(config.domain));
    client->endpoints_ = std::make_unique<Endpoints>(std::move(participant));
    // Unique across clients and hosts: pid + random; the counter makes it unique per request.
    std::random_device rd;
    char host[64] = {};
    ::gethostname(host, sizeof(host) - 1);
    client->client_id_ = std::string(host) + ":" + std::to_string(::getpid()) + ":" + std::to_string(rd() % 1000000);
    // Servers record who sent each command in their audit trail: the DDS Security identity's name leads the id
    // (only enrolled identities may send commands on a secured domain).
    if (!config.domain.security.empty()) {
        if (auto identity = wire::checkIdentity(config.domain.security); identity.isOk()) {
            client->client_id_ = identity->name + "@" + client->client_id_;
        }
    }
    return client;
}

Status ScanClient::readOnly() const {
    return unavailable("this client only reads status and snapshots (it has no command endpoints)");
}

std::string ScanClient::nextRequestId() { return client_id_ + ":" + std::to_string(++request_counter_); }

Status ScanClient::waitForServer() {
    Endpoints& e = *endpoints_;
    if (e.server_seen) return Status::ok();
    // Every server publishes ScanStatus from its start; reading it is what every role of a secured site may do.
    RETURN_IF_ERROR(ensureStatusReader());
    const auto deadline = Clock::now() + config_.timeout;
    if (!e.status_reader->waitForWriters(1, config_.timeout)) return deadlineExceeded(noServerMessage(config_.domain));
    // Other servers on the domain are discovered at about the same time; give them a moment too.
    std::this_thread::sleep_for(std::min(config_.discovery_settle, remaining(deadline)));
    e.server_seen = true;
    return Status::ok();
}

Status ScanClient::enableCommands() {
    Endpoints& e = *endpoints_;
    if (e.command_writer && e.reply_reader) return Status::ok();
    if (!config_.commands) return readOnly();
    Status made = [&]() -> Status {
        ASSIGN_OR_RETURN(auto command_topic, wire::Topic<facescan_wire_ScanCommand>::create(e.participant));
        e.command_topic.emplace(std::move(command_topic));
        ASSIGN_OR_RETURN(auto reply_topic, wire::Topic<facescan_wire_ScanReply>::create(e.participant));
        e.reply_topic.emplace(std::move(reply_topic));
        ASSIGN_OR_RETURN(auto writer, wire::Writer<facescan_wire_ScanCommand>::create(*e.command_topic));
        e.command_writer.emplace(std::move(writer));
        ASSIGN_OR_RETURN(auto reader, wire::Reader<facescan_wire_ScanReply>::create(*e.reply_topic));
        e.reply_reader.emplace(std::move(reader));
        return Status::ok();
    }();
    if (made.code() == StatusCode::kPermissionDenied) {
        return permissionDenied("DDS Security access control refused: identity " + config_.domain.security +
                                " may not send commands to servers (its role's permissions: " + made.message() + ")");
    }
    return made;
}

Status ScanClient::waitForCommandServer() {
    Endpoints& e = *endpoints_;
    RETURN_IF_ERROR(enableCommands());
    if (e.command_server_seen) return Status::ok();
    // Every server reads ScanCommand and writes ScanReply: both directions must be matched before a command is
    // sent, or the (volatile) command or its reply would go to nobody.
    const auto deadline = Clock::now() + config_.timeout;
    const bool found =
        wire::pollUntil([&] { return e.command_writer->matchedReaders() > 0 && e.reply_reader->matchedWriters() > 0; },
                        config_.timeout);
    if (!found) return deadlineExceeded(noServerMessage(config_.domain));
    // Other servers on the domain are discovered at about the same time; give them a moment so that the
    // command reaches the one that owns the session.
    std::this_thread::sleep_for(std::min(config_.discovery_settle, remaining(deadline)));
    e.command_server_seen = true;
    return Status::ok();
}

StatusOr<CommandReply> ScanClient::request(const std::string& session_id, facescan_wire_CommandKind kind,
                                           bool want_texture) {
    RETURN_IF_ERROR(waitForCommandServer());
    Endpoints& e = *endpoints_;
    const std::string request_id = nextRequestId();
    facescan_wire_ScanCommand command{};
    command.session_id = wire::stringView(session_id);
    command.request_id = wire::stringView(request_id);
    command.client_id = wire::stringView(client_id_);
    command.kind = kind;
    command.want_texture = want_texture;
    RETURN_IF_ERROR(e.command_writer->write(command));

    const auto deadline = Clock::now() + config_.timeout;
    std::optional<Clock::time_point> error_deadline;
    std::optional<CommandReply> ok_reply;
    std::optional<CommandReply> error_reply;
    while (!ok_reply) {
        const auto now = Clock::now();
        if (error_deadline && now >= *error_deadline) break;
        if (now >= deadline) break;
        auto until = error_deadline ? std::min(*error_deadline, deadline) : deadline;
        e.reply_reader->waitForData(std::min(milliseconds(100), remaining(until)));
        auto taken = e.reply_reader->take(
            [&](const facescan_wire_ScanReply& r, const dds_sample_info_t& info) {
                if (!info.valid_data || wire::fromDds(r.request_id) != request_id) return;
                CommandReply reply;
                reply.session_id = wire::fromDds(r.session_id);
                reply.server_id = wire::fromDds(r.server_id);
                reply.ok = r.ok;
                reply.error = wire::fromDds(r.error);
                reply.vertex_count = r.vertex_count;
                reply.triangle_count = r.triangle_count;
                if (r.ok) {
                    reply.payload = copyBytes(r.payload);
                    reply.texture = copyBytes(r.texture);
                    if (!ok_reply) ok_reply = std::move(reply);
                } else if (!error_reply) {
                    error_reply = std::move(reply);
                    error_deadline = Clock::now() + config_.grace;
                }
            },
            64);
        if (!taken.isOk()) return taken.status();
    }
    if (ok_reply) return std::move(*ok_reply);
    if (error_reply) {
        const std::string& why = error_reply->error.empty() ? std::string("refused") : error_reply->error;
        if (why.starts_with("unknown session")) return notFound(why);
        return invalidArgument(std::string(commandKindName(kind)) + " '" + session_id + "': " + why);
    }
    return deadlineExceeded(noServerMessage(config_.domain) + " (no reply to " + commandKindName(kind) + " within " +
                            std::to_string(config_.timeout.count() / 1000.0).substr(0, 4) + " s)");
}

Status ScanClient::ensureStatusReader() {
    Endpoints& e = *endpoints_;
    if (e.status_reader) return Status::ok();
    ASSIGN_OR_RETURN(auto topic, wire::Topic<facescan_wire_ScanStatus>::create(e.participant));
    e.status_topic.emplace(std::move(topic));
    ASSIGN_OR_RETURN(auto reader, wire::Reader<facescan_wire_ScanStatus>::create(*e.status_topic));
    e.status_reader.emplace(std::move(reader));
    ASSIGN_OR_RETURN(auto waitset, wire::WaitSet::create(e.participant));
    e.followed.emplace(std::move(waitset));
    return e.followed->attach(*e.status_reader);
}

Status ScanClient::ensureSnapshotReader() {
    Endpoints& e = *endpoints_;
    if (e.snapshot_reader) return Status::ok();
    ASSIGN_OR_RETURN(auto topic, wire::Topic<facescan_wire_MeshSnapshot>::create(e.participant));
    e.snapshot_topic.emplace(std::move(topic));
    ASSIGN_OR_RETURN(auto reader, wire::Reader<facescan_wire_MeshSnapshot>::create(*e.snapshot_topic));
    e.snapshot_reader.emplace(std::move(reader));
    RETURN_IF_ERROR(ensureStatusReader());
    return e.followed->attach(*e.snapshot_reader);
}

Status ScanClient::takeStatuses(std::map<std::string, SessionStatus>& statuses) {
    Endpoints& e = *endpoints_;
    auto taken = e.status_reader->take(
        [&](const facescan_wire_ScanStatus& m, const dds_sample_info_t& info) {
            if (info.valid_data) {
                SessionStatus s = fromMessage(m);
                s.alive = info.instance_state == DDS_IST_ALIVE;
                e.status_instances[info.instance_handle] = s.session_id;
                statuses[s.session_id] = std::move(s);
                return;
            }
            // No data: the instance changed state (its server died or disposed it).
            const auto it = e.status_instances.find(info.instance_handle);
            if (it == e.status_instances.end()) return;
            if (auto st = statuses.find(it->second); st != statuses.end()) {
                st->second.alive = info.instance_state == DDS_IST_ALIVE;
            }
        },
        1024);
    return taken.isOk() ? Status::ok() : taken.status();
}

StatusOr<std::vector<SessionStatus>> ScanClient::sessions(milliseconds settle) {
    RETURN_IF_ERROR(ensureStatusReader());
    RETURN_IF_ERROR(waitForServer());
    Endpoints& e = *endpoints_;
    // Durable ScanStatus samples arrive right after the match; a server with sessions has a ScanStatus writer.
    const auto deadline = Clock::now() + settle;
    std::map<std::string, SessionStatus> statuses;
    while (Clock::now() < deadline) {
        e.status_reader->waitForData(std::min(milliseconds(50), remaining(deadline)));
        RETURN_IF_ERROR(takeStatuses(statuses));
    }
    std::vector<SessionStatus> out;
    for (auto& [id, s] : statuses) {
        if (s.alive) out.push_back(std::move(s));
    }
    return out;
}

Status ScanClient::poll(milliseconds wait, std::map<std::string, SessionStatus>& statuses,
                        const std::string& snapshot_session, std::vector<MeshSnapshotData>* snapshots) {
    RETURN_IF_ERROR(ensureStatusReader());
    Endpoints& e = *endpoints_;
    if (snapshots && !snapshot_session.empty()) RETURN_IF_ERROR(ensureSnapshotReader());
    e.followed->wait(wait);
    RETURN_IF_ERROR(takeStatuses(statuses));
    if (!e.snapshot_reader) return Status::ok();
    auto taken = e.snapshot_reader->take(
        [&](const facescan_wire_MeshSnapshot& m, const dds_sample_info_t& info) {
            if (!info.valid_data || !snapshots) return;
            if (snapshot_session != kAllSessions && wire::fromDds(m.session_id) != snapshot_session) return;
            MeshSnapshotData snap;
            snap.session_id = wire::fromDds(m.session_id);
            snap.seq = m.seq;
            snap.frames_integrated = m.frames_integrated;
            snap.vertex_count = m.vertex_count;
            snap.triangle_count = m.triangle_count;
            snap.created_ns = m.created_ns;
            snap.draco = copyBytes(m.draco);
            snap.received = Clock::now();
            snapshots->push_back(std::move(snap));
        },
        64);
    return taken.isOk() ? Status::ok() : taken.status();
}

StatusOr<std::vector<std::string>> ScanClient::takeErased() {
    Endpoints& e = *endpoints_;
    if (!e.erase_reader) {
        ASSIGN_OR_RETURN(auto topic, wire::Topic<facescan_wire_EraseRequest>::create(e.participant));
        e.erase_topic.emplace(std::move(topic));
        ASSIGN_OR_RETURN(auto reader, wire::Reader<facescan_wire_EraseRequest>::create(*e.erase_topic));
        e.erase_reader.emplace(std::move(reader));
    }
    std::vector<std::string> out;
    auto taken = e.erase_reader->take([&](const facescan_wire_EraseRequest& m, const dds_sample_info_t& info) {
        if (!info.valid_data) return;
        std::string id = wire::fromDds(m.session_id);
        if (wire::validateSessionId(id).isOk() && e.erased.insert(id).second) out.push_back(std::move(id));
    });
    if (!taken.isOk()) return taken.status();
    return out;
}

Status ScanClient::ensureClusterReaders() {
    Endpoints& e = *endpoints_;
    if (e.owner_reader) return Status::ok();
    ASSIGN_OR_RETURN(auto announce_topic, wire::Topic<facescan_wire_ServerAnnounce>::create(e.participant));
    e.announce_topic.emplace(std::move(announce_topic));
    ASSIGN_OR_RETURN(auto announce_reader, wire::Reader<facescan_wire_ServerAnnounce>::create(*e.announce_topic));
    e.announce_reader.emplace(std::move(announce_reader));
    ASSIGN_OR_RETURN(auto owner_topic, wire::Topic<facescan_wire_SessionOwner>::create(e.participant));
    e.owner_topic.emplace(std::move(owner_topic));
    ASSIGN_OR_RETURN(auto owner_reader, wire::Reader<facescan_wire_SessionOwner>::create(*e.owner_topic));
    e.owner_reader.emplace(std::move(owner_reader));
    return Status::ok();
}

namespace {

// Takes the samples of a cluster topic into `into` (by key); malformed ones are left out, not-alive notices
// mark the entry.
// `writers`, when given, gets the writer and time stamp of each key's latest valid sample, and `arrived` counts
// the valid samples per key.
template <typename Msg, typename Info>
Status takeKeyed(wire::Reader<Msg>& reader, std::map<std::string, Info>& into, char* Msg::*key,
                 std::map<std::string, SampleOrigin>* writers = nullptr,
                 std::map<std::string, int>* arrived = nullptr) {
    auto taken = reader.take(
        [&](const Msg& m, const dds_sample_info_t& info) {
            const std::string id = wire::fromDds(m.*key);
            if (!info.valid_data) {
                if (auto it = into.find(id); it != into.end()) it->second.alive = info.instance_state == DDS_IST_ALIVE;
                return;
            }
            auto parsed = wire::fromMessage(m);
            if (!parsed.isOk()) return;
            Info v;
            static_cast<decltype(*parsed)&>(v) = std::move(*parsed);
            v.alive = info.instance_state == DDS_IST_ALIVE;
            into[id] = std::move(v);
            if (writers) (*writers)[id] = SampleOrigin{info.publication_handle, info.source_timestamp};
            if (arrived) ++(*arrived)[id];
        },
        1024);
    return taken.isOk() ? Status::ok() : taken.status();
}

}  // namespace

StatusOr<std::vector<ServerInfo>> ScanClient::servers(milliseconds settle, milliseconds max_wait) {
    RETURN_IF_ERROR(ensureClusterReaders());
    Endpoints& e = *endpoints_;
    const auto start = Clock::now();
    const auto settled = start + settle;
    const auto deadline = start + std::max(settle, max_wait);
    // A working server writes its announcement at least once a second (cluster.cpp). A new reader gets the
    // last one at once and counts its writer alive until a lease passes without an assertion, longer than this
    // command lives; so whether a server still works is told by a fresh announcement instead: one stamped in the
    // last kFresh by the server's clock, or a second one arriving while we listen. A clock that is off only costs
    // waiting up to kListen for that second one, never a wrong verdict.
    constexpr auto kFresh = milliseconds(2000);
    constexpr auto kListen = milliseconds(2500);
    std::map<std::string, int> arrived;  // announcements received during this call, by server
    const auto fresh = [&](const std::string& id) {
        const auto seen = e.server_writers.find(id);
        if (seen == e.server_writers.end()) return false;
        const int64_t age_ns = wallNowNs() - seen->second.source_ns;
        return arrived[id] >= 2 || (age_ns >= 0 && age_ns < std::chrono::nanoseconds(kFresh).count());
    };
    // Announcements are durable: they come right after discovery; then a moment for the others. Each server
    // has one announcement writer, so a matched writer not yet heard from is a server whose announcement is
    // still on its way: on a loaded host that can take longer than the settle time, and a listing (or an erasure)
    // that silently left a live server out would be wrong.
    while (true) {
        const auto now = Clock::now();
        const bool unheard = e.announce_reader->matchedWriters() > static_cast<int>(e.servers.size());
        bool unsure = false;
        for (const auto& [id, s] : e.servers) unsure |= s.alive && !fresh(id);
        if (now >= deadline || (now >= settled && !unheard && (!unsure || now >= start + kListen))) break;
        e.announce_reader->waitForData(std::min(milliseconds(100), remaining(deadline)));
        RETURN_IF_ERROR(takeKeyed(*e.announce_reader, e.servers, &facescan_wire_ServerAnnounce::server_id,
                                  &e.server_writers, &arrived));
    }
    // A server whose writer is still matched (its process answers discovery) but which announces nothing, or
    // whose liveliness lapsed, is there but stuck (its intake stalled, or too loaded): listed as not responding,
    // since that is the server that needs attention. One whose writer is gone has left.
    const std::vector<dds_instance_handle_t> matched = e.announce_reader->matchedPublications();
    std::vector<ServerInfo> out;
    for (auto [id, s] : e.servers) {
        const auto seen = e.server_writers.find(id);
        const bool present = seen != e.server_writers.end() &&
                             std::find(matched.begin(), matched.end(), seen->second.writer) != matched.end();
        if (!s.alive && !present) continue;
        s.responding = s.alive && fresh(id);
        out.push_back(std::move(s));
    }
    if (out.empty()) return deadlineExceeded(noServerMessage(config_.domain));
    return out;
}

StatusOr<std::map<std::string, OwnerInfo>> ScanClient::owners(milliseconds settle) {
    RETURN_IF_ERROR(ensureClusterReaders());
    Endpoints& e = *endpoints_;
    const auto deadline = Clock::now() + settle;
    do {
        e.owner_reader->waitForData(std::min(milliseconds(50), remaining(deadline)));
        RETURN_IF_ERROR(takeKeyed(*e.owner_reader, e.owners, &facescan_wire_SessionOwner::session_id));
    } while (Clock::now() < deadline);
    return e.owners;
}

}  // namespace facescan::client
