// facescan-server's engine: DDS endpoints on one participant and the threads of issue 8.
//   intake    one waitset on CameraInfo, RgbdFrame and ScanCommand; it only routes samples (copies a frame's
//             bytes into its session and returns the loan). Frames are taken per instance (= per session):
//             a recording session whose bounded queue is full is simply not taken from, so its samples stay in
//             the reader (keep-all, 16 per instance), the reader stops acknowledging and DDS reliability blocks
//             the agent's writer. Live sessions and other recordings keep flowing meanwhile.
//   workers   one per session (session.hpp): decode -> detection/segmentation -> recon core.
//   commands  replies to ScanCommand (mesh extraction and encoding happen here or on the session's worker).
//   snapshots coarse meshes at --snapshot-hz, off the frame path, at a lower OS priority.
//   status    ScanStatus per session at status_hz; finishes idle sessions.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "service/server_params.hpp"
#include "service/session.hpp"
#include "wire/topics.hpp"

namespace facescan::service {

class Server {
 public:
    // Validates params, joins the domain and starts the threads.
    static StatusOr<std::unique_ptr<Server>> create(const ServerParams& params);
    ~Server();  // shutdown()
    Server(const Server&) = delete;
    Server& operator=(const Server&) = delete;

    // Finishes every open session (written to the data dir), publishes their final status, stops the threads.
    // Idempotent.
    void shutdown();

    const ServerParams& params() const { return params_; }
    // Current stats of every session this server knows (open, finished and refused).
    std::vector<SessionStats> sessions() const;
    int openSessions() const;

 private:
    struct Command {
        std::string session_id, request_id;
        uint32_t kind = 0;
    };
    struct Refused {
        std::string detail;
    };

    explicit Server(const ServerParams& params) : params_(params) {}
    Status start();
    void intakeLoop();
    void takeCameraInfos();
    void takeCommands();
    void takeFrames();
    void commandLoop();
    void snapshotLoop();
    void statusLoop();
    // The status and snapshot threads' clock: advances `next` by `period` (from now when the last tick ran late)
    // and sleeps until then; false when the server is stopping.
    bool waitForTick(std::chrono::steady_clock::time_point& next, std::chrono::duration<double> period);
    void runCommand(const Command& c);
    // The session for a new or known id, or null when refused (max sessions) or invalid.
    std::shared_ptr<Session> sessionFor(const std::string& session_id);
    void reply(const Command& c, const Status& status, const MeshResult* mesh = nullptr,
               const std::vector<uint8_t>* payload = nullptr);
    void publishStatus(const SessionStats& s);
    void publishSnapshot(const std::string& session_id, const SnapshotResult& snap);
    void publishRefused(const std::string& session_id, const std::string& detail);

    ServerParams params_;
    std::unique_ptr<wire::Participant> participant_;
    std::unique_ptr<wire::Topic<facescan_wire_CameraInfo>> camera_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_RgbdFrame>> frame_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_ScanStatus>> status_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_MeshSnapshot>> snapshot_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_ScanCommand>> command_topic_;
    std::unique_ptr<wire::Topic<facescan_wire_ScanReply>> reply_topic_;
    std::unique_ptr<wire::Reader<facescan_wire_CameraInfo>> camera_reader_;
    std::unique_ptr<wire::Reader<facescan_wire_RgbdFrame>> frame_reader_;
    std::unique_ptr<wire::Reader<facescan_wire_ScanCommand>> command_reader_;
    std::unique_ptr<wire::Writer<facescan_wire_ScanStatus>> status_writer_;
    std::unique_ptr<wire::Writer<facescan_wire_MeshSnapshot>> snapshot_writer_;
    std::unique_ptr<wire::Writer<facescan_wire_ScanReply>> reply_writer_;
    wire::Entity waitset_;
    wire::Entity wake_;  // guard condition: queue space freed, or shutdown

    mutable std::mutex sessions_mutex_;
    std::map<std::string, std::shared_ptr<Session>> sessions_;
    std::map<std::string, Refused> refused_;
    std::map<dds_instance_handle_t, std::string> frame_instances_;  // RgbdFrame instance -> session id

    std::mutex command_mutex_;
    std::condition_variable command_cv_;
    std::deque<Command> commands_;

    std::mutex sleep_mutex_;  // status and snapshot threads sleep on this until their next tick or shutdown
    std::condition_variable sleep_cv_;
    std::atomic<bool> stopping_{false};
    bool shut_down_ = false;
    std::thread intake_, command_, snapshot_, status_;
};

}  // namespace facescan::service
