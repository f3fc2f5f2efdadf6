// JPEG colour through the TurboJPEG API of libjpeg-turbo 2.1 (Debian 12).
#include "wire/colour_codec.hpp"

#include <turbojpeg.h>

#include <string>
#include <utility>

#if __has_include("facescan.h")
#include "facescan.h"
static_assert(static_cast<int>(facescan::wire::ColourCodecId::kNone) == facescan_wire_COLOUR_NONE);
static_assert(static_cast<int>(facescan::wire::ColourCodecId::kJpeg) == facescan_wire_COLOUR_JPEG);
static_assert(static_cast<int>(facescan::wire::ColourCodecId::kRawBgr) == facescan_wire_COLOUR_RAW_BGR);
#endif

namespace facescan::wire {
namespace {

std::string sizeText(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

Status checkDims(int w, int h, const char* what) {
    if (w < 1 || h < 1 || w > kMaxColourWidthPx || h > kMaxColourHeightPx) {
        return outOfRange(std::string(what) + " " + sizeText(w, h) + " outside 1x1.." +
                          sizeText(kMaxColourWidthPx, kMaxColourHeightPx));
    }
    return Status::ok();
}

std::string tjError(void* handle) { return tjGetErrorStr2(static_cast<tjhandle>(handle)); }

}  // namespace

Status ColourJpegParams::validate() const {
    if (quality < 1 || quality > 100) return invalidArgument("ColourJpegParams: quality outside [1, 100]");
    return Status::ok();
}

ColourJpegEncoder::ColourJpegEncoder(ColourJpegParams params) : params_(params), handle_(tjInitCompress()) {}
ColourJpegEncoder::~ColourJpegEncoder() {
    if (handle_) tjDestroy(static_cast<tjhandle>(handle_));
}
ColourJpegEncoder::ColourJpegEncoder(ColourJpegEncoder&& other) noexcept
    : params_(other.params_), handle_(std::exchange(other.handle_, nullptr)) {}
ColourJpegEncoder& ColourJpegEncoder::operator=(ColourJpegEncoder&& other) noexcept {
    std::swap(params_, other.params_);
    std::swap(handle_, other.handle_);
    return *this;
}

Status ColourJpegEncoder::encode(const cv::Mat& bgr, std::vector<uint8_t>& out) {
    RETURN_IF_ERROR(params_.validate());
    if (bgr.type() != CV_8UC3) return invalidArgument("JPEG encoder needs a CV_8UC3 BGR image");
    RETURN_IF_ERROR(checkDims(bgr.cols, bgr.rows, "colour image"));
    if (handle_ == nullptr) return resourceExhausted("tjInitCompress failed");
    const int subsamp = params_.subsample_420 ? TJSAMP_420 : TJSAMP_444;
    // Worst case size up front + NOREALLOC: TurboJPEG writes into our vector and never reallocates it.
    out.resize(tjBufSize(bgr.cols, bgr.rows, subsamp));
    unsigned char* dst = out.data();
    unsigned long jpeg_bytes = out.size();
    const int flags = TJFLAG_NOREALLOC | (params_.fast_dct ? TJFLAG_FASTDCT : 0);
    if (tjCompress2(static_cast<tjhandle>(handle_), bgr.data, bgr.cols, static_cast<int>(bgr.step[0]), bgr.rows,
                    TJPF_BGR, &dst, &jpeg_bytes, subsamp, params_.quality, flags) != 0) {
        return internalError("JPEG encoding failed: " + tjError(handle_));
    }
    out.resize(jpeg_bytes);
    return Status::ok();
}

ColourJpegDecoder::ColourJpegDecoder() : handle_(tjInitDecompress()) {}
ColourJpegDecoder::~ColourJpegDecoder() {
    if (handle_) tjDestroy(static_cast<tjhandle>(handle_));
}
ColourJpegDecoder::ColourJpegDecoder(ColourJpegDecoder&& other) noexcept
    : handle_(std::exchange(other.handle_, nullptr)) {}
ColourJpegDecoder& ColourJpegDecoder::operator=(ColourJpegDecoder&& other) noexcept {
    std::swap(handle_, other.handle_);
    return *this;
}

Status ColourJpegDecoder::decode(const uint8_t* data, size_t size, int expected_width, int expected_height,
                                 cv::Mat& bgr) {
    RETURN_IF_ERROR(checkDims(expected_width, expected_height, "expected colour size"));
    if (handle_ == nullptr) return resourceExhausted("tjInitDecompress failed");
    if (data == nullptr || size < 4) return dataLoss("JPEG payload truncated (" + std::to_string(size) + " bytes)");
    auto* handle = static_cast<tjhandle>(handle_);
    int w = 0;
    int h = 0;
    int subsamp = 0;
    int colourspace = 0;
    // libjpeg-turbo 2.1 leaves a handle unusable after some header errors (a later valid JPEG then fails with the
    // same "Bogus DQT index"): after any failure the handle is replaced, so one bad frame cannot poison the next.
    auto fail = [this](const std::string& what) {
        const std::string message = what + tjError(handle_);
        tjDestroy(static_cast<tjhandle>(handle_));
        handle_ = tjInitDecompress();
        return dataLoss(message);
    };
    if (tjDecompressHeader3(handle, data, size, &w, &h, &subsamp, &colourspace) != 0) {
        return fail("JPEG header corrupt: ");
    }
    if (w != expected_width || h != expected_height) {
        return dataLoss("JPEG is " + sizeText(w, h) + ", camera says " + sizeText(expected_width, expected_height));
    }
    if (bgr.rows != h || bgr.cols != w || bgr.type() != CV_8UC3) bgr = cv::Mat(h, w, CV_8UC3);
    // STOPONWARNING: libjpeg treats truncated / corrupt entropy data as a warning and pads with grey; for network
    // bytes that is data loss. LIMITSCANS: caps progressive scans (a tiny file can otherwise take seconds).
    const int flags = TJFLAG_STOPONWARNING | TJFLAG_LIMITSCANS | TJFLAG_FASTDCT;
    if (tjDecompress2(handle, data, size, bgr.data, w, static_cast<int>(bgr.step[0]), h, TJPF_BGR, flags) != 0) {
        return fail("JPEG data corrupt or truncated: ");
    }
    return Status::ok();
}

Status encodeColourJpeg(const cv::Mat& bgr, int quality, std::vector<uint8_t>& out) {
    ColourJpegParams params;
    params.quality = quality;
    return ColourJpegEncoder(params).encode(bgr, out);
}

Status decodeColourJpeg(const uint8_t* data, size_t size, int expected_width, int expected_height, cv::Mat& bgr) {
    return ColourJpegDecoder().decode(data, size, expected_width, expected_height, bgr);
}

}  // namespace facescan::wire
