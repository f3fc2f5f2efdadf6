// The agent's side of the cluster: which server owns its session, and the frames it keeps until they
// are safe.
//   OwnerLink     follows facescan/SessionOwner for the session (the strongest live claim, EXCLUSIVE ownership) and
//                 facescan/ServerAnnounce (how many servers are alive). Frames go only to the owner: they are
//                 written in the session's DDS partition, which only the owner reads.
//   ReplayBuffer  every recording frame sent and not yet confirmed by the owner (replicated to its standby, or on
//                 its disk): after a takeover, or when the owner asks, the agent sends them again from the frame
//                 the owner names. Bounded: when full, the agent waits (a recording loses nothing).
//   SessionStream writes with a bounded blocking time: a stuck owner is reported, never waited on blindly.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "wire/cluster_codec.hpp"
#include "wire/messages.hpp"
#include "wire/replica_codec.hpp"

namespace facescan::capture {

struct OwnerInfo {
    wire::SessionOwnerData data;
    bool alive = false;  // a live server holds the claim
    // The owner reads the session's frames (READY or ACTIVE) and is alive.
    bool serving() const {
        return alive && (data.state == wire::OwnerState::kReady || data.state == wire::OwnerState::kActive);
    }
    bool finished() const { return data.state == wire::OwnerState::kFinished; }
};

class OwnerLink {
 public:
    static StatusOr<OwnerLink> create(const wire::Participant& participant, const std::string& session_id);
    // Takes what arrived; cheap, call it before every frame.
    void poll();
    const std::optional<OwnerInfo>& owner() const { return owner_; }
    int liveServers() const;

 private:
    std::string session_id_;
    std::optional<wire::Topic<facescan_wire_SessionOwner>> owner_topic_;
    std::optional<wire::Topic<facescan_wire_ServerAnnounce>> announce_topic_;
    std::optional<wire::Reader<facescan_wire_SessionOwner>> owner_reader_;
    std::optional<wire::Reader<facescan_wire_ServerAnnounce>> announce_reader_;
    std::optional<OwnerInfo> owner_;
    std::map<std::string, bool> servers_;  // id -> alive
};

class ReplayBuffer {
 public:
    explicit ReplayBuffer(size_t max_frames) : max_frames_(max_frames) {}
    bool full() const { return frames_.size() >= max_frames_; }
    size_t size() const { return frames_.size(); }
    size_t bytes() const { return bytes_; }
    void push(const wire::EncodedFrame& frame, bool end_of_stream);
    void popBack();
    // Drops the frames before `seq` (the owner confirmed them).
    void dropBefore(uint32_t seq);
    bool empty() const { return frames_.empty(); }
    // The oldest frame kept; `otherwise` when none is.
    uint32_t firstSeq(uint32_t otherwise) const { return frames_.empty() ? otherwise : frames_.front().frame.seq; }
    // One past the newest frame kept (not the end of the stream); `otherwise` when none is.
    uint32_t nextAfterFrames(uint32_t otherwise) const;
    // Calls fn(frame, end_of_stream) for every kept frame from `seq` on, in order; stops when fn returns false.
    template <typename Fn>
    void forEachFrom(uint32_t seq, Fn&& fn) const {
        for (const Entry& e : frames_) {
            if (e.frame.seq >= seq && !fn(e.frame, e.end_of_stream)) return;
        }
    }

