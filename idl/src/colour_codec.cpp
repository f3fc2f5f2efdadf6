// JPEG colour through libjpeg-turbo 2.1 (Debian 12): encoded with its TurboJPEG API, decoded with its libjpeg API.
#include "wire/colour_codec.hpp"

// jpeglib.h needs size_t and FILE declared first.
#include <jpeglib.h>
#include <turbojpeg.h>

#include <algorithm>
#include <csetjmp>
#include <cstdio>
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

// libjpeg reports errors through error_exit, which must not return: the callbacks longjmp back into run() below,
// whose frame between setjmp and the jump holds no C++ object with a destructor.
struct ColourJpegDecoder::Impl {
    jpeg_decompress_struct cinfo{};
    jpeg_error_mgr errors{};
    jpeg_progress_mgr progress{};
    std::jmp_buf jump{};
    char message[JMSG_LENGTH_MAX] = {};
    bool live = false;

    static Impl& of(j_common_ptr c) { return *static_cast<Impl*>(c->client_data); }
    static void onError(j_common_ptr c) {
        (*c->err->format_message)(c, of(c).message);
        std::longjmp(of(c).jump, 1);
    }
    // Warnings (level -1) are corrupt or truncated data: for network bytes that is data loss (TurboJPEG's
    // TJFLAG_STOPONWARNING), not an image padded with grey. Trace messages (level >= 0) are ignored.
    static void onMessage(j_common_ptr c, int level) {
        if (level < 0) onError(c);
    }
    static void onProgress(j_common_ptr c) {
        if (auto* d = reinterpret_cast<j_decompress_ptr>(c); d->input_scan_number > kMaxScans) {
            std::snprintf(of(c).message, sizeof of(c).message, "progressive JPEG with more than %d scans", kMaxScans);
            std::longjmp(of(c).jump, 1);
        }
    }
    static constexpr int kMaxScans = 500;  // as TurboJPEG's TJFLAG_LIMITSCANS: a tiny file cannot spin for seconds

    Impl() { create(); }
    ~Impl() { destroy(); }
    Impl(const Impl&) = delete;
    Impl& operator=(const Impl&) = delete;
    void create() {
        cinfo.err = jpeg_std_error(&errors);
        errors.error_exit = onError;
        errors.emit_message = onMessage;
        cinfo.client_data = this;
        if (setjmp(jump)) return;  // out of memory: live stays false
        jpeg_create_decompress(&cinfo);
        cinfo.client_data = this;  // jpeg_create_decompress clears the struct but for err and client_data
        progress.progress_monitor = onProgress;
        cinfo.progress = &progress;
        live = true;
    }
    void destroy() {
        if (live) jpeg_destroy_decompress(&cinfo);
        live = false;
    }
};

namespace {

enum class Stage { kHeader, kWrongSize, kPixels };

// Rows [y0, y1) and columns [x0, x1) into dst (row stride `step`); header_only stops after the header.
// Returns true, or false with the stage that failed (the message in d.message). Plain data only in this frame.
bool runLibjpeg(ColourJpegDecoder::Impl& d, const uint8_t* data, size_t size, int expected_width, int expected_height,
                bool header_only, int x0, int x1, int y0, int y1, uint8_t* dst, size_t step, Stage& failed, int& width,
                int& height) {
    j_decompress_ptr c = &d.cinfo;
    failed = Stage::kHeader;
    if (setjmp(d.jump)) {
        jpeg_abort_decompress(c);
        return false;
    }
    jpeg_mem_src(c, data, static_cast<unsigned long>(size));
    (void)jpeg_read_header(c, TRUE);  // TRUE: a tables-only file is an error, so the header is the image's
    width = static_cast<int>(c->image_width);
    height = static_cast<int>(c->image_height);
    if (width != expected_width || height != expected_height) {
        jpeg_abort_decompress(c);
        failed = Stage::kWrongSize;
        return false;
    }
    if (header_only) {
        jpeg_abort_decompress(c);
        return true;
    }
    failed = Stage::kPixels;
    c->out_color_space = JCS_EXT_BGR;
    c->dct_method = JDCT_IFAST;  // as the encoder's TJFLAG_FASTDCT: invisible at quality 90, and faster
    jpeg_start_decompress(c);
    auto left = static_cast<JDIMENSION>(x0);
    auto cols = static_cast<JDIMENSION>(x1 - x0);
    if (cols < c->output_width) jpeg_crop_scanline(c, &left, &cols);  // widened to whole blocks
    if (y0 > 0) (void)jpeg_skip_scanlines(c, static_cast<JDIMENSION>(y0));
    constexpr int kBatch = 16;  // up to two MCU rows a call
    JSAMPROW rows[kBatch];
    while (static_cast<int>(c->output_scanline) < y1) {
        const int first = static_cast<int>(c->output_scanline);
        const int n = std::min(kBatch, y1 - first);
        for (int i = 0; i < n; ++i)
            rows[i] = dst + static_cast<size_t>(first + i) * step + 3 * static_cast<size_t>(left);
        if (jpeg_read_scanlines(c, rows, static_cast<JDIMENSION>(n)) == 0) {
            std::snprintf(d.message, sizeof d.message, "the decoder made no progress at row %d", first);
            jpeg_abort_decompress(c);
            return false;
        }
    }
    // The whole image is checked to its end (as TurboJPEG does); a region stops after its last row.
    if (y1 == height) {
        (void)jpeg_finish_decompress(c);
    } else {
        jpeg_abort_decompress(c);
    }
    return true;
}

}  // namespace

