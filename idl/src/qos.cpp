#include "wire/topics.hpp"

namespace facescan::wire {
namespace {

// Reliable writers block at most this long when a keep-all history is full, then report a timeout.
constexpr int64_t kMaxBlocking = DDS_SECS(5);

Qos reliable(dds_durability_kind_t durability, dds_history_kind_t history, int32_t depth) {
    Qos q;
    dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, kMaxBlocking);
    dds_qset_durability(q.get(), durability);
    dds_qset_history(q.get(), history, depth);
    return q;
}

}  // namespace

Qos cameraInfoQos() { return reliable(DDS_DURABILITY_TRANSIENT_LOCAL, DDS_HISTORY_KEEP_LAST, 1); }
Qos rgbdFrameQos() { return reliable(DDS_DURABILITY_VOLATILE, DDS_HISTORY_KEEP_LAST, 8); }
Qos scanStatusQos() { return reliable(DDS_DURABILITY_TRANSIENT_LOCAL, DDS_HISTORY_KEEP_LAST, 1); }
Qos meshSnapshotQos() { return reliable(DDS_DURABILITY_TRANSIENT_LOCAL, DDS_HISTORY_KEEP_LAST, 1); }
Qos commandQos() { return reliable(DDS_DURABILITY_VOLATILE, DDS_HISTORY_KEEP_ALL, 0); }

namespace {
Qos noAutoDispose(Qos q) {
    dds_qset_writer_data_lifecycle(q.get(), false);
    return q;
}
}  // namespace

Qos erasureQos() { return noAutoDispose(reliable(DDS_DURABILITY_TRANSIENT_LOCAL, DDS_HISTORY_KEEP_LAST, 1)); }

Qos serverAnnounceQos() { return noAutoDispose(reliable(DDS_DURABILITY_TRANSIENT_LOCAL, DDS_HISTORY_KEEP_LAST, 1)); }
Qos sessionOwnerQos() {
    Qos q = noAutoDispose(reliable(DDS_DURABILITY_TRANSIENT_LOCAL, DDS_HISTORY_KEEP_LAST, 1));
    dds_qset_ownership(q.get(), DDS_OWNERSHIP_EXCLUSIVE);
    return q;
}
Qos claimWriterQos(int32_t strength) {
    Qos q = sessionOwnerQos();
    dds_qset_ownership_strength(q.get(), strength);
    return q;
}
Qos withProgressLiveliness(Qos q, double lease_s) {
    dds_qset_liveliness(q.get(), DDS_LIVELINESS_MANUAL_BY_PARTICIPANT, static_cast<dds_duration_t>(lease_s * 1e9));
    return q;
}
Qos withClaimLiveliness(Qos q, double lease_s) {
    dds_qset_liveliness(q.get(), DDS_LIVELINESS_MANUAL_BY_TOPIC, static_cast<dds_duration_t>(lease_s * 1e9));
    return q;
}
Qos replicaQos() {
    Qos q = reliable(DDS_DURABILITY_VOLATILE, DDS_HISTORY_KEEP_ALL, 0);
    // A few replicas in flight per standby: a slow standby blocks the owner's replication thread (never its
    // frame path), and the owner then skips a round instead of queueing megabytes.
    dds_qset_resource_limits(q.get(), 4, DDS_LENGTH_UNLIMITED, 4);
    return q;
}
Qos replicaAckQos() { return reliable(DDS_DURABILITY_VOLATILE, DDS_HISTORY_KEEP_LAST, 4); }

std::string sessionPartition(const std::string& session_id) { return "facescan.session." + session_id; }
std::string serverPartition(const std::string& server_id) { return "facescan.server." + server_id; }

Qos frameWriterQos(bool every_frame) {
    if (!every_frame) return rgbdFrameQos();
    Qos q = reliable(DDS_DURABILITY_VOLATILE, DDS_HISTORY_KEEP_ALL, 0);
    // Bounded so that a stalled server stops the agent (which then waits) instead of filling its memory.
    dds_qset_resource_limits(q.get(), 32, DDS_LENGTH_UNLIMITED, 32);
    return q;
}

Qos frameReaderQos() {
    Qos q = reliable(DDS_DURABILITY_VOLATILE, DDS_HISTORY_KEEP_ALL, 0);
    dds_qset_resource_limits(q.get(), 256, DDS_LENGTH_UNLIMITED, 16);
    return q;
}

}  // namespace facescan::wire
