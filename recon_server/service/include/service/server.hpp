// facescan-server's engine: DDS endpoints on one participant and its threads (docs/design.md), in a cluster.
//   intake    one waitset on CameraInfo, ScanCommand, the cluster's topics and the frame reader of every owned
//             session; it routes samples and makes the cluster's decisions (server_cluster.cpp): which new
//             session to claim, when a claim has settled, when to give one up, when to take over from a dead
//             owner or resume from the data dir. A session's frames are read in its own DDS partition, so only
//             its owner receives them; a recording whose bounded queue is full is simply not taken from, its
//             samples stay in the reader and DDS reliability blocks the agent's writer.
//   workers   one per session (session.hpp): decode -> detection/segmentation -> recon core.
//   commands  replies to ScanCommand, for the sessions this server owns (and, on the one "responder" server,
//             for sessions nobody owns).
//   snapshots coarse meshes at --snapshot-hz, off the frame path, at a lower OS priority.
//   status    ScanStatus per owned session at status_hz, the server's announcement; finishes idle sessions;
//             retires finished sessions from memory (finished_sessions.hpp, server_finished.cpp).
//   replicas  replication.hpp: every owned session's state to its standby and its data dir; replicas received
//             as a standby.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "service/cluster.hpp"
#include "service/data_dir_lock.hpp"
#include "service/erasure.hpp"
#include "service/erasure_service.hpp"
#include "service/finished_sessions.hpp"
#include "service/live_count.hpp"
#include "service/retirer.hpp"
#include "service/server_params.hpp"
#include "service/session.hpp"
#include "service/watchdog.hpp"
#include "wire/audit_log.hpp"
#include "wire/peer_identity.hpp"
#include "wire/topics.hpp"

namespace facescan::service {

class Replicator;

// A session this server claimed: its claim on SessionOwner and, once the claim settled, the session and the
// reader of its frames. Shared with the replication thread.
struct OwnedSession {
    LiveCount<OwnedSession> live;  // first, so last destroyed (the memory line counts these)
    // kGivenUp: yielded or released; its endpoints are on their way to the retiring thread (retirer.hpp).
    enum class Phase { kClaiming, kReady, kActive, kFinished, kGivenUp };
    std::string id;
    // Raised while the session runs when another server's claim won the tie at this epoch with less of the scan
    // (Server::claimFullerSession); the replication thread reads it.
    std::atomic<uint32_t> epoch{1};
    std::shared_ptr<Claim> claim;  // shared with its FinishedSession record once retired
    std::atomic<Phase> phase{Phase::kClaiming};
    int64_t claimed_ns = 0;  // steady clock
    int64_t ready_ns = 0;
    std::filesystem::path dir;  // its folder in the data dir, made at its first replica (owner.json names us)
    std::shared_ptr<Session> session;
    std::optional<wire::CameraInfoData> camera;     // a new session: from its CameraInfo
    std::optional<wire::ReplicaData> restore_from;  // a takeover or a restart: the state to continue from
    int64_t takeover_from_ns = 0;                   // the old owner's last sign of life (steady clock)
    uint32_t failovers_before = 0;                  // a takeover from the first frame: the claim's count until then
    std::unique_ptr<wire::Reader<facescan_wire_RgbdFrame>> frames;
    dds_entity_t frame_condition = 0;
    bool ahead = false;                    // a recording frame after a gap arrived: the agent must resend
    std::atomic<bool> recording{true};     // every frame kept by its agent (set by activate(); held after long pauses)
    std::atomic<bool> agent_alive{false};  // its agent's CameraInfo writer is alive (the intake thread's view)
    bool idle_said = false;                // status thread: "waiting for the agent" said once
    int64_t last_replay_request_ns = 0;
    dds_instance_handle_t camera_writer = 0;  // the CameraInfo writer (flood control)
    // The session's engine, built on a thread of its own from the claim on (Server::buildEngine): activate() waits
    // for it. Last, so that its destructor, which waits for the build, runs before camera and restore_from go.
    std::future<StatusOr<SessionEngine>> engine;
};

class Server {
 public:
    // Validates params, joins the domain (refusing a duplicate --server-id) and starts the threads.
    static StatusOr<std::unique_ptr<Server>> create(const ServerParams& params);
    ~Server();  // shutdown()
    Server(const Server&) = delete;
    Server& operator=(const Server&) = delete;

