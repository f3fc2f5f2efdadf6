#include "capture/owner_link.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

namespace facescan::capture {

StatusOr<OwnerLink> OwnerLink::create(const wire::Participant& participant, const std::string& session_id) {
    OwnerLink link;
    link.session_id_ = session_id;
    ASSIGN_OR_RETURN(link.owner_topic_, wire::Topic<facescan_wire_SessionOwner>::create(participant));
    ASSIGN_OR_RETURN(link.announce_topic_, wire::Topic<facescan_wire_ServerAnnounce>::create(participant));
    ASSIGN_OR_RETURN(link.owner_reader_, wire::Reader<facescan_wire_SessionOwner>::create(*link.owner_topic_));
    ASSIGN_OR_RETURN(link.announce_reader_, wire::Reader<facescan_wire_ServerAnnounce>::create(*link.announce_topic_));
    return link;
}

void OwnerLink::poll() {
    (void)owner_reader_->take(
        [&](const facescan_wire_SessionOwner& m, const dds_sample_info_t& info) {
            if (wire::fromDds(m.session_id) != session_id_) return;
            if (!info.valid_data) {
                if (owner_ && info.instance_state != DDS_IST_ALIVE) owner_->alive = false;  // its owner died
                return;
            }
            auto o = wire::fromMessage(m);
            if (!o.isOk()) return;  // a malformed claim is not followed
            owner_ = OwnerInfo{std::move(*o), info.instance_state == DDS_IST_ALIVE};
        },
        256);
    (void)announce_reader_->take(
        [&](const facescan_wire_ServerAnnounce& m, const dds_sample_info_t& info) {
            const std::string id = wire::fromDds(m.server_id);
            if (!wire::validateServerId(id).isOk()) return;
            servers_[id] = info.instance_state == DDS_IST_ALIVE;
        },
        256);
}

int OwnerLink::liveServers() const {
    int n = 0;
    for (const auto& [id, alive] : servers_) n += alive ? 1 : 0;
    return n;
}

void ReplayBuffer::push(const wire::EncodedFrame& frame, bool end_of_stream) {
    frames_.push_back({frame, end_of_stream});
    bytes_ += frame.bytes();
}

void ReplayBuffer::popBack() {
    if (frames_.empty()) return;
    bytes_ -= frames_.back().frame.bytes();
    frames_.pop_back();
}

uint32_t ReplayBuffer::nextAfterFrames(uint32_t otherwise) const {
    for (auto e = frames_.rbegin(); e != frames_.rend(); ++e) {
        if (!e->end_of_stream) return e->frame.seq + 1;
    }
    return otherwise;
}

void ReplayBuffer::dropBefore(uint32_t seq) {
    while (!frames_.empty() && frames_.front().frame.seq < seq) {
        bytes_ -= frames_.front().frame.bytes();
        frames_.pop_front();
    }
}

namespace {
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

// While the agent waits for the finish, the end of the stream goes again this often.
constexpr auto kEndRepeat = 3s;

std::string seconds(double s) {
    char text[32];
    std::snprintf(text, sizeof(text), "%g", s);
    return text;
}

Clock::time_point deadlineAfter(float timeout_s) {
    return timeout_s > 0
               ? Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<float>(timeout_s))
               : Clock::time_point::max();
}
}  // namespace

SessionStream::SessionStream(OwnerLink link, wire::Writer<facescan_wire_RgbdFrame>& writer, std::string session_id,
                             bool every_frame, size_t keep_frames, float stalled_after_s, std::string where,
                             Events on_event)
    : link_(std::move(link)),
      writer_(writer),
      session_id_(std::move(session_id)),
      every_frame_(every_frame),
      kept_(keep_frames),
      stalled_after_(
          std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::duration<float>(stalled_after_s))),
      where_(std::move(where)),
      on_event_(std::move(on_event)) {}

void SessionStream::say(const std::string& waiting) {
    if (waiting == state_.waiting) return;
    state_.waiting = waiting;
    if (!waiting.empty()) on_event_(waiting);
}

bool SessionStream::ownerChanged() const {
    const std::optional<OwnerInfo>& o = link_.owner();
    return o && (o->data.owner_id != state_.owner || o->data.epoch != state_.epoch);
}

