// libFuzzer target: decodeReplica and mergeReplica (the bytes a standby receives from an owner over DDS, and a
// restarted server reads from its data dir). Input byte 0 picks the mode:
//   0: the bytes are a whole replica (header, zstd frame, body);
//   1: the bytes are a replica BODY, put behind a valid header in a valid zstd frame first, so the fuzzer reaches
//      the body's parser and checks without having to keep a checksum in step with its mutations (flag: full);
//   2: two bodies (split at byte 1-2), both framed; the second is merged onto the first when both decode.
// Whatever decodes must validate, encode again and decode to the same state.
#include <cstring>

#include "wire/replica_codec.hpp"

namespace {

using namespace facescan;

bool decodeBody(const uint8_t* data, size_t size, bool full, wire::ReplicaData& out) {
    std::vector<uint8_t> framed;
    if (!wire::frameReplicaBody(data, size, full, framed).isOk()) return false;
    return wire::decodeReplica(framed.data(), framed.size(), out).isOk();
}

void roundTrip(const wire::ReplicaData& r) {
    if (!r.state.validate().isOk()) __builtin_trap();
    std::vector<uint8_t> again;
    if (!wire::encodeReplica(r, again).isOk()) __builtin_trap();
    wire::ReplicaData back;
    if (!wire::decodeReplica(again.data(), again.size(), back).isOk()) __builtin_trap();
    if (back.round != r.round || back.next_seq != r.next_seq || back.state.blocks.coords != r.state.blocks.coords ||
        back.state.trajectory.size() != r.state.trajectory.size()) {
        __builtin_trap();
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    if (size < 1) return 0;
    const uint8_t mode = data[0] % 3;
    const bool full = (data[0] & 0x80) != 0;
    ++data;
    --size;
    wire::ReplicaData r;
    if (mode == 0) {
        if (wire::decodeReplica(data, size, r).isOk()) roundTrip(r);
        return 0;
    }
    if (mode == 1) {
        if (decodeBody(data, size, full, r)) roundTrip(r);
        return 0;
    }
    if (size < 2) return 0;
    const size_t split = std::min<size_t>(size - 2, (size_t{data[0]} << 8) | data[1]);
    wire::ReplicaData delta;
    if (!decodeBody(data + 2, split, true, r) || !decodeBody(data + 2 + split, size - 2 - split, full, delta)) return 0;
    if (wire::mergeReplica(r, delta).isOk()) roundTrip(r);
    return 0;
}