    // Finishes every open session (written to the data dir), publishes their final status, stops the threads.
    // Idempotent.
    void shutdown();

    const ServerParams& params() const { return params_; }
    // Current stats of every session this server owns, of the finished ones it lists (--keep-finished) and of
    // refused ones.
    std::vector<SessionStats> sessions() const;
    int openSessions() const;
    int standbySessions() const;

 private:
    struct Command {
        std::string session_id, request_id;
        uint32_t kind = 0;
        int64_t received_ns = 0;
        std::string client_id;      // as the client sent it (its DDS Security identity's name first, when it has one)
        std::string identity;       // who sent it, for the audit trail (identify())
        bool want_texture = false;  // GET_MESH: the finished model's texture too, when it has one
    };
    struct Candidate {  // a CameraInfo of a session nobody owns yet
        wire::CameraInfoData camera;
        dds_instance_handle_t writer = 0;  // its publication handle: flood control per agent writer
        int64_t order_key = 0;             // source timestamp: the same on every server
        int64_t first_seen_ns = 0;         // steady clock
        int64_t heard_ns = 0;              // steady clock: its last CameraInfo (an agent repeats it every second)
        bool writer_alive = true;
    };
    struct Refused {
        std::string detail;
    };

    explicit Server(const ServerParams& params);  // out of line: Replicator is incomplete here
    Status start();
    Status join();
    void intakeLoop();
    void takeCameraInfos();
    void takeCommands();
    void takeFrames();
    void takeFramesOf(OwnedSession& owned);
    void commandLoop();
    void snapshotLoop();
    void statusLoop();
    bool waitForTick(std::chrono::steady_clock::time_point& next, std::chrono::duration<double> period);
    void runCommand(const Command& c);
    // Appends the answered command to the audit trail (server_audit.cpp); a status query is not recorded.
    void audit(const Command& c, const Status& status);
    // The audit trail's IDENTITY of a sample's sender (server_audit.cpp): with DDS Security the subject its
    // participant authenticated with (wire/peer_identity.hpp), the client id it claims only beside it.
    std::string identify(dds_entity_t reader, dds_instance_handle_t writer, const std::string& claimed_client);
    void reply(const Command& c, const Status& status, const MeshResult* mesh = nullptr,
               const std::vector<uint8_t>* payload = nullptr, const std::vector<uint8_t>* texture = nullptr);
    // GET_MESH with want_texture of a session finished into `dir`: the textured model (textured.drc and its atlas,
    // finished_sessions.hpp) when the session has one; false when it has none (the caller answers as without).
    bool answerTextured(const Command& c, const std::filesystem::path& dir);
    void publishStatus(const SessionStats& s);
    void publishSnapshot(const std::string& session_id, const SnapshotResult& snap);
    void publishRefused(const std::string& session_id, const std::string& detail);

    // server_finished.cpp, on the status thread: finished sessions whose final status went out (final_sent) leave
    // owned_ and memory for finished_; those beyond --keep-finished or older than --keep-finished-s are unlisted.
    void retireFinished(std::map<std::string, bool>& final_sent);
    void forgetFinished(FinishedSession& f);  // unlisted; its claim ends on the retiring thread
    // A result finished here while this server was cut off or frozen, and finished again by the server that took
    // the scan over meanwhile: the winner's claim (view) says FINISHED with every frame this one had (up to
    // next_seq). Then this one is a second result for one scan and goes (dropSupersededResults, yield).
    bool resultSuperseded(const OwnerView& view, uint32_t epoch, uint32_t next_seq) const;
    void dropSupersededResults(const std::map<std::string, OwnerView>& owners);
    // This server's finished result holds more of the scan than the stronger claim's (another server's, FINISHED):
    // it claims the scan again above that epoch, and the other server's partial result then goes.
    bool holdsFullerResult(const OwnerView& view, const SessionStats& mine) const;
    void claimFullerResult(const std::string& session_id, const wire::SessionOwnerData& winner);
    // The same while the session runs: another server's claim won the tie at this session's epoch, holding fewer
    // confirmed frames than this server's, which its agent may have dropped. This server raises its claim to the
    // next epoch and goes on; the other one yields to it.
    bool holdsFullerSession(const OwnedSession& o, const OwnerView& view) const;
    void claimFullerSession(OwnedSession& o, const wire::SessionOwnerData& winner);
    // The files of a copy in the data dir (a replica, and what an interrupted finish wrote beside it), not folders.
    void removeCopy(const std::filesystem::path& dir);
    void removeResultFiles(const std::string& session_id, const std::filesystem::path& dir, const std::string& why);
    void unlist(const std::string& session_id);  // this server's status and mesh of it leave the writers
    // A finished session that this server retired: listed, or its files in the data dir name this server.
    bool answersFromFiles(const std::string& session_id) const;
    // Answers a command of such a session from its files; false when this server has none.
    bool answerFromFiles(const Command& c);

