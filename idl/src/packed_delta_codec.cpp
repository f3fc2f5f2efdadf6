// Histogram-packed delta tokens (format in wire/packed_delta_codec.hpp), with bounds checks on every read for network
// input.
#include "wire/packed_delta_codec.hpp"

#include <cstring>
#include <string>

namespace facescan::wire::packed {
namespace {

constexpr uint8_t kEscape = 0xff;

inline uint16_t zigzag(uint16_t d) { return static_cast<uint16_t>((d << 1) ^ static_cast<uint16_t>(-(d >> 15))); }
inline uint16_t unzigzag(uint16_t z) { return static_cast<uint16_t>((z >> 1) ^ static_cast<uint16_t>(-(z & 1))); }

}  // namespace

size_t encode(const uint16_t* pixels, int width, int height, uint16_t* rank_of, uint8_t* out) {
    const size_t n = size_t(width) * size_t(height);
    // Value map: which of the 65536 values occur; rank_of doubles as the "seen" flags before ranks are assigned.
    std::memset(rank_of, 0, 65536 * sizeof(uint16_t));
    for (size_t i = 0; i < n; ++i) rank_of[pixels[i]] = 1;
    uint8_t* map = out;
    std::memset(map, 0, kValueMapBytes);
    uint16_t rank = 0;
    for (uint32_t v = 0; v < 65536; ++v) {
        if (rank_of[v] == 0) continue;
        map[v >> 3] = static_cast<uint8_t>(map[v >> 3] | (1u << (v & 7)));
        rank_of[v] = rank++;  // wraps to 0 only after the last of 65536 values: never read again
    }

    uint8_t* q = out + kValueMapBytes;
    for (int r = 0; r < height; ++r) {
        const uint16_t* row = pixels + size_t(r) * size_t(width);
        uint16_t pred = r > 0 ? rank_of[row[-width]] : 0;
        for (int c = 0; c < width; ++c) {
            const uint16_t k = rank_of[row[c]];
            const uint16_t z = zigzag(static_cast<uint16_t>(k - pred));
            pred = k;
            if (z < kEscape) {
                *q++ = static_cast<uint8_t>(z);
            } else {
                q[0] = kEscape;
                q[1] = static_cast<uint8_t>(z);
                q[2] = static_cast<uint8_t>(z >> 8);
                q += 3;
            }
        }
    }
    return static_cast<size_t>(q - out);
}

Status decode(const uint8_t* tokens, size_t size, int width, int height, uint16_t* value_of, uint16_t* pixels) {
    if (size < kValueMapBytes) {
        return dataLoss("packed depth tokens truncated in the value map (" + std::to_string(size) + " bytes)");
    }
    uint32_t count = 0;
    for (uint32_t v = 0; v < 65536; ++v) {
        if (tokens[v >> 3] & (1u << (v & 7))) value_of[count++] = static_cast<uint16_t>(v);
    }
    if (count == 0) return dataLoss("packed depth value map is empty");

    const uint8_t* p = tokens + kValueMapBytes;
    const uint8_t* const end = tokens + size;
    uint16_t rank_above = 0;  // rank of the previous row's first pixel: column 0's prediction
    for (int r = 0; r < height; ++r) {
        uint16_t* row = pixels + size_t(r) * size_t(width);
        uint16_t pred = rank_above;
        for (int c = 0; c < width; ++c) {
            if (p >= end) return dataLoss("packed depth tokens end at pixel " + std::to_string(size_t(r) * width + c));
            uint16_t z = *p++;
            if (z == kEscape) {
                if (end - p < 2) return dataLoss("packed depth tokens end inside an escaped token");
                z = static_cast<uint16_t>(p[0] | p[1] << 8);
                p += 2;
            }
            const uint16_t k = static_cast<uint16_t>(pred + unzigzag(z));
            if (k >= count) {
                return dataLoss("packed depth rank " + std::to_string(k) + " outside the value map's " +
                                std::to_string(count) + " values");
            }
            row[c] = value_of[k];
            pred = k;
            if (c == 0) rank_above = k;
        }
    }
    if (p != end) return dataLoss("packed depth tokens have " + std::to_string(end - p) + " bytes left over");
    return Status::ok();
}

}  // namespace facescan::wire::packed
