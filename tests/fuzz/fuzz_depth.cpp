// libFuzzer target: DepthDecoder for one codec (FUZZ_DEPTH_CODEC_NAME, one binary per codec id).
// Input byte 0 picks the mode: even = the bytes are a whole payload (header parsing and the checks against the
// expected size); odd = bytes 1-2 give a size (1..256 each side) and the rest is a body behind a valid header, so
// the fuzzer reaches the codec bodies without having to keep the header's body size in step with its mutations.
// A payload that decodes must re-encode and decode to the same image (lossless codecs are bijective on images).
#include <cstring>

#include "wire/depth_codec.hpp"

namespace {

using facescan::wire::DepthCodecId;

DepthCodecId codecUnderTest() {
    static const DepthCodecId codec = *facescan::wire::depthCodecFromName([] {
        std::string name = FUZZ_DEPTH_CODEC_NAME;
        for (char& c : name) c = c == '_' ? '-' : c;
        return name;
    }());
    return codec;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan::wire;
    static DepthDecoder decoder;
    static cv::Mat depth;
    if (size < 1) return 0;
    const DepthCodecId codec = codecUnderTest();
    int w = 16;
    int h = 12;
    std::vector<uint8_t> payload;
    if ((data[0] & 1) == 0) {
        payload.assign(data + 1, data + size);
        auto header = parseDepthHeader(payload.data(), payload.size());
        if (header.isOk() && header->width_px * header->height_px <= 256 * 256) {
            w = header->width_px;
            h = header->height_px;
        }
    } else {
        if (size < 3) return 0;
        w = 1 + data[1];
        h = 1 + data[2];
        payload.resize(kDepthHeaderBytes + size - 3);
        const size_t body = size - 3;
        const uint8_t header[kDepthHeaderBytes] = {'F',
                                                   'S',
                                                   'D',
                                                   1,
                                                   static_cast<uint8_t>(codec),
                                                   0,
                                                   static_cast<uint8_t>(w),
                                                   static_cast<uint8_t>(w >> 8),
                                                   static_cast<uint8_t>(h),
                                                   static_cast<uint8_t>(h >> 8),
                                                   0,
                                                   0,
                                                   static_cast<uint8_t>(body),
                                                   static_cast<uint8_t>(body >> 8),
                                                   static_cast<uint8_t>(body >> 16),
                                                   static_cast<uint8_t>(body >> 24)};
        std::memcpy(payload.data(), header, kDepthHeaderBytes);
        if (body > 0) std::memcpy(payload.data() + kDepthHeaderBytes, data + 3, body);
    }
    if (!decoder.decode(codec, payload.data(), payload.size(), w, h, depth).isOk()) return 0;
    if (depth.cols != w || depth.rows != h || depth.type() != CV_16UC1) __builtin_trap();
    DepthCodecParams params;
    params.codec = codec;
    std::vector<uint8_t> again;
    if (!encodeDepth(depth, params, again).isOk()) __builtin_trap();
    cv::Mat round_trip;
    if (!decoder.decode(codec, again.data(), again.size(), w, h, round_trip).isOk()) __builtin_trap();
    if (cv::norm(round_trip, depth, cv::NORM_INF) != 0.0) __builtin_trap();
    return 0;
}