bool SessionStream::follow(const std::atomic<bool>& stop, Clock::time_point deadline) {
    link_.poll();
    state_.servers = link_.liveServers();
    const std::optional<OwnerInfo>& o = link_.owner();
    if (!o || !o->serving()) {
        const std::string kept = every_frame_ ? " (" + std::to_string(kept_.size()) + " frames kept)" : "";
        if (state_.servers == 0) {
            say("no facescan-server alive on " + where_ + ": waiting for one" + kept);
            const int64_t now =
                std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
            if (no_server_since_ns_ == 0) no_server_since_ns_ = now;
            if (!hinted_ && no_server_hint_ && now - no_server_since_ns_ > 2'000'000'000) {
                on_event_("no facescan-server answers: " + no_server_hint_());
                hinted_ = true;
            }
        } else if (o && !o->alive && !o->finished()) {
            say("server '" + o->data.owner_id + "' is gone: waiting for its standby to take over" + kept);
        } else if (!o || !o->finished()) {
            say("waiting for a server to take session " + session_id_ + " (" + std::to_string(state_.servers) +
                " alive)" + kept);
        }
        return false;
    }
    no_server_since_ns_ = 0;
    if (writer_.matchedReaders() == 0) return false;  // the owner's reader is not discovered yet
    const wire::SessionOwnerData& d = o->data;
    if (every_frame_) dropConfirmed(d.confirmed_seq);
    state_.kept = kept_.size();
    state_.standby = d.standby_id;
    const bool new_owner = d.owner_id != state_.owner || d.epoch != state_.epoch;
    if (!new_owner && d.replay_request == replay_seen_ && !resend_cut_) {
        if (!stalled_) say("");
        return true;
    }
    if (new_owner && !state_.owner.empty()) {
        ++state_.takeovers;
        on_event_("session " + session_id_ + " taken over by '" + d.owner_id + "' (epoch " + std::to_string(d.epoch) +
                  "): " + (every_frame_ ? "resending from frame " + std::to_string(d.resume_seq) : "streaming on"));
    } else if (new_owner) {
        on_event_("server '" + d.owner_id + "' owns session " + session_id_ + ": streaming" +
                  (every_frame_ ? " (every frame)" : " (live)"));
    }
    state_.owner = d.owner_id;
    state_.epoch = d.epoch;
    state_.followed_epoch = std::max(state_.followed_epoch, d.epoch);
    replay_seen_ = d.replay_request;
    stalled_ = false;
    say("");
    if (!every_frame_) return true;
    // The owner continues from resume_seq: everything kept from there goes again, in order.
    const uint32_t resume_seq = d.resume_seq;  // `d` changes when write() polls the claim
    bool complete = true;
    kept_.forEachFrom(resume_seq, [&](const wire::EncodedFrame& f, bool eos) {
        const StatusOr<bool> sent = write(f, eos, stop, deadline);
        if (sent.isOk() && *sent) ++state_.replayed;
        // A DDS error shows again on the caller's own write; a stop or another owner ends the resend here.
        complete = !sent.isOk() || *sent;
        return sent.isOk() && *sent;
    });
    // Cut short (a stop, the deadline): the rest goes at the next follow(), or it never would while this owner
    // lasts (duplicates of what arrived are dropped by the owner).
    resend_cut_ = !complete;
    return complete;
}

Status SessionStream::waitUntilServed(const std::atomic<bool>& stop, float timeout_s) {
    const auto deadline = deadlineAfter(timeout_s);
    while (!follow(stop, Clock::time_point::max())) {
        if (stop) return Status::ok();
        // A finished claim for a session this agent never streamed: the id names a scan that is over (its files
        // are on that server), and a new scan under it would be mixed up with that one.
        if (const std::optional<OwnerInfo>& o = link_.owner(); o && o->finished() && state_.owner.empty()) {
            return invalidArgument("session " + session_id_ + " already finished on server '" + o->data.owner_id +
                                   "': a session id names one scan; start the agent with another --session (or "
                                   "without one, for a fresh id)");
        }
        if (on_wait_) on_wait_();
        if (Clock::now() > deadline) {
            return deadlineExceeded("no facescan-server took session " + session_id_ + " on " + where_ + " within " +
                                    seconds(timeout_s) + " s: start one with the same --profile and --domain");
        }
        std::this_thread::sleep_for(50ms);
    }
    return Status::ok();
}

StatusOr<bool> SessionStream::write(const wire::EncodedFrame& frame, bool end_of_stream, const std::atomic<bool>& stop,
                                    Clock::time_point deadline) {
    facescan_wire_RgbdFrame msg = wire::toMessage(session_id_, frame);
    msg.end_of_stream = end_of_stream;
    // Tells an owner that needs older frames that they are gone from here (confirmed by an earlier owner whose copy
    // did not survive), so that it goes on from what exists instead of asking for them for ever.
    if (every_frame_) msg.oldest_kept_seq = std::min(frame.seq, kept_.firstSeq(frame.seq));
    const auto first_try = Clock::now();
    for (;;) {
        if (stop || Clock::now() >= deadline) return false;
        const Status written = writer_.write(msg);
        if (written.isOk()) break;
        // Back-pressure: a keep-all writer times out (within kFrameWriteBlocking) while the owner has not taken
        // frames (or died: its reader then lapses with its lease and the writer is free again).
        if (written.code() != StatusCode::kDeadlineExceeded) return written;
        link_.poll();
        if (ownerChanged()) return false;
        if (!stalled_ && Clock::now() - first_try >= stalled_after_ && !state_.owner.empty()) {
            stalled_ = true;
            say("server '" + state_.owner + "' has stopped taking frames (none for " +
                seconds(std::chrono::duration<double>(stalled_after_).count()) + " s" +
                (every_frame_ ? ", " + std::to_string(kept_.size()) + " kept" : "") +
                "): waiting for it or for another server to take the session over");
        }
        if (on_wait_) on_wait_();
    }
    if (!end_of_stream) next_seq_ = std::max(next_seq_, frame.seq + 1);
    if (end_of_stream && !end_) {
        end_ = frame;
        end_written_ = Clock::now();
    }
    if (stalled_) {
        stalled_ = false;
        on_event_("server '" + state_.owner + "' takes frames again");
        say("");
    }
    return true;
}