ColourJpegDecoder::ColourJpegDecoder() : impl_(std::make_unique<Impl>()) {}
ColourJpegDecoder::~ColourJpegDecoder() = default;
ColourJpegDecoder::ColourJpegDecoder(ColourJpegDecoder&&) noexcept = default;
ColourJpegDecoder& ColourJpegDecoder::operator=(ColourJpegDecoder&&) noexcept = default;

Status ColourJpegDecoder::decode(const uint8_t* data, size_t size, int expected_width, int expected_height,
                                 cv::Mat& bgr) {
    return run(data, size, expected_width, expected_height, nullptr, &bgr);
}

Status ColourJpegDecoder::decodeRegion(const uint8_t* data, size_t size, int expected_width, int expected_height,
                                       const cv::Rect& roi_px, cv::Mat& bgr) {
    return run(data, size, expected_width, expected_height, &roi_px, &bgr);
}

Status ColourJpegDecoder::checkHeader(const uint8_t* data, size_t size, int expected_width, int expected_height) {
    return run(data, size, expected_width, expected_height, nullptr, nullptr);
}

Status ColourJpegDecoder::run(const uint8_t* data, size_t size, int expected_width, int expected_height,
                              const cv::Rect* roi_px, cv::Mat* bgr) {
    RETURN_IF_ERROR(checkDims(expected_width, expected_height, "expected colour size"));
    if (!impl_) impl_ = std::make_unique<Impl>();  // moved from
    if (!impl_->live) impl_->create();
    if (!impl_->live) return resourceExhausted("libjpeg: cannot create a decompressor");
    if (data == nullptr || size < 4) return dataLoss("JPEG payload truncated (" + std::to_string(size) + " bytes)");
    const cv::Rect whole(0, 0, expected_width, expected_height);
    cv::Rect region = roi_px ? (*roi_px & whole) : whole;
    // Columns are cropped to whole blocks, and the chroma upsampling at a crop's edge has no neighbour to blend
    // with: one 16-pixel block more each side keeps the region's own pixels the whole image's (measured: without
    // it, the edge columns of a 4:2:0 frame differed by up to 8 levels).
    constexpr int kColumnMarginPx = 16;
    if (!region.empty() && region != whole) {
        const int x0 = std::max(0, region.x - kColumnMarginPx);
        const int x1 = std::min(expected_width, region.x + region.width + kColumnMarginPx);
        region = cv::Rect(x0, region.y, x1 - x0, region.height);
    }
    uint8_t* dst = nullptr;
    size_t step = 0;
    if (bgr) {
        if (bgr->rows != expected_height || bgr->cols != expected_width || bgr->type() != CV_8UC3) {
            // The header first: a lying size is refused before anything is allocated.
            RETURN_IF_ERROR(checkHeader(data, size, expected_width, expected_height));
            bgr->create(expected_height, expected_width, CV_8UC3);
        }
        if (region.empty()) return Status::ok();
        dst = bgr->data;
        step = bgr->step[0];
    }
    Stage failed = Stage::kHeader;
    int w = 0;
    int h = 0;
    if (runLibjpeg(*impl_, data, size, expected_width, expected_height, bgr == nullptr, region.x,
                   region.x + region.width, region.y, region.y + region.height, dst, step, failed, w, h)) {
        return Status::ok();
    }
    if (failed == Stage::kWrongSize) {
        return dataLoss("JPEG is " + sizeText(w, h) + ", camera says " + sizeText(expected_width, expected_height));
    }
    const std::string message =
        (failed == Stage::kHeader ? "JPEG header corrupt: " : "JPEG data corrupt or truncated: ") +
        std::string(impl_->message);
    // libjpeg keeps tables from one image to the next (abbreviated streams): after a failure start afresh, so a
    // hostile frame cannot leave tables that the next one uses.
    impl_->destroy();
    impl_->create();
    return dataLoss(message);
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
