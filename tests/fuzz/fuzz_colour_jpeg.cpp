// libFuzzer target: ColourJpegDecoder. The expected size comes from the JPEG's own header (when it is small, to
// keep executions fast) so the fuzzer reaches the entropy decoder; a second call with a wrong size must fail.
#include <turbojpeg.h>

#include "wire/colour_codec.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan::wire;
    static ColourJpegDecoder decoder;
    static tjhandle peek = tjInitDecompress();
    static cv::Mat bgr;
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
    if (decoder.decode(data, size, w + 1, h, bgr).isOk()) __builtin_trap();
    return 0;
}
