// RVL: A. D. Wilson, "Fast lossless depth image compression", ISS 2017. The body format of DepthCodecId::kRvl
// (and the pre-pass of kRvlZstd). Runs of zeros and non-zeros alternate; each count and each zigzagged delta to
// the previous non-zero pixel is a variable-length code of 3-bit groups in nibbles (high bit = more follows),
// packed eight nibbles per little-endian 32-bit word, most significant nibble first, exactly as Wilson's code.
// Unlike the paper's int16 version, deltas are taken on uint16 values, so depths above 32767 round-trip too.
#pragma once

#include <cstddef>
#include <cstdint>

#include "recon/status.hpp"

namespace facescan::wire::rvl {

// Worst case: a 17-bit zigzag delta takes 6 nibbles per pixel; run counts and the last partial word add a few.
inline constexpr size_t maxEncodedBytes(size_t pixel_count) { return pixel_count * 3 + 32; }

// Encodes pixel_count pixels into out (capacity >= maxEncodedBytes(pixel_count)); returns the bytes written,
// always a multiple of 4.
size_t encode(const uint16_t* pixels, size_t pixel_count, uint8_t* out);

// Decodes exactly pixel_count pixels. DATA_LOSS when the stream ends early, a run overflows the image, a
// non-zero run decodes a zero or out-of-range value, a code is longer than any valid one, or bytes are left over.
Status decode(const uint8_t* data, size_t size, uint16_t* pixels, size_t pixel_count);

}  // namespace facescan::wire::rvl
