// Whether this server may act on its view of the cluster, and whether it is alive in a sense that matters: its
// liveliness on the domain is asserted by the loop that does its work (a stuck server loses its claims within the
// lease, as a dead one does), its watchdog ends it when a loop stays stuck, and a server that was frozen re-observes
// the cluster before it acts on anything (server.hpp says what it holds meanwhile).
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "service/server.hpp"

namespace facescan::service {
namespace {

// A server that found itself stuck exits with this (EX_SOFTWARE): systemd's Restart=on-failure starts it again.
constexpr int kExitStalled = 70;

// FACESCAN_STALL_STACKS=1: before a stuck server exits, gdb prints every thread's stack into its log. A stall that
// only a rare interleaving causes (the chaos test's) is gone once the server restarts; its stacks name the lock or
// the wait behind it. For engineers and tests: a user's server exits at once.
void printStacksIfAsked() {
    const char* ask = std::getenv("FACESCAN_STALL_STACKS");
    if (ask == nullptr || std::string(ask) != "1") return;
    const std::string pid = std::to_string(::getpid());
    const char* argv[] = {"gdb", "-batch", "-nx", "-p", pid.c_str(), "-ex", "thread apply all bt", nullptr};
    pid_t child = 0;
    if (::posix_spawnp(&child, "gdb", nullptr, nullptr, const_cast<char* const*>(argv), environ) != 0) {
        std::fprintf(stderr, "facescan-server: FACESCAN_STALL_STACKS: could not start gdb (apt-get install gdb)\n");
        return;
    }
    int status = 0;
    (void)::waitpid(child, &status, 0);
}

}  // namespace

void Server::noticePause(int64_t gap_ns, int64_t now_ns) {
    view_stale_until_ns_ = now_ns + 2 * lease_ns_;
    // Its claims lapse in the others' view a lease after its last assertion. Short of that (less a margin for the
    // way there), nobody can have taken its sessions over, and holding them would only stall their scans. The
    // whole process was paused, so nothing was asserted during the gap: the intake thread may have woken first and
    // asserted already (a 9 s freeze in the chaos soak read as "asserted 0.0 s ago"), so the gap counts as well.
    const int64_t unasserted_ns = std::max(gap_ns, now_ns - last_progress_ns_.load());
    if (unasserted_ns >= lease_ns_ - lease_ns_ / 6) {
        hold_until_ns_ = now_ns + 2 * lease_ns_;
        std::fprintf(stderr,
                     "facescan-server: this server did not run for %.1f s (frozen, or the machine paused): its view "
                     "of the cluster is stale; re-observing it for %.1f s before taking anything over, and holding "
                     "its own sessions until it knows it still owns them\n",
                     static_cast<double>(gap_ns) * 1e-9, 2 * static_cast<double>(lease_ns_) * 1e-9);
        return;
    }
    std::fprintf(stderr,
                 "facescan-server: this server did not run for %.1f s (frozen, or the machine paused): its view of the "
                 "cluster is stale; re-observing it for %.1f s before taking anything over. Its own sessions go on: "
                 "its liveliness was asserted %.1f s ago, within the %.1f s lease, so none can have been taken over\n",
                 static_cast<double>(gap_ns) * 1e-9, 2 * static_cast<double>(lease_ns_) * 1e-9,
                 static_cast<double>(unasserted_ns) * 1e-9, static_cast<double>(lease_ns_) * 1e-9);
}

bool Server::viewFresh() const {
    // The watchdog's last check must be recent too: after a pause the other threads may wake before the watchdog
    // has noticed it, and they must not act in the meantime.
    const int64_t now = steadyNowNs();
    return now >= view_stale_until_ns_.load() && now - watchdog_->lastCheckNs() < lease_ns_ / 2;
}

bool Server::ownSessionsFree() const { return sessionFree(/*recording=*/true); }

bool Server::sessionFree(bool recording) const {
    // After a pause long enough to lose its claims, only recordings are held. What the hold guards against is a
    // server that goes on confirming frames of a scan that was taken over meanwhile (its agent then drops frames
    // the new owner's copy lacks). A live scan's agent keeps no frames, so nothing can be confirmed away: the worst
    // a live session taken over meanwhile does here is integrate frames that it drops, writing nothing, when it
    // sees the stronger claim. Held, it would stall the person's scan for two leases after every such pause.
    const int64_t now = steadyNowNs();
    if (now - watchdog_->lastCheckNs() >= lease_ns_ / 2) return false;  // the pause is not noticed yet
    return !recording || now >= hold_until_ns_.load();
}

void Server::finishIdle(OwnedSession& o) {
    if (o.recording && o.agent_alive) {
        // A recording's agent that lives still holds the frames to come (a takeover, a peer that holds its writes
        // back): finishing now would make a partial scan of the person for good.
        if (!o.idle_said) {
            std::fprintf(stderr,
                         "facescan-server: session %s: no frame for %.0f s, but its agent (a recording) is still "
                         "there: waiting for the rest instead of finishing without it (facescan finish %s ends it "
                         "now)\n",
                         o.id.c_str(), params_.idle_timeout_s, o.id.c_str());
            o.idle_said = true;
        }
        return;
    }
    o.session->requestFinish("idle for " + std::to_string(static_cast<int>(params_.idle_timeout_s)) + " s", nullptr);
}

void Server::assertProgress(int64_t now_ns) {
    // The announcement's liveliness (the claims live by their own writes, Server::refreshClaims). A few times a
    // lease is enough for the readers' lease, and cheap (one small message per peer). Often enough that a server cut
    // off sees the agents' leases lapse soon after its peers' claims (Server::witnessed).
    if (now_ns - last_progress_ns_.load() < lease_ns_ / 12) return;
    last_progress_ns_ = now_ns;
    if (const dds_return_t rc = dds_assert_liveliness(participant_->handle()); rc < 0) {
        std::fprintf(stderr, "facescan-server: %s\n", wire::ddsStatus(rc, "assert liveliness").toString().c_str());
    }
}

void Server::refreshClaims(int64_t now_ns) {
    // Each claim this server holds is written again a few times a lease, whether it changed or not: a claim lives by
    // its own writes (MANUAL_BY_TOPIC, wire::withClaimLiveliness), and this is what keeps it alive at every reader.
    // From the intake thread and through the claim, so a server whose work has stopped lets its claims lapse
    // (Claim's `progressing`). Also while its view is stale after a pause: the claims are what tells the others it
    // is back, and a claim at its epoch cannot win over a takeover made meanwhile (a higher epoch). Held back for
    // the two leases of re-observing, they lapsed after a 2.7 s freeze, and two servers took a live scan that the
    // owner was finishing over from old copies. The same write revives a claim of ours that reads as not alive while
    // we hold it: a weaker writer of the same instance (an old owner back from a partition, which then withdraws)
    // can leave readers with no live writer although ours still writes, and the agent would wait for a standby. It
    // also covers a weaker claim shown instead of ours while ours has not reached a reader yet. A stronger claim
    // still wins on ownership strength. Six times a lease: a claim lapses only after the intake thread missed five
    // writes in a row, on a loaded machine too.
    if (now_ns - claims_refreshed_ns_ < lease_ns_ / 6) return;
    claims_refreshed_ns_ = now_ns;
    for (const auto& o : ownedSessions()) {
        const OwnedSession::Phase phase = o->phase;
        if (!o->claim || phase == OwnedSession::Phase::kFinished || phase == OwnedSession::Phase::kGivenUp) continue;
        o->claim->update([](wire::SessionOwnerData&) {}, /*force=*/true);
    }
}

void Server::failpoint() {
    std::error_code ec;
    if (!std::filesystem::exists(stall_file_, ec)) return;
    std::fprintf(stderr, "facescan-server: failpoint: the intake thread stops (%s exists)\n", stall_file_.c_str());
    while (!stopping_) std::this_thread::sleep_for(std::chrono::milliseconds(100));
}

bool Server::claimsMayBeWritten() const {
    std::error_code ec;
    if (!claims_silent_file_.empty() && std::filesystem::exists(claims_silent_file_, ec)) return false;
    const int64_t since = intake_beat_->busySinceNs();
    return since == 0 || steadyNowNs() - since < lease_ns_ / 3;
}

void Server::onStall(const std::string& what) {
    std::fprintf(stderr,
                 "facescan-server: stuck: %s. Exiting with status %d so that the service manager restarts this "
                 "server; the cluster takes its sessions over from their standbys and data dir.\n",
                 what.c_str(), kExitStalled);
    std::fflush(stderr);
    printStacksIfAsked();
    std::_Exit(kExitStalled);
}

}  // namespace facescan::service
