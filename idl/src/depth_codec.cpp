// Lossless depth codecs: header, dispatch, and the zstd / delta / PNG bodies (RVL is in rvl_codec.cpp).
#include "wire/depth_codec.hpp"

// For ZSTD_c_literalCompressionMode (zstd's "experimental" parameters; see zstdInto's fast_literals below).
#define ZSTD_STATIC_LINKING_ONLY
#include <zstd.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "wire/packed_delta_codec.hpp"
#include "wire/rvl_codec.hpp"

#if __has_include("facescan.h")
#include "facescan.h"
// The C++ ids are the IDL tags, so a message's depth_codec field converts with a cast.
static_assert(static_cast<int>(facescan::wire::DepthCodecId::kRaw16) == facescan_wire_DEPTH_RAW16);
static_assert(static_cast<int>(facescan::wire::DepthCodecId::kRvl) == facescan_wire_DEPTH_RVL);
static_assert(static_cast<int>(facescan::wire::DepthCodecId::kZstd) == facescan_wire_DEPTH_ZSTD);
static_assert(static_cast<int>(facescan::wire::DepthCodecId::kRvlZstd) == facescan_wire_DEPTH_RVL_ZSTD);
static_assert(static_cast<int>(facescan::wire::DepthCodecId::kDeltaZstd) == facescan_wire_DEPTH_DELTA_ZSTD);
static_assert(static_cast<int>(facescan::wire::DepthCodecId::kPng) == facescan_wire_DEPTH_PNG);
static_assert(static_cast<int>(facescan::wire::DepthCodecId::kPackedDeltaZstd) ==
              facescan_wire_DEPTH_PACKED_DELTA_ZSTD);
#endif

