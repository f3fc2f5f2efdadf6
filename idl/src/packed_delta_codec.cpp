// Histogram-packed delta tokens (format in wire/packed_delta_codec.hpp), with bounds checks on every read for network
// input (the decoder checks a run of 8 tokens once, then decodes it without further checks).
#include "wire/packed_delta_codec.hpp"

#include <cstring>
#include <string>

namespace facescan::wire::packed {
namespace {

constexpr uint8_t kEscape = 0xff;

inline uint16_t zigzag(uint16_t d) { return static_cast<uint16_t>((d << 1) ^ static_cast<uint16_t>(-(d >> 15))); }
inline uint16_t unzigzag(uint16_t z) { return static_cast<uint16_t>((z >> 1) ^ static_cast<uint16_t>(-(z & 1))); }

// GCC/clang vector extensions: SIMD on any target without intrinsics.
using Bytes8 = uint8_t __attribute__((vector_size(8)));
using U16x8 = uint16_t __attribute__((vector_size(16)));
using I16x8 = int16_t __attribute__((vector_size(16)));

// Whether any of the 8 bytes at p is the escape 0xFF (the classic has-zero-byte test on the complement).
inline bool hasEscape8(const uint8_t* p) {
    uint64_t word;
    std::memcpy(&word, p, sizeof word);
    const uint64_t x = ~word;
    return ((x - 0x0101010101010101ull) & ~x & 0x8080808080808080ull) != 0;
}

// The ranks of the 8 pixels whose one-byte tokens are at p, after a pixel of rank k: k plus the running sum of
// their deltas, modulo 2^16 as in the scalar loop (a prefix sum in three shifted adds).
inline U16x8 ranksOf8(const uint8_t* p, uint16_t k) {
    Bytes8 t;
    std::memcpy(&t, p, sizeof t);
    const U16x8 z = __builtin_convertvector(t, U16x8);
    const U16x8 zero = {};
    U16x8 d = (z >> 1) ^ -(z & 1);  // unzigzag, 8 lanes
    d += __builtin_shufflevector(zero, d, 0, 8, 9, 10, 11, 12, 13, 14);
    d += __builtin_shufflevector(zero, d, 0, 0, 8, 9, 10, 11, 12, 13);
    d += __builtin_shufflevector(zero, d, 0, 0, 0, 0, 8, 9, 10, 11);
    return d + k;
}

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
    // The set bits of the map in order: a byte at a time, most of them 0.
    uint32_t count = 0;
    for (uint32_t byte = 0; byte < kValueMapBytes; ++byte) {
        for (unsigned bits = tokens[byte]; bits != 0; bits &= bits - 1) {
            value_of[count++] = static_cast<uint16_t>(byte * 8 + static_cast<uint32_t>(__builtin_ctz(bits)));
        }
    }
    if (count == 0) return dataLoss("packed depth value map is empty");
    const auto max_rank = static_cast<uint16_t>(count - 1);
    auto outside = [&](uint16_t k) {
        return dataLoss("packed depth rank " + std::to_string(k) + " outside the value map's " + std::to_string(count) +
                        " values");
    };

    const uint8_t* p = tokens + kValueMapBytes;
    const uint8_t* const end = tokens + size;
    uint16_t rank_above = 0;  // rank of the previous row's first pixel: column 0's prediction
    for (int r = 0; r < height; ++r) {
        uint16_t* row = pixels + size_t(r) * size_t(width);
        uint16_t k = rank_above;
        int c = 0;
        while (c < width) {
            // Eight one-byte tokens inside the row and the stream: no bounds check per pixel, and their ranks are a
            // running sum 8 lanes wide instead of a chain of 8 dependent additions (the decoder's bottleneck).
            if (width - c >= 8 && end - p >= 8 && !hasEscape8(p)) {
                const U16x8 ks = ranksOf8(p, k);
                const I16x8 bad = ks > max_rank;
                uint64_t bad_bits[2];
                std::memcpy(bad_bits, &bad, sizeof bad_bits);
                if ((bad_bits[0] | bad_bits[1]) != 0) {
                    for (int i = 0; i < 8; ++i) {
                        if (ks[i] > max_rank) return outside(ks[i]);  // the first in raster order, as below
                    }
                }
                for (int i = 0; i < 8; ++i) row[c + i] = value_of[ks[i]];
                if (c == 0) rank_above = ks[0];
                k = ks[7];
                p += 8;
                c += 8;
                continue;
            }
            // One token, every read checked: an escape, the row's last pixels, the stream's last bytes.
            if (p >= end) return dataLoss("packed depth tokens end at pixel " + std::to_string(size_t(r) * width + c));
            uint16_t z = *p++;
            if (z == kEscape) {
                if (end - p < 2) return dataLoss("packed depth tokens end inside an escaped token");
                z = static_cast<uint16_t>(p[0] | p[1] << 8);
                p += 2;
            }
            k = static_cast<uint16_t>(k + unzigzag(z));
            if (k > max_rank) return outside(k);
            row[c] = value_of[k];
            if (c == 0) rank_above = k;
            ++c;
        }
    }
    if (p != end) return dataLoss("packed depth tokens have " + std::to_string(end - p) + " bytes left over");
    return Status::ok();
}

}  // namespace facescan::wire::packed