 private:
    struct Entry {
        wire::EncodedFrame frame;
        bool end_of_stream = false;
    };
    size_t max_frames_;
    size_t bytes_ = 0;
    std::deque<Entry> frames_;
};

// What the stream is doing, for the agent's status line.
struct StreamState {
    std::string owner;  // empty: none yet
    std::string standby;
    uint32_t epoch = 0;
    uint32_t takeovers = 0;                    // owner changes seen while streaming
    uint32_t replayed = 0;                     // frames sent again
    size_t kept = 0;                           // recording frames kept until confirmed
    std::string waiting;                       // why nothing is sent now (empty: streaming)
    int servers = 0;                           // servers alive on the domain
    uint64_t digest = wire::kFrameDigestSeed;  // of every frame sent (the first time), as the server digests them
    uint32_t followed_epoch = 0;               // the highest owner epoch streamed to
    uint32_t dropped_before = 0;               // recordings: frames before it were confirmed and dropped
};

// How long the agent's frame writes may block before they look at `stop` and the owner again. The writer's
// max_blocking_time: short, so that a stop is noticed and a stuck owner is seen within it. The write is then
// tried again: a recording's back-pressure is unchanged (every frame waits for the owner; none is dropped).
inline constexpr std::chrono::milliseconds kFrameWriteBlocking{250};

// Sends a session's frames to its owner: waits while nobody serves the session (live frames meanwhile are
// dropped by the caller's queue, recording frames wait), resends the kept frames to a new owner or when the
// owner asks, and forgets the ones the owner confirmed.
class SessionStream {
 public:
    using Events = std::function<void(const std::string&)>;
    // stalled_after_s: an owner that has taken no frame for this long while writes wait is reported as having
    // stopped taking frames (the stream keeps following its claim: a takeover resends as usual).
    SessionStream(OwnerLink link, wire::Writer<facescan_wire_RgbdFrame>& writer, std::string session_id,
                  bool every_frame, size_t keep_frames, float stalled_after_s, std::string where, Events on_event);
    // Until an owner serves the session; DeadlineExceeded after timeout_s (0: no limit). Ok (not served) on stop.
    Status waitUntilServed(const std::atomic<bool>& stop, float timeout_s);
    // One frame, or the end of the stream. Waits for an owner and, for a recording, for room to keep it
    // (DeadlineExceeded after timeout_s; 0: no limit). A stop interrupts the wait: a recording's frame is then
    // set aside, not sent, and unconfirmed() has it too.
    Status send(const wire::EncodedFrame& frame, bool end_of_stream, const std::atomic<bool>& stop,
                float timeout_s = 0);
    // After the end of the stream: until the owner reports the session finished (resending to a new owner
    // meanwhile, and the end of the stream again every few seconds: an owner that lost it, or took the session
    // over from a copy after the agent had dropped it, finishes then). False when it did not within timeout_s, or
    // within grace_after_stop_s of `stop`.
    bool waitFinished(const std::atomic<bool>& stop, float timeout_s, float grace_after_stop_s);
    bool finished() const { return link_.owner() && link_.owner()->finished(); }
    // The recording frames that no owner has confirmed (the latest claim's confirmed_seq read now), then the
    // ones a stop kept from being sent, in order, without the end of the stream.
    std::vector<wire::EncodedFrame> unconfirmed();
    // The frame after the last one sent or kept for sending: the end of the stream's seq. A recording's owner takes
    // frames in order only, so a larger one would make it ask for frames that will never come, and a smaller one
    // is dropped as a duplicate of a frame.
    uint32_t nextSeq() const;
    StreamState state() const;
    // The epoch of the owner serving the session now (0: none), without copying the whole state: asked per frame.
    uint32_t servingEpoch() const;
    // Called about every 20 ms while the stream waits (the agent reports its status line from it).
    void onWait(std::function<void()> tick) { on_wait_ = std::move(tick); }
    // Why no server may answer (e.g. a secured domain): said once when no server was seen for 2 s.
    void onNoServer(std::function<std::string()> hint) { no_server_hint_ = std::move(hint); }

 private:
    using Clock = std::chrono::steady_clock;
    // Follows the owner: forgets confirmed frames, resends to a new owner or on request. False: not served, or
    // its resend was cut short (a stop, the deadline, another owner).
    bool follow(const std::atomic<bool>& stop, Clock::time_point deadline);
    // True: written. False: given up on a stop, at the deadline or because another owner claimed the session
    // meanwhile (the next follow() resends the kept frames to it). An error: DDS failed.
    StatusOr<bool> write(const wire::EncodedFrame& frame, bool end_of_stream, const std::atomic<bool>& stop,
                         Clock::time_point deadline);
    // The claim now names another owner or epoch than the one the stream follows.
    bool ownerChanged() const;
    void say(const std::string& waiting);
    void dropConfirmed(uint32_t confirmed_seq);  // a recording's frames before it: an owner has them

    OwnerLink link_;
    wire::Writer<facescan_wire_RgbdFrame>& writer_;
    std::string session_id_;
    bool every_frame_;
    ReplayBuffer kept_;
    std::chrono::nanoseconds stalled_after_;
    bool stalled_ = false;                    // the owner was reported as having stopped taking frames
    std::vector<wire::EncodedFrame> unsent_;  // recording frames a stop kept from being sent
    uint32_t next_seq_ = 0;
    std::string where_;
    Events on_event_;
    StreamState state_;
    uint32_t replay_seen_ = 0;
    bool resend_cut_ = false;  // the last resend stopped short: the next follow() resends again
    // The end of the stream once sent, and when it was last written: repeated while the agent waits for the finish.
    std::optional<wire::EncodedFrame> end_;
    Clock::time_point end_written_{};
    std::function<void()> on_wait_;
    std::function<std::string()> no_server_hint_;
    int64_t no_server_since_ns_ = 0;  // steady clock; 0 while servers are seen
    bool hinted_ = false;
};

}  // namespace facescan::capture