namespace facescan::wire {
namespace {

static_assert(std::endian::native == std::endian::little, "payloads are little-endian; add byte swaps for BE hosts");

constexpr uint8_t kMagic[3] = {'F', 'S', 'D'};
constexpr uint8_t kVersion = 1;
constexpr const char* kNames[kDepthCodecCount] = {
    "raw16", "rvl", "zstd", "rvl-zstd", "delta-zstd", "png", "packed-delta-zstd"};

void putU16(uint8_t* p, uint32_t v) {
    p[0] = static_cast<uint8_t>(v);
    p[1] = static_cast<uint8_t>(v >> 8);
}
void putU32(uint8_t* p, uint32_t v) {
    putU16(p, v & 0xffffu);
    putU16(p + 2, v >> 16);
}
uint32_t getU16(const uint8_t* p) { return uint32_t{p[0]} | uint32_t{p[1]} << 8; }
uint32_t getU32(const uint8_t* p) { return getU16(p) | getU16(p + 2) << 16; }
uint32_t getU32BigEndian(const uint8_t* p) {
    return uint32_t{p[0]} << 24 | uint32_t{p[1]} << 16 | uint32_t{p[2]} << 8 | uint32_t{p[3]};
}

// Layout: "FSD" version codec flags(0) width:u16 height:u16 reserved:u16(0) body_bytes:u32, little-endian.
void writeHeader(uint8_t* p, DepthCodecId codec, int width, int height, size_t body_bytes) {
    std::memcpy(p, kMagic, 3);
    p[3] = kVersion;
    p[4] = static_cast<uint8_t>(codec);
    p[5] = 0;
    putU16(p + 6, static_cast<uint32_t>(width));
    putU16(p + 8, static_cast<uint32_t>(height));
    putU16(p + 10, 0);
    putU32(p + 12, static_cast<uint32_t>(body_bytes));
}

std::string sizeText(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// Delta pre-pass of kDeltaZstd: each pixel minus its left neighbour (the pixel above for column 0), modulo 2^16,
// zigzagged so small negative steps become small codes, split into a low-byte and a high-byte plane: on depth
// the high plane is almost all zero and zstd squeezes it to nearly nothing.
void deltaPlanes(const uint16_t* px, int w, int h, uint8_t* planes) {
    const size_t n = size_t(w) * size_t(h);
    uint8_t* lo = planes;
    uint8_t* hi = planes + n;
    for (int r = 0; r < h; ++r) {
        const uint16_t* row = px + size_t(r) * size_t(w);
        uint16_t pred = r > 0 ? row[-w] : 0;
        const size_t base = size_t(r) * size_t(w);
        for (int c = 0; c < w; ++c) {
            const uint16_t d = static_cast<uint16_t>(row[c] - pred);
            const uint16_t z = static_cast<uint16_t>((d << 1) ^ static_cast<uint16_t>(-(d >> 15)));
            lo[base + c] = static_cast<uint8_t>(z);
            hi[base + c] = static_cast<uint8_t>(z >> 8);
            pred = row[c];
        }
    }
}

void undeltaPlanes(const uint8_t* planes, int w, int h, uint16_t* px) {
    const size_t n = size_t(w) * size_t(h);
    const uint8_t* lo = planes;
    const uint8_t* hi = planes + n;
    for (int r = 0; r < h; ++r) {
        uint16_t* row = px + size_t(r) * size_t(w);
        uint16_t pred = r > 0 ? row[-w] : 0;
        const size_t base = size_t(r) * size_t(w);
        for (int c = 0; c < w; ++c) {
            const uint16_t z = static_cast<uint16_t>(lo[base + c] | hi[base + c] << 8);
            const uint16_t d = static_cast<uint16_t>((z >> 1) ^ static_cast<uint16_t>(-(z & 1)));
            pred = static_cast<uint16_t>(pred + d);
            row[c] = pred;
        }
    }
}

Status checkDims(int w, int h, const char* what) {
    if (w < 1 || h < 1 || w > kMaxDepthWidthPx || h > kMaxDepthHeightPx) {
        return outOfRange(std::string(what) + " " + sizeText(w, h) + " outside 1x1.." +
                          sizeText(kMaxDepthWidthPx, kMaxDepthHeightPx));
    }
    return Status::ok();
}

}  // namespace

const char* depthCodecName(DepthCodecId codec) {
    const auto i = static_cast<size_t>(codec);
    return i < std::size(kNames) ? kNames[i] : "unknown";
}

std::optional<DepthCodecId> depthCodecFromName(std::string_view name) {
    for (int i = 0; i < kDepthCodecCount; ++i) {
        if (name == kNames[i]) return static_cast<DepthCodecId>(i);
    }
    return std::nullopt;
}

StatusOr<DepthCodecId> depthCodecFromTag(uint32_t tag) {
    if (tag >= static_cast<uint32_t>(kDepthCodecCount)) {
        return invalidArgument("unknown depth codec tag " + std::to_string(tag));
    }
    return static_cast<DepthCodecId>(tag);
}

Status DepthCodecParams::validate() const {
    if (static_cast<int>(codec) >= kDepthCodecCount) return invalidArgument("DepthCodecParams: unknown codec");
    if (zstd_level < -7 || zstd_level > 19) return invalidArgument("DepthCodecParams: zstd_level outside [-7, 19]");
    if (zstd_fast_step < 0 || zstd_fast_step > 1024) {
        return invalidArgument("DepthCodecParams: zstd_fast_step outside [0, 1024]");
    }
    if (png_compression < 0 || png_compression > 9) {
        return invalidArgument("DepthCodecParams: png_compression outside [0, 9]");
    }
    return Status::ok();
}

StatusOr<DepthPayloadHeader> parseDepthHeader(const uint8_t* data, size_t size) {
    if (data == nullptr || size < kDepthHeaderBytes) {
        return dataLoss("depth payload truncated (" + std::to_string(size) + " bytes, header needs " +
                        std::to_string(kDepthHeaderBytes) + ")");
    }
    if (std::memcmp(data, kMagic, 3) != 0) return dataLoss("depth payload has no FSD magic");
    if (data[3] != kVersion) return dataLoss("depth payload version " + std::to_string(data[3]) + " unsupported");
    if (data[4] >= kDepthCodecCount) return dataLoss("depth payload codec " + std::to_string(data[4]) + " unknown");
    if (data[5] != 0 || getU16(data + 10) != 0) return dataLoss("depth payload has unknown flags set");
    DepthPayloadHeader header;
    header.codec = static_cast<DepthCodecId>(data[4]);
    header.width_px = static_cast<int>(getU16(data + 6));
    header.height_px = static_cast<int>(getU16(data + 8));
    header.body_bytes = getU32(data + 12);
    RETURN_IF_ERROR(checkDims(header.width_px, header.height_px, "depth payload claims"));
    if (header.body_bytes != size - kDepthHeaderBytes) {
        return dataLoss("depth payload truncated or padded (" + std::to_string(size - kDepthHeaderBytes) +
                        " body bytes, header says " + std::to_string(header.body_bytes) + ")");
    }
    return header;
}

// ---------------------------------------------------------------------------------------------- encoder
struct DepthEncoder::State {
    ZSTD_CCtx* cctx = ZSTD_createCCtx();
    std::vector<uint16_t> pixels;  // contiguous copy when the input Mat has a stride
    std::vector<uint8_t> scratch;  // pre-pass output (RVL words or delta planes)
    std::vector<uint8_t> png;
    std::vector<uint16_t> rank_of = std::vector<uint16_t>(65536);  // kPackedDeltaZstd's value -> rank table
    ~State() { ZSTD_freeCCtx(cctx); }
};

DepthEncoder::DepthEncoder(DepthCodecParams params) : params_(params), state_(std::make_unique<State>()) {}
DepthEncoder::~DepthEncoder() = default;
DepthEncoder::DepthEncoder(DepthEncoder&&) noexcept = default;
DepthEncoder& DepthEncoder::operator=(DepthEncoder&&) noexcept = default;

Status DepthEncoder::encode(const cv::Mat& depth_u16, std::vector<uint8_t>& out) {
    RETURN_IF_ERROR(params_.validate());
    if (depth_u16.type() != CV_16UC1) return invalidArgument("depth encoder needs a CV_16UC1 image");
    const int w = depth_u16.cols;
    const int h = depth_u16.rows;
    RETURN_IF_ERROR(checkDims(w, h, "depth image"));
    if (state_->cctx == nullptr) return resourceExhausted("depth encoder: ZSTD_createCCtx failed");
    const size_t n = size_t(w) * size_t(h);
    const uint16_t* px = depth_u16.ptr<uint16_t>();
    if (!depth_u16.isContinuous()) {
        state_->pixels.resize(n);
        for (int r = 0; r < h; ++r) std::memcpy(&state_->pixels[size_t(r) * w], depth_u16.ptr<uint16_t>(r), 2 * w);
        px = state_->pixels.data();
    }

    // fast_literals: kPackedDeltaZstd's tuning (DepthCodecParams::zstd_fast_step). The parameters are set per
    // call because one context serves every codec.
    auto zstdInto = [&](const void* src, size_t src_bytes, bool fast_literals = false) -> Status {
        ZSTD_CCtx* cctx = state_->cctx;
        ZSTD_CCtx_reset(cctx, ZSTD_reset_session_and_parameters);
        size_t r = ZSTD_CCtx_setParameter(cctx, ZSTD_c_compressionLevel, params_.zstd_level);
        if (ZSTD_isError(r)) return internalError(std::string("zstd level rejected: ") + ZSTD_getErrorName(r));
        if (fast_literals && params_.zstd_level <= 1 && params_.zstd_fast_step > 0) {
            // A step > 0 makes zstd store literals raw unless Huffman is forced; forcing it is an experimental
            // parameter, so a libzstd that refuses it still yields a valid (larger) frame: its error is ignored.
            (void)ZSTD_CCtx_setParameter(cctx, ZSTD_c_strategy, ZSTD_fast);
            (void)ZSTD_CCtx_setParameter(cctx, ZSTD_c_targetLength, params_.zstd_fast_step);
            (void)ZSTD_CCtx_setParameter(cctx, ZSTD_c_literalCompressionMode, ZSTD_ps_enable);
        }
        out.resize(kDepthHeaderBytes + ZSTD_compressBound(src_bytes));
        r = ZSTD_compress2(cctx, out.data() + kDepthHeaderBytes, out.size() - kDepthHeaderBytes, src, src_bytes);
        if (ZSTD_isError(r)) return internalError(std::string("zstd compression failed: ") + ZSTD_getErrorName(r));
        out.resize(kDepthHeaderBytes + r);
        return Status::ok();
    };

    switch (params_.codec) {
        case DepthCodecId::kRaw16:
            out.resize(kDepthHeaderBytes + 2 * n);
            std::memcpy(out.data() + kDepthHeaderBytes, px, 2 * n);
            break;
        case DepthCodecId::kRvl: {
            out.resize(kDepthHeaderBytes + rvl::maxEncodedBytes(n));
            const size_t bytes = rvl::encode(px, n, out.data() + kDepthHeaderBytes);
            out.resize(kDepthHeaderBytes + bytes);
            break;
        }
        case DepthCodecId::kZstd: RETURN_IF_ERROR(zstdInto(px, 2 * n)); break;
        case DepthCodecId::kRvlZstd: {
            state_->scratch.resize(rvl::maxEncodedBytes(n));
            const size_t bytes = rvl::encode(px, n, state_->scratch.data());
            RETURN_IF_ERROR(zstdInto(state_->scratch.data(), bytes));
            break;
        }
        case DepthCodecId::kDeltaZstd:
            state_->scratch.resize(2 * n);
            deltaPlanes(px, w, h, state_->scratch.data());
            RETURN_IF_ERROR(zstdInto(state_->scratch.data(), 2 * n));
            break;
        case DepthCodecId::kPackedDeltaZstd: {
            state_->scratch.resize(packed::maxTokenBytes(n));
            const size_t bytes = packed::encode(px, w, h, state_->rank_of.data(), state_->scratch.data());
            RETURN_IF_ERROR(zstdInto(state_->scratch.data(), bytes, true));
            break;
        }
        case DepthCodecId::kPng: {
            const cv::Mat contiguous(h, w, CV_16UC1, const_cast<uint16_t*>(px));
            try {
                if (!cv::imencode(".png", contiguous, state_->png,
                                  {cv::IMWRITE_PNG_COMPRESSION, params_.png_compression})) {
                    return internalError("PNG encoding failed");
                }
            } catch (const cv::Exception& e) {
                return internalError(std::string("PNG encoding failed: ") + e.what());
            }
            out.resize(kDepthHeaderBytes + state_->png.size());
            std::memcpy(out.data() + kDepthHeaderBytes, state_->png.data(), state_->png.size());
            break;
        }
    }
    if (out.size() - kDepthHeaderBytes > 0xffffffffu) return outOfRange("depth payload over 4 GiB");
    writeHeader(out.data(), params_.codec, w, h, out.size() - kDepthHeaderBytes);
    return Status::ok();
}

// ---------------------------------------------------------------------------------------------- decoder
struct DepthDecoder::State {
    ZSTD_DCtx* dctx = ZSTD_createDCtx();
    std::vector<uint8_t> scratch;
    std::vector<uint16_t> value_of = std::vector<uint16_t>(65536);  // kPackedDeltaZstd's rank -> value table
    ~State() { ZSTD_freeDCtx(dctx); }

