// Histogram-packed delta tokens: the pre-pass of DepthCodecId::kPackedDeltaZstd (zstd runs over its output).
//
// Why: a Kinect v1 measures disparity, and OpenNI converts it to millimetres through a table, so one frame uses only
// a sparse subset of the 16-bit values (at 0.7 m consecutive depths are ~1.4 mm apart, at 2 m ~10 mm). Deltas of
// raw millimetres therefore carry log2(step) bits of pure table structure per pixel. "Histogram packing" (a known
// lossless-image pre-pass; A. J. Pinho, "On the impact of histogram sparseness on some lossless
// image compression techniques", ICIP 2001) replaces
// each value by its rank among the values the frame uses, so deltas count disparity steps instead. The set of used
// values travels as a 65536-bit map (8 KB before zstd, a few hundred bytes after). Measured on 7-Scenes Kinect
// frames: 8.9:1 with zstd against 6.8:1 for plain deltas (`facescan-bench codecs`).
//
// Token stream: the 8192-byte value map (bit v of byte v/8 set <=> value v occurs), then one token per pixel in
// raster order: z = zigzag(uint16(rank - predicted rank)), predicted = the left pixel's rank (column 0: the pixel
// above; pixel 0: rank 0). z < 255 is one byte; otherwise 0xFF then z as two little-endian bytes. One byte per
// pixel for nearly every pixel halves zstd's input compared with 16-bit planes, which is where the time goes.
#pragma once

#include <cstddef>
#include <cstdint>

#include "recon/status.hpp"

namespace facescan::wire::packed {

inline constexpr size_t kValueMapBytes = 65536 / 8;

// Worst case: every pixel takes an escaped 3-byte token.
inline constexpr size_t maxTokenBytes(size_t pixel_count) { return kValueMapBytes + 3 * pixel_count; }

// Encodes a width x height image (contiguous rows) into out (capacity >= maxTokenBytes(width * height)); returns
// the bytes written. rank_of is caller-owned scratch of 65536 entries, so a 30 Hz encoder does not allocate.
size_t encode(const uint16_t* pixels, int width, int height, uint16_t* rank_of, uint8_t* out);

// Decodes exactly width x height pixels. value_of is caller-owned scratch of 65536 entries. DATA_LOSS when the
// value map is short or empty, the tokens end early, a rank falls outside the map, or bytes are left over.
Status decode(const uint8_t* tokens, size_t size, int width, int height, uint16_t* value_of, uint16_t* pixels);

}  // namespace facescan::wire::packed
