// Lossless depth codecs for RgbdFrame.depth (docs/design.md section 3). Depth must arrive bit-exact: fusion accuracy
// starts at the raw sensor value, so every codec here is lossless and round-trips every uint16 image.
//
// Every payload starts with a 16-byte self-describing header (magic "FSD", version, codec, width, height, body
// size) so a decoder checks the claimed size against what it expects (CameraInfo) BEFORE it allocates, and a
// truncated or padded payload is caught before any codec runs. The codec tag also travels in the message
// (RgbdFrame.depth_codec); the decoder checks that both agree.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string_view>
#include <vector>

#include "recon/status.hpp"

namespace facescan::wire {

// Same numbering as the IDL enum facescan::wire::DepthCodec (static_assert in depth_codec.cpp).
enum class DepthCodecId : uint8_t {
    kRaw16 = 0,            // little-endian uint16 pixels, no compression
    kRvl = 1,              // Wilson 2017 "Fast lossless depth image compression" (run length + variable-length deltas)
    kZstd = 2,             // zstd over the raw little-endian pixels
    kRvlZstd = 3,          // RVL, then zstd over the RVL words
    kDeltaZstd = 4,        // left-neighbour delta, zigzag, split into low/high byte planes, then zstd
    kPng = 5,              // 16-bit greyscale PNG (OpenCV imencode): the baseline
    kPackedDeltaZstd = 6,  // histogram packing + left delta, byte tokens, then zstd (wire/packed_delta_codec.hpp)
};
inline constexpr int kDepthCodecCount = 7;

const char* depthCodecName(DepthCodecId codec);  // "rvl", "rvl-zstd", ...
std::optional<DepthCodecId> depthCodecFromName(std::string_view name);
// A tag from the wire (RgbdFrame.depth_codec) checked against the known codecs.
StatusOr<DepthCodecId> depthCodecFromTag(uint32_t tag);

// Absolute caps whatever the caller expects: no decoder allocates more than 4096 x 4096 x 2 bytes of image.
inline constexpr int kMaxDepthWidthPx = 4096;
inline constexpr int kMaxDepthHeightPx = 4096;
inline constexpr size_t kDepthHeaderBytes = 16;

struct DepthCodecParams {
    // Shipped default: histogram-packed deltas + zstd level 1 with a fast match step. Measured
    // (`facescan-bench codecs`, 640x480 frames) it has the best ratio of the codecs at under 1 ms encode on every
    // Kinect-like set; `facescan-bench codecs` prints the per-set table.
    DepthCodecId codec = DepthCodecId::kPackedDeltaZstd;
    int zstd_level = 1;  // zstd compression level [-7, 19]; 1 is the fastest positive level
    // kPackedDeltaZstd only, at zstd levels <= 1 (zstd's "fast" strategy): the match finder's step
    // (ZSTD_c_targetLength). Depth residuals are nearly all literals, so searching every position for matches
    // costs time and finds little; literals stay Huffman-coded. 0 = zstd's own default.
    int zstd_fast_step = 32;  // [0, 1024]
    int png_compression = 1;  // zlib level for the PNG baseline [0, 9]

    Status validate() const;
};

struct DepthPayloadHeader {
    DepthCodecId codec = DepthCodecId::kRaw16;
    int width_px = 0;
    int height_px = 0;
    size_t body_bytes = 0;  // bytes after the header
};
// Parses and checks the header only (magic, version, codec, caps, body size == size - header).
StatusOr<DepthPayloadHeader> parseDepthHeader(const uint8_t* data, size_t size);

// Encodes CV_16UC1 images. Keeps the zstd context and scratch buffers, so after the first frame of a given
// size encode() does not allocate (out's capacity is reused too; the PNG baseline is the exception: OpenCV's
// imencode allocates). Thread-compatible: one encoder per thread.
class DepthEncoder {
 public:
    explicit DepthEncoder(DepthCodecParams params = {});
    ~DepthEncoder();
    DepthEncoder(DepthEncoder&&) noexcept;
    DepthEncoder& operator=(DepthEncoder&&) noexcept;
    DepthEncoder(const DepthEncoder&) = delete;
    DepthEncoder& operator=(const DepthEncoder&) = delete;

    const DepthCodecParams& params() const { return params_; }
    // depth_u16: CV_16UC1, 1..4096 pixels each side, any stride. out is overwritten (header + body).
    Status encode(const cv::Mat& depth_u16, std::vector<uint8_t>& out);

 private:
    struct State;
    DepthCodecParams params_;
    std::unique_ptr<State> state_;
};

// Decodes payloads of any codec. Checks the header against the expected size before it allocates, never reads
// past `size`, and returns DATA_LOSS / OUT_OF_RANGE / INVALID_ARGUMENT on corrupt, truncated or oversized input.
// Keeps its zstd context and scratch buffers (no allocation per frame after warm-up). Thread-compatible.
class DepthDecoder {
 public:
    DepthDecoder();
    ~DepthDecoder();
    DepthDecoder(DepthDecoder&&) noexcept;
    DepthDecoder& operator=(DepthDecoder&&) noexcept;
    DepthDecoder(const DepthDecoder&) = delete;
    DepthDecoder& operator=(const DepthDecoder&) = delete;

    // codec: the message's tag; expected_*: from CameraInfo. depth_u16 becomes CV_16UC1 expected_h x expected_w
    // (its buffer is reused when it already has that shape). On error depth_u16 content is unspecified.
    Status decode(DepthCodecId codec, const uint8_t* data, size_t size, int expected_width, int expected_height,
                  cv::Mat& depth_u16);

 private:
    struct State;
    std::unique_ptr<State> state_;
};

// One-shot helpers (they build a codec object per call: fine for tests and tools, not for a 30 Hz loop).
Status encodeDepth(const cv::Mat& depth_u16, const DepthCodecParams& params, std::vector<uint8_t>& out);
Status decodeDepth(DepthCodecId codec, const uint8_t* data, size_t size, int expected_width, int expected_height,
                   cv::Mat& depth_u16);

}  // namespace facescan::wire