    // server_cluster.cpp: the cluster's decisions, on the intake thread.
    void clusterTick();
    void placeNewSessions(const std::map<std::string, OwnerView>& owners);
    void settleClaims(const std::map<std::string, OwnerView>& owners);
    void takeOverOrphans(const std::map<std::string, OwnerView>& owners);
    // A dead owner's session that nobody holds a replica of, while its agent still keeps every frame.
    void takeOverFromFirstFrame(const std::string& session_id, const OwnerView& view);
    void requestReplays();
    void releaseStale();
    // Whether a takeover may go ahead: most servers still in view, or else the agent still heard half a lease later.
    bool witnessed(const std::string& session_id, int64_t owner_gone_since_ns) const;
    bool agentLives(const std::string& session_id) const;  // its CameraInfo writer is alive in this view
    bool agentHeardSince(const std::string& session_id, int64_t since_ns) const;  // a CameraInfo came since then
    // The owner announced itself since its claim lapsed here, less than a lease ago: its claim may come back.
    bool ownerHeardAgain(const std::string& session_id, const std::string& owner_id, int64_t gone_since_ns);
    // Its agent, heard from within the lease, says that an owner at `epoch` or later serves it.
    bool agentStillServed(const std::string& session_id, uint32_t epoch) const;
    // Whether this server is cut off, or back from it and re-observing the cluster before it takes anything over.
    bool rejoining();
    // A new scan under the id of one that finished in this server's data dir: refused with a FINISHED claim (true),
    // so that no server places it and its agent says why.
    bool refuseReusedId(const std::string& session_id);
    // A recording whose agent followed an owner, with no claim of it in view: whether it may be placed as new (from
    // the first frame, above the epoch followed), else why not, said once.
    bool placeableAsNew(const std::string& session_id, const Candidate& c);
    // A refusal that holds until the view changes (re-checked every turn): logged the first time only.
    void sayOnce(const std::string& line);
    Status claimSession(const std::string& session_id, uint32_t epoch, std::shared_ptr<OwnedSession> owned,
                        const wire::SessionOwnerData& previous);
    void buildEngine(OwnedSession& owned);  // starts the build of owned.engine
    Status activate(OwnedSession& owned);
    void yield(const std::string& session_id, const std::string& why, const OwnerView& winner);
    // After a yield: this server's copy of a recording in its data dir, kept ready in case the new owner fails too.
    void keepCopyInCase(const std::string& session_id, const OwnerView& winner);
    // The one way a session's endpoints end: out of owned_, its frame reader lingering (retireFrameReader) and its
    // status unlisted (all here, on the intake thread), then claim and session ended in that order on the retiring
    // thread.
    // `dispose_claim`: the claim says RELEASED first (nobody owns the session); else it is withdrawn, as if this
    // server had died, and a stronger claim stays the only one.
    void retireOwned(const std::shared_ptr<OwnedSession>& o, bool dispose_claim);
    // A session's frame reader that nothing takes from any more, with its read condition on the intake's waitset:
    // drained on the intake thread until its agent's writer is gone (drainLingering, every turn), then deleted on
    // the retiring thread; never deleted while a writer can fill it (service/lingering_reader.hpp).
    void retireFrameReader(std::unique_ptr<wire::Reader<facescan_wire_RgbdFrame>> frames, dds_entity_t condition);
    void drainLingering();
    void endLingering();  // shutdown
    // Status thread, server_memory.cpp: once a minute, when it changed, what this server holds in memory and why
    // (resident, heap in use and held free, sessions open and still in memory, standby copies, finished records,
    // lingering readers): memory that grows shows what holds it.
    void logMemory(int64_t now_ns);
    int64_t memory_logged_ns_ = 0;  // status thread: last checked
    // Status thread, server_memory.cpp: freed memory that stays resident goes back to the system (malloc_trim) once
    // it exceeds a bound; checked every 2 s when idle, every 30 s under load.
    void returnHeldMemory(int64_t now_ns);
    int64_t trim_checked_ns_ = 0;
    double baseline_outside_heap_mib_ = -1;
    std::string memory_said_;  // status thread: the counts last said
    // server_health.cpp: the cluster view. A server that was frozen (SIGSTOP, a paused VM) for half a lease or more
    // (its watchdog's thread notices it: noticePause) saw the others' leases lapse only in its own eyes: for two leases
    // after it wakes, it re-observes the cluster and takes nothing over, places nothing, and holds its own sessions'
    // work and output (frames, finishes, replicas, status, snapshots, replies) until it knows whether it still owns
    // them.
    void noticePause(int64_t gap_ns, int64_t now_ns);
    bool viewFresh() const;        // not re-observing the cluster after a pause: it may take over and place
    bool ownSessionsFree() const;  // its own sessions may go on (not held after a pause long enough to lose them)
    bool sessionFree(bool recording) const;  // a session may: a live scan is not held (server_health.cpp)
    // Status thread: a session without frames for idle_timeout_s is finished, but a recording whose agent lives.
    void finishIdle(OwnedSession& o);
    void assertProgress(int64_t now_ns);  // the announcement's liveliness (wire::withProgressLiveliness)
    void refreshClaims(int64_t now_ns);   // the claims' liveliness: each written again a few times a lease
    int64_t claims_refreshed_ns_ = 0;
    void onStall(const std::string& what);  // the watchdog found a loop stuck: say so and exit non-zero
    // Fault injection for the cluster tests (failpoint.hpp): with FACESCAN_FAILPOINT=intake-stall-when-file:PATH
    // the intake thread stops for good once PATH exists, a real stall of a real thread that the watchdog and the
    // cluster must handle. Unset in production.
    void failpoint();
    // Whether a claim's write may go out now (Claim's `progressing`): the intake makes progress, and
    // FACESCAN_FAILPOINT=claims-silent-when-file:PATH does not hold the claims back (PATH exists: their liveliness
    // lapses at the others while this server announces itself, as when its DDS traffic is starved).
    bool claimsMayBeWritten() const;
    void loadResumable();
    std::shared_ptr<OwnedSession> owned(const std::string& session_id) const;
    std::vector<std::shared_ptr<OwnedSession>> ownedSessions() const;

