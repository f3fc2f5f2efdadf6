// Colour codec for RgbdFrame.colour: baseline JPEG through libjpeg-turbo, encoded with its TurboJPEG API (measured
// faster than OpenCV's imencode on the same frames, see `facescan-bench codecs`), decoded with its libjpeg API. Colour
// only drives detection and vertex colours, so it is lossy; the payload is a plain JPEG file (self-describing, checked
// before decoding).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "recon/status.hpp"

namespace facescan::wire {

// Same numbering as the IDL enum facescan::wire::ColourCodec (static_assert in colour_codec.cpp).
enum class ColourCodecId : uint8_t { kNone = 0, kJpeg = 1, kRawBgr = 2 };

inline constexpr int kMaxColourWidthPx = 4096;  // absolute caps whatever the caller expects
inline constexpr int kMaxColourHeightPx = 4096;

struct ColourJpegParams {
    int quality = 90;           // JPEG quality [1, 100]: 90 keeps skin texture for vertex colours at ~1:15
    bool subsample_420 = true;  // 4:2:0 chroma (half the chroma samples; faces have little chroma detail)
    bool fast_dct = true;       // libjpeg-turbo's fast integer DCT: a few % faster, invisible at quality >= 90
    Status validate() const;
};

// Keeps its TurboJPEG handle; out's capacity is reused and never grown by TurboJPEG (worst-case sized buffer),
// so after the first frame of a size encode() does not allocate. Thread-compatible: one per thread.
class ColourJpegEncoder {
 public:
    explicit ColourJpegEncoder(ColourJpegParams params = {});
    ~ColourJpegEncoder();
    ColourJpegEncoder(ColourJpegEncoder&&) noexcept;
    ColourJpegEncoder& operator=(ColourJpegEncoder&&) noexcept;
    ColourJpegEncoder(const ColourJpegEncoder&) = delete;
    ColourJpegEncoder& operator=(const ColourJpegEncoder&) = delete;

    const ColourJpegParams& params() const { return params_; }
    // bgr: CV_8UC3, 1..4096 pixels each side, any stride. out is overwritten with a JPEG file.
    Status encode(const cv::Mat& bgr, std::vector<uint8_t>& out);

 private:
    ColourJpegParams params_;
    void* handle_ = nullptr;  // tjhandle
};

// Decodes through libjpeg-turbo's libjpeg API, which can decode a region (TurboJPEG 2.1, Debian 12's, cannot:
// tj3SetCroppingRegion is 3.0's). Checks the JPEG header (dimensions against expected and the caps) before it
// allocates; progressive scans are limited (500, as TurboJPEG's TJFLAG_LIMITSCANS) so a hostile file cannot make
// it spin; any libjpeg warning (truncated or corrupt data) is a DATA_LOSS error, never a grey-filled image.
// Output as TurboJPEG's TJFLAG_FASTDCT with BGR pixels gives. After a failure the libjpeg state is replaced, so
// one bad frame cannot poison the next. Thread-compatible: one per thread.
class ColourJpegDecoder {
 public:
    ColourJpegDecoder();
    ~ColourJpegDecoder();
    ColourJpegDecoder(ColourJpegDecoder&&) noexcept;
    ColourJpegDecoder& operator=(ColourJpegDecoder&&) noexcept;
    ColourJpegDecoder(const ColourJpegDecoder&) = delete;
    ColourJpegDecoder& operator=(const ColourJpegDecoder&) = delete;

    // bgr becomes CV_8UC3 expected_height x expected_width (its buffer is reused when it has that shape).
    Status decode(const uint8_t* data, size_t size, int expected_width, int expected_height, cv::Mat& bgr);
    // Only the pixels of roi_px (clipped to the image) are decoded, and the same as decode() gives them: rows
    // above and below it are skipped (their entropy data is still read, so a cut or corrupt payload before the
    // region's end still fails), and columns outside it are not transformed. bgr is shaped as for decode(); its
    // pixels outside the region keep what they held (libjpeg may write a few columns either side).
    Status decodeRegion(const uint8_t* data, size_t size, int expected_width, int expected_height,
                        const cv::Rect& roi_px, cv::Mat& bgr);
    // The header alone: a JPEG of the expected size (no pixel is decoded, nothing is allocated).
    Status checkHeader(const uint8_t* data, size_t size, int expected_width, int expected_height);

    struct Impl;  // libjpeg's state (public for the C callbacks in colour_codec.cpp)

 private:
    Status run(const uint8_t* data, size_t size, int expected_width, int expected_height, const cv::Rect* roi_px,
               cv::Mat* bgr);
    std::unique_ptr<Impl> impl_;
};

// One-shot helpers (a codec per call: for tests and tools, not a 30 Hz loop).
Status encodeColourJpeg(const cv::Mat& bgr, int quality, std::vector<uint8_t>& out);
Status decodeColourJpeg(const uint8_t* data, size_t size, int expected_width, int expected_height, cv::Mat& bgr);

}  // namespace facescan::wire
