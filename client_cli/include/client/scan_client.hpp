// The client side of the scan protocol (notes/protocol.md): commands with replies collected from every server,
// the live ScanStatus of all sessions, and MeshSnapshots. One DDS participant; endpoints are made on first use so
// that `facescan mesh` never pulls the durable snapshots of every session, and a read-only identity (DDS Security
// role viewer) can watch without the command topics it may not touch.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "recon/status.hpp"
#include "wire/cluster_codec.hpp"
#include "wire/messages.hpp"
#include "wire/topics.hpp"

namespace facescan::client {

struct ClientConfig {
    wire::DomainConfig domain{0, "lan"};
    std::chrono::milliseconds timeout{10'000};  // no server answers within this: DeadlineExceeded
    std::chrono::milliseconds grace{500};       // after an error reply, wait this long for another server's ok
    // After the first server is discovered, wait this long for more (each server answers for its own sessions).
    std::chrono::milliseconds discovery_settle{250};
    // false: status and snapshots only, no ScanCommand writer or ScanReply reader (a live feed never sends
    // commands, and a read-only viewer identity may not); request() is then Unavailable at once.
    bool commands = true;

    Status validate() const;
};

struct CommandReply {
    std::string session_id;
    std::string server_id;
    bool ok = false;
    std::string error;
    uint32_t vertex_count = 0;
    uint32_t triangle_count = 0;
    std::vector<uint8_t> payload;
    // GET_MESH with want_texture of a finished model that has a texture: its atlas (PNG), and the payload is the
    // textured model (Draco with texture coordinates). Empty otherwise.
    std::vector<uint8_t> texture;
};

// The latest ScanStatus of a session (wire::ScanStatusData, converted in one place) and whether its server lives.
struct SessionStatus : wire::ScanStatusData {
    bool alive = true;  // false once the server that publishes it is gone
};

// A server of the domain (its announcement) and whether it is alive.
struct ServerInfo : wire::ServerAnnounceData {
    bool alive = true;
    // false: the server is still on the domain but has not asserted its liveliness for a lease (frozen or
    // overloaded); its sessions are taken over if it stays so.
    bool responding = true;
};

// Who owns a session (the strongest live claim: every reader sees the same one).
struct OwnerInfo : wire::SessionOwnerData {
    bool alive = true;  // false once its owner died and nobody took it over yet
};

struct MeshSnapshotData {
    std::string session_id;
    uint32_t seq = 0;
    uint32_t frames_integrated = 0;
    uint32_t vertex_count = 0;
    uint32_t triangle_count = 0;
    int64_t created_ns = 0;
    std::vector<uint8_t> draco;
    std::chrono::steady_clock::time_point received;  // our clock: snapshot age needs no synchronised clocks
};

// ScanClient::poll's snapshot_session for the snapshots of every session (no session id is "*").
inline constexpr const char* kAllSessions = "*";

const char* scanStateName(facescan_wire_ScanState state);  // "WAITING", "SCANNING", ...
const char* commandKindName(facescan_wire_CommandKind kind);

// "no server answered on domain N (profile P): is facescan-server running?" and why that may be (DDS Security)
std::string noServerMessage(const wire::DomainConfig& domain);

class ScanClient {
 public:
    // Creates the participant and the command endpoints. Errors come from the profile (NotFound,
    // InvalidArgument) or from DDS itself (e.g. the socket buffer limit, Unavailable).
    static StatusOr<std::unique_ptr<ScanClient>> connect(const ClientConfig& config);
    ~ScanClient();
    ScanClient(const ScanClient&) = delete;
    ScanClient& operator=(const ScanClient&) = delete;

    const ClientConfig& config() const { return config_; }

    // Waits until at least one server is discovered (its ScanStatus writer), up to the timeout.
    // DeadlineExceeded with noServerMessage() when none is. Needs only the right to read ScanStatus.
    Status waitForServer();

    // Makes the command endpoints now rather than at the first request: PermissionDenied when this identity's role
    // may not send commands (DDS Security), Unavailable for a client that only reads. Safe to call again.
    Status enableCommands();

    // Sends one command and collects replies with its request id (notes/protocol.md): the first ok reply wins;
    // after an error reply, other servers get `grace` to answer ok. Errors: DeadlineExceeded (no server),
    // NotFound ("unknown session 'X'", the server's text), InvalidArgument (any other refusal),
    // PermissionDenied (DDS Security: this identity's role may not send commands).
    // want_texture: GET_MESH of a finished model asks for its texture too (CommandReply::texture); a server without
    // one, or of an older version, answers with the vertex-coloured mesh.
    StatusOr<CommandReply> request(const std::string& session_id, facescan_wire_CommandKind kind,
                                   bool want_texture = false);

    // The ScanStatus of every session on the domain, as far as it has arrived: waits for a server, then up to
    // `settle` for the durable samples. Sorted by session id.
    StatusOr<std::vector<SessionStatus>> sessions(std::chrono::milliseconds settle);

    // The servers on the domain (their durable announcements; one that is there but not responding too), after
    // `settle` for them to arrive, and
    // longer, up to `max_wait` in all, while a server already matched has not been heard yet. Sorted by id.
    StatusOr<std::vector<ServerInfo>> servers(std::chrono::milliseconds settle,
                                              std::chrono::milliseconds max_wait = std::chrono::milliseconds(0));
    // The owner of every session that has one (durable claims), after up to `settle`.
    StatusOr<std::map<std::string, OwnerInfo>> owners(std::chrono::milliseconds settle);

    // Live following: takes what has arrived into `statuses` (by session id) and returns new snapshots of
    // `snapshot_session` (empty: none wanted; kAllSessions: every session's). Waits at most `wait` for a status or
    // a snapshot to arrive.
    Status poll(std::chrono::milliseconds wait, std::map<std::string, SessionStatus>& statuses,
                const std::string& snapshot_session, std::vector<MeshSnapshotData>* snapshots);

    // The sessions erased on the domain (`facescan delete`: EraseRequest) since the last call, each once; the
    // first call starts reading them (durable: erasures from before it joined come too). PermissionDenied for an
    // identity enrolled before its role read erasures.
    StatusOr<std::vector<std::string>> takeErased();

    // This client's id as its commands carry it (its DDS Security identity's name first, when it has one).
    const std::string& clientId() const { return client_id_; }

 private:
    explicit ScanClient(ClientConfig config);
    Status ensureStatusReader();
    Status waitForCommandServer();
    Status ensureSnapshotReader();
    Status ensureClusterReaders();
    Status takeStatuses(std::map<std::string, SessionStatus>& statuses);
    Status readOnly() const;
    std::string nextRequestId();

    struct Endpoints;
    ClientConfig config_;
    std::unique_ptr<Endpoints> endpoints_;
    std::string client_id_;
    uint64_t request_counter_ = 0;
};

}  // namespace facescan::client