    ServerParams params_;
    DataDirLock data_dir_lock_;                    // held for the server's life (released last)
    std::unique_ptr<wire::AuditLog> audit_;        // DATA_DIR/audit.log: every command answered (wire/audit_log.hpp)
    std::unique_ptr<RetentionSweeper> retention_;  // --retain-days (server_audit.cpp starts it); stops before audit_
    void startRetention();
    std::unique_ptr<wire::Participant> participant_;
    std::unique_ptr<wire::PeerIdentities> peers_;  // with DDS Security: who authenticated as the sender of a command
    std::unique_ptr<Cluster> cluster_;
    std::unique_ptr<Replicator> replicator_;
    std::unique_ptr<wire::Topic<facescan_wire_CameraInfo>> camera_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_RgbdFrame>> frame_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_ScanStatus>> status_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_MeshSnapshot>> snapshot_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_ScanCommand>> command_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_ScanReply>> reply_topic_;
    std::unique_ptr<wire::Reader<facescan_wire_CameraInfo>> camera_reader_;
    std::unique_ptr<wire::Reader<facescan_wire_ScanCommand>> command_reader_;
    std::unique_ptr<wire::Writer<facescan_wire_ScanStatus>> status_writer_;
    std::unique_ptr<wire::Writer<facescan_wire_MeshSnapshot>> snapshot_writer_;
    std::unique_ptr<wire::Writer<facescan_wire_ScanReply>> reply_writer_;
    std::unique_ptr<Watchdog> watchdog_;
    std::shared_ptr<Watchdog::Beat> intake_beat_;
    std::unique_ptr<Retirer> retirer_;  // after the DDS entities: it ends readers and claims, so it goes first
    int64_t lease_ns_ = 10'000'000'000;
    std::atomic<int64_t> view_stale_until_ns_{0};  // steady clock: after a pause, the view is re-observed until then
    std::atomic<int64_t> last_progress_ns_{0};     // intake thread: when liveliness was last asserted
    std::atomic<int64_t> hold_until_ns_{0};        // steady clock: after a long pause, its own sessions wait until then
    std::filesystem::path stall_file_;             // FACESCAN_FAILPOINT; empty: none
    std::filesystem::path claims_silent_file_;     // FACESCAN_FAILPOINT; empty: none
    wire::Entity waitset_;
    wire::Entity wake_;  // guard condition: queue space freed, an engine built, or shutdown

