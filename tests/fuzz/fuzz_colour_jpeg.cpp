// libFuzzer target: ColourJpegDecoder. The expected size comes from the JPEG's own header (when it is small, to
// keep executions fast) so the fuzzer reaches the entropy decoder; a second call with a wrong size must fail. A
// region (placed by the input's length) is decoded too: it must succeed where the whole image did, with the whole
// image's pixels, and the header check must pass where either did.
#include <turbojpeg.h>

#include "wire/colour_codec.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan::wire;
    static ColourJpegDecoder decoder;
    static tjhandle peek = tjInitDecompress();
    static cv::Mat bgr;
    static cv::Mat part;
    int w = 64;
    int h = 48;
    int subsamp = 0;
    int colourspace = 0;
    int jw = 0;
    int jh = 0;
    if (size > 0 && tjDecompressHeader3(peek, data, size, &jw, &jh, &subsamp, &colourspace) == 0 && jw > 0 && jh > 0 &&
        jw <= 512 && jh <= 512) {
        w = jw;
        h = jh;
    }
    const facescan::Status st = decoder.decode(data, size, w, h, bgr);
    if (st.isOk() && (bgr.cols != w || bgr.rows != h || bgr.type() != CV_8UC3)) __builtin_trap();
    const cv::Rect roi(static_cast<int>(size * 7 % static_cast<size_t>(w)),
                       static_cast<int>(size * 13 % static_cast<size_t>(h)), 1 + static_cast<int>(size % 40),
                       1 + static_cast<int>(size % 30));
    const facescan::Status region = decoder.decodeRegion(data, size, w, h, roi, part);
    if (st.isOk()) {
        if (!region.isOk()) __builtin_trap();
        const cv::Rect in = roi & cv::Rect(0, 0, w, h);
        if (cv::norm(part(in), bgr(in), cv::NORM_INF) != 0.0) __builtin_trap();
    }
    if ((st.isOk() || region.isOk()) && !decoder.checkHeader(data, size, w, h).isOk()) __builtin_trap();
    if (decoder.decode(data, size, w + 1, h, bgr).isOk()) __builtin_trap();
    return 0;
}