    // Decompresses exactly `want` bytes (or, when !exact, at most `want`) into dst; returns the size.
    StatusOr<size_t> unzstd(const uint8_t* src, size_t src_bytes, uint8_t* dst, size_t want, bool exact) {
        if (dctx == nullptr) return resourceExhausted("depth decoder: ZSTD_createDCtx failed");
        const size_t r = ZSTD_decompressDCtx(dctx, dst, want, src, src_bytes);
        if (ZSTD_isError(r)) return dataLoss(std::string("zstd body corrupt: ") + ZSTD_getErrorName(r));
        if (exact && r != want) {
            return dataLoss("zstd body decodes to " + std::to_string(r) + " bytes, expected " + std::to_string(want));
        }
        return r;
    }
};

DepthDecoder::DepthDecoder() : state_(std::make_unique<State>()) {}
DepthDecoder::~DepthDecoder() = default;
DepthDecoder::DepthDecoder(DepthDecoder&&) noexcept = default;
DepthDecoder& DepthDecoder::operator=(DepthDecoder&&) noexcept = default;

namespace {

// A PNG of exactly w x h, 16-bit greyscale, checked in the IHDR before OpenCV sees (and allocates for) it.
Status checkPngHeader(const uint8_t* body, size_t size, int w, int h) {
    static constexpr uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (size < 33) return dataLoss("PNG depth body truncated (" + std::to_string(size) + " bytes)");
    if (std::memcmp(body, kSignature, 8) != 0 || std::memcmp(body + 12, "IHDR", 4) != 0 ||
        getU32BigEndian(body + 8) != 13) {
        return dataLoss("PNG depth body has no PNG signature / IHDR");
    }
    const uint32_t png_w = getU32BigEndian(body + 16);
    const uint32_t png_h = getU32BigEndian(body + 20);
    if (png_w != uint32_t(w) || png_h != uint32_t(h)) {
        return dataLoss("PNG depth body is " + std::to_string(png_w) + "x" + std::to_string(png_h) + ", header says " +
                        sizeText(w, h));
    }
    if (body[24] != 16 || body[25] != 0) return dataLoss("PNG depth body is not 16-bit greyscale");
    return Status::ok();
}

}  // namespace

Status DepthDecoder::decode(DepthCodecId codec, const uint8_t* data, size_t size, int expected_width,
                            int expected_height, cv::Mat& depth_u16) {
    RETURN_IF_ERROR(checkDims(expected_width, expected_height, "expected depth size"));
    if (static_cast<int>(codec) >= kDepthCodecCount) return invalidArgument("unknown depth codec");
    ASSIGN_OR_RETURN(const DepthPayloadHeader header, parseDepthHeader(data, size));
    if (header.codec != codec) {
        return dataLoss(std::string("depth codec tag says ") + depthCodecName(codec) + ", payload says " +
                        depthCodecName(header.codec));
    }
    if (header.width_px != expected_width || header.height_px != expected_height) {
        return dataLoss("depth payload is " + sizeText(header.width_px, header.height_px) + ", camera says " +
                        sizeText(expected_width, expected_height));
    }
    const int w = header.width_px;
    const int h = header.height_px;
    const size_t n = size_t(w) * size_t(h);
    const uint8_t* body = data + kDepthHeaderBytes;
    const size_t body_bytes = header.body_bytes;

    if (depth_u16.rows != h || depth_u16.cols != w || depth_u16.type() != CV_16UC1 || !depth_u16.isContinuous()) {
        depth_u16 = cv::Mat(h, w, CV_16UC1);
    }
    auto* px = depth_u16.ptr<uint16_t>();
    auto* px_bytes = reinterpret_cast<uint8_t*>(px);

    switch (codec) {
        case DepthCodecId::kRaw16:
            if (body_bytes != 2 * n) {
                return dataLoss("raw depth body is " + std::to_string(body_bytes) + " bytes, expected " +
                                std::to_string(2 * n));
            }
            std::memcpy(px, body, 2 * n);
            return Status::ok();
        case DepthCodecId::kRvl: return rvl::decode(body, body_bytes, px, n);
        case DepthCodecId::kZstd: return state_->unzstd(body, body_bytes, px_bytes, 2 * n, true).status();
        case DepthCodecId::kRvlZstd: {
            state_->scratch.resize(rvl::maxEncodedBytes(n));
            ASSIGN_OR_RETURN(const size_t rvl_bytes,
                             state_->unzstd(body, body_bytes, state_->scratch.data(), state_->scratch.size(), false));
            return rvl::decode(state_->scratch.data(), rvl_bytes, px, n);
        }
        case DepthCodecId::kDeltaZstd: {
            state_->scratch.resize(2 * n);
            RETURN_IF_ERROR(state_->unzstd(body, body_bytes, state_->scratch.data(), 2 * n, true).status());
            undeltaPlanes(state_->scratch.data(), w, h, px);
            return Status::ok();
        }
        case DepthCodecId::kPackedDeltaZstd: {
            state_->scratch.resize(packed::maxTokenBytes(n));
            ASSIGN_OR_RETURN(const size_t token_bytes,
                             state_->unzstd(body, body_bytes, state_->scratch.data(), state_->scratch.size(), false));
            return packed::decode(state_->scratch.data(), token_bytes, w, h, state_->value_of.data(), px);
        }
        case DepthCodecId::kPng: {
            RETURN_IF_ERROR(checkPngHeader(body, body_bytes, w, h));
            cv::Mat decoded;
            try {
                decoded = cv::imdecode(cv::Mat(1, static_cast<int>(body_bytes), CV_8UC1, const_cast<uint8_t*>(body)),
                                       cv::IMREAD_UNCHANGED);
            } catch (const cv::Exception& e) {
                return dataLoss(std::string("PNG depth body corrupt: ") + e.what());
            }
            if (decoded.empty() || decoded.type() != CV_16UC1 || decoded.cols != w || decoded.rows != h) {
                return dataLoss("PNG depth body corrupt or truncated");
            }
            decoded.copyTo(depth_u16);
            return Status::ok();
        }
    }
    return invalidArgument("unknown depth codec");
}

Status encodeDepth(const cv::Mat& depth_u16, const DepthCodecParams& params, std::vector<uint8_t>& out) {
    return DepthEncoder(params).encode(depth_u16, out);
}

Status decodeDepth(DepthCodecId codec, const uint8_t* data, size_t size, int expected_width, int expected_height,
                   cv::Mat& depth_u16) {
    return DepthDecoder().decode(codec, data, size, expected_width, expected_height, depth_u16);
}

}  // namespace facescan::wire