    mutable std::mutex sessions_mutex_;  // guards owned_ and refused_
    std::map<std::string, std::shared_ptr<OwnedSession>> owned_;
    std::map<std::string, Refused> refused_;  // as the responder: sessions no server had room for
    // Finished sessions once retired from owned_ (the status thread moves them under sessions_mutex_, so that a
    // session is always in one of the two). Before the DDS entities below it in destruction: it holds claims.
    FinishedSessions finished_;

    // Intake thread only.
    std::map<std::string, Candidate> candidates_;
    // What the agents that are gone last said they had dropped (frames confirmed before this one): a copy that
    // ends earlier lacks frames nobody can send any more, so a takeover from it would be a partial scan.
    std::map<std::string, uint32_t> gone_agents_dropped_before_;
    std::map<std::string, wire::ReplicaData> resumable_;  // from the data dir, waiting for the join to end
    // Of those, the ones another live server continues: the highest epoch seen there, kept for a takeover.
    std::map<std::string, uint32_t> held_elsewhere_;
    // Sessions given up whose result here stays for now (their agent is gone, so it may hold frames the new owner
    // never gets) or may still be written by a finish under way: epoch and frames, until the new owner's FINISHED
    // claim has every one of them (dropSupersededResults removes the files then).
    struct GivenUpResult {
        uint32_t epoch = 0;
        uint32_t next_seq = 0;
        int64_t since_ns = 0;
    };
    std::map<std::string, GivenUpResult> given_up_results_;
    int64_t joined_ns_ = 0;         // steady clock: when the join ended
    int64_t cut_off_since_ns_ = 0;  // steady clock: since when this server sees no other server and no agent
    int64_t rejoin_until_ns_ = 0;   // steady clock: re-observing the cluster until then (rejoining)
    bool had_peers_ = false;
    struct LingeringReader {
        std::unique_ptr<wire::Reader<facescan_wire_RgbdFrame>> reader;
        dds_entity_t condition = 0;  // the session's, still on the intake's waitset: data wakes the intake
    };
    std::vector<LingeringReader> lingering_frames_;             // the intake thread only
    std::atomic<int> lingering_count_{0};                       // its size, for the memory line
    std::map<std::string, int64_t> owner_gone_since_ns_;        // takeOverOrphans: when its owner was first seen gone
    std::map<std::string, int64_t> owner_back_since_ns_;        // ownerHeardAgain: when its gone owner was heard again
    std::map<std::string, int64_t> orphaned_since_ns_;          // takeOverFromFirstFrame: when its owner was seen gone
    std::map<std::string, std::unique_ptr<Claim>> tombstones_;  // refuseReusedId, while the candidate lasts
    std::set<std::string> refusals_logged_;                     // takeovers refused: each reason said once
    std::deque<Command> deferred_;                              // commands for sessions being claimed here

    std::mutex command_mutex_;
    std::condition_variable command_cv_;
    std::deque<Command> commands_;

    std::mutex sleep_mutex_;  // status and snapshot threads sleep on this until their next tick or shutdown
    std::condition_variable sleep_cv_;
    std::atomic<bool> stopping_{false};
    bool shut_down_ = false;
    bool joined_ = false;  // the join completed (this server's id is its own)
    std::thread intake_, command_, snapshot_, status_;
    // `facescan delete` (server_audit.cpp starts it). Last: its thread stops before anything it uses goes.
    std::unique_ptr<ErasureService> erasure_;
    Status startErasure();
};

}  // namespace facescan::service