Status SessionStream::send(const wire::EncodedFrame& frame, bool end_of_stream, const std::atomic<bool>& stop,
                           float timeout_s) {
    const auto deadline = deadlineAfter(timeout_s);
    for (;;) {
        if (stop) {
            if (every_frame_ && !end_of_stream) unsent_.push_back(frame);
            return Status::ok();
        }
        if (Clock::now() > deadline) return deadlineExceeded("no server took the frame in time");
        if (!follow(stop, deadline)) {
            if (on_wait_) on_wait_();
            std::this_thread::sleep_for(20ms);
            continue;
        }
        if (every_frame_ && kept_.full()) {
            say("waiting for server '" + state_.owner + "' to confirm frames (" + std::to_string(kept_.size()) +
                " kept, the limit)");
            if (on_wait_) on_wait_();
            std::this_thread::sleep_for(20ms);
            continue;
        }
        break;
    }
    // Kept before it is written: a write given up (a stop, another owner) leaves it where the next follow()
    // resends it from, or where unconfirmed() finds it.
    if (every_frame_) kept_.push(frame, end_of_stream);
    state_.kept = kept_.size();
    ASSIGN_OR_RETURN(const bool written, write(frame, end_of_stream, stop, deadline));
    if (!written && !every_frame_) return Status::ok();  // a live frame: the next one matters more
    if (!written && stop) {
        kept_.popBack();  // never written: it goes with the unsent frames, after the end of the stream
        if (!end_of_stream) unsent_.push_back(frame);
        state_.kept = kept_.size();
        return Status::ok();
    }
    if (!written && Clock::now() >= deadline && !stop) return deadlineExceeded("no server took the frame in time");
    if (!end_of_stream) {
        state_.digest = wire::frameDigest(state_.digest, frame.depth.data(), frame.depth.size(), frame.colour.data(),
                                          frame.colour.size());
    }
    return Status::ok();
}

bool SessionStream::waitFinished(const std::atomic<bool>& stop, float timeout_s, float grace_after_stop_s) {
    auto deadline = deadlineAfter(timeout_s);
    bool stopped = false;
    for (;;) {
        if (stop && !stopped) {
            // Ctrl-C: a short grace for the server to finish, not the whole timeout.
            stopped = true;
            deadline = std::min(deadline, deadlineAfter(grace_after_stop_s));
        }
        const bool served = follow(stop, deadline);
        if (finished()) return true;
        if (Clock::now() >= deadline) return false;
        if (served && end_ && Clock::now() - end_written_ >= kEndRepeat) {
            // The owner may never have had it (it was lost with an owner that had it confirmed, or a write of it
            // was cut short): once more. An owner that has it already drops the duplicate.
            end_written_ = Clock::now();
            (void)write(*end_, /*end_of_stream=*/true, stop, std::min(deadline, Clock::now() + kEndRepeat));
        }
        if (on_wait_) on_wait_();
        std::this_thread::sleep_for(20ms);
    }
}

std::vector<wire::EncodedFrame> SessionStream::unconfirmed() {
    link_.poll();
    if (const std::optional<OwnerInfo>& o = link_.owner()) dropConfirmed(o->data.confirmed_seq);
    std::vector<wire::EncodedFrame> frames;
    kept_.forEachFrom(0, [&](const wire::EncodedFrame& f, bool eos) {
        if (!eos) frames.push_back(f);
        return true;
    });
    frames.insert(frames.end(), unsent_.begin(), unsent_.end());
    return frames;
}

uint32_t SessionStream::nextSeq() const {
    // A recording's frame whose write an owner change cut short is kept, not written, and goes to the next owner
    // before the end of the stream: the end comes after it. Numbered after the frames written alone, the end took
    // that frame's number when it was the last one, every later owner dropped it as a duplicate, and the scan was
    // never finished (a chaos soak's recording of 120 frames, all integrated by four owners in turn, lost).
    return std::max(next_seq_, kept_.nextAfterFrames(0));
}

StreamState SessionStream::state() const { return state_; }

uint32_t SessionStream::servingEpoch() const {
    const std::optional<OwnerInfo>& o = link_.owner();
    return o && o->serving() ? o->data.epoch : 0u;
}

void SessionStream::dropConfirmed(uint32_t confirmed_seq) {
    kept_.dropBefore(confirmed_seq);
    if (every_frame_) state_.dropped_before = std::max(state_.dropped_before, confirmed_seq);
}

}  // namespace facescan::capture
