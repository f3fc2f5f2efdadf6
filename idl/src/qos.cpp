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
