// JPEG colour codec: PSNR and size on pattern and real frames, a decoder that gives TurboJPEG's pixels, for the
// whole image or a region of it, and refuses truncated, corrupt, mismatched and oversized input with a Status.
#include <gtest/gtest.h>
#include <turbojpeg.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "test_data.hpp"
#include "wire/codecs.hpp"

namespace facescan::wire {
namespace {

// Smooth gradients, a soft skin-toned disc and some fine texture: what a face frame looks like to JPEG.
cv::Mat colourPattern(int w, int h) {
    cv::Mat bgr(h, w, CV_8UC3);
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            bgr.at<cv::Vec3b>(v, u) = cv::Vec3b(static_cast<uint8_t>(60 + 100 * u / std::max(1, w - 1)),
                                                static_cast<uint8_t>(80 + 90 * v / std::max(1, h - 1)),
                                                static_cast<uint8_t>(((u / 8 + v / 8) % 2) ? 150 : 130));
        }
    }
    cv::circle(bgr, {w / 2, h / 2}, std::min(w, h) / 3, cv::Scalar(120, 150, 210), cv::FILLED, cv::LINE_AA);
    cv::GaussianBlur(bgr, bgr, {3, 3}, 0.8);
    return bgr;
}

void expectJpegRoundTrip(const cv::Mat& bgr, int quality, double min_psnr_db, double max_bytes_per_pixel) {
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeColourJpeg(bgr, quality, bytes).isOk());
    EXPECT_LE(static_cast<double>(bytes.size()), max_bytes_per_pixel * static_cast<double>(bgr.total()));
    cv::Mat decoded;
    const Status st = decodeColourJpeg(bytes.data(), bytes.size(), bgr.cols, bgr.rows, decoded);
    ASSERT_TRUE(st.isOk()) << st.toString();
    ASSERT_EQ(decoded.type(), CV_8UC3);
    ASSERT_EQ(decoded.size(), bgr.size());
    EXPECT_GE(cv::PSNR(bgr, decoded), min_psnr_db);
}

TEST(ColourJpeg, RoundTripKeepsQualityAndCompresses) {
    // Quality 90 on a smooth 640x480 frame: > 35 dB and under 1 byte per pixel (raw BGR is 3).
    expectJpegRoundTrip(colourPattern(640, 480), 90, 35.0, 1.0);
    // Odd sizes (partial MCUs) and a single pixel still decode to the right shape.
    expectJpegRoundTrip(colourPattern(33, 17), 90, 28.0, 16.0);
    expectJpegRoundTrip(colourPattern(1, 1), 95, 20.0, 1000.0);
}

TEST(ColourJpeg, QualityTradesSizeForFidelity) {
    const cv::Mat bgr = colourPattern(320, 240);
    std::vector<uint8_t> low;
    std::vector<uint8_t> high;
    ASSERT_TRUE(encodeColourJpeg(bgr, 50, low).isOk());
    ASSERT_TRUE(encodeColourJpeg(bgr, 95, high).isOk());
    EXPECT_LT(low.size(), high.size());
    cv::Mat low_img;
    cv::Mat high_img;
    ASSERT_TRUE(decodeColourJpeg(low.data(), low.size(), 320, 240, low_img).isOk());
    ASSERT_TRUE(decodeColourJpeg(high.data(), high.size(), 320, 240, high_img).isOk());
    EXPECT_GT(cv::PSNR(bgr, high_img), cv::PSNR(bgr, low_img));
}

TEST(ColourJpeg, RealFramesRoundTrip) {
    FACESCAN_REQUIRE_DATA(data, ".");
    int tested = 0;
    for (const auto& file : {data / "biwi_subject01_5frames/rgb/frame_00000.png",
                             data / "7scenes_tsdf_fusion/rgbd-frames/frame-000150.color.png"}) {
        if (!std::filesystem::exists(file)) continue;
        const cv::Mat bgr = cv::imread(file.string(), cv::IMREAD_COLOR);
        ASSERT_FALSE(bgr.empty()) << file;
        // Real sensor frames carry noise: 32 dB at quality 90, and still well under raw size.
        expectJpegRoundTrip(bgr, 90, 32.0, 1.5);
        ++tested;
    }
    if (tested == 0) GTEST_SKIP() << "no real colour frames under " << data;
}

TEST(ColourJpeg, EncoderReusesOutputBuffer) {
    ColourJpegEncoder encoder;
    const cv::Mat bgr = colourPattern(160, 120);
    std::vector<uint8_t> out;
    ASSERT_TRUE(encoder.encode(bgr, out).isOk());
    ASSERT_TRUE(encoder.encode(bgr, out).isOk());
    const uint8_t* data = out.data();
    ASSERT_TRUE(encoder.encode(bgr, out).isOk());
    EXPECT_EQ(out.data(), data);
    // A view with a row stride encodes the view.
    ASSERT_TRUE(encoder.encode(bgr(cv::Rect(5, 5, 50, 40)), out).isOk());
    cv::Mat decoded;
    ASSERT_TRUE(decodeColourJpeg(out.data(), out.size(), 50, 40, decoded).isOk());
    EXPECT_GT(cv::PSNR(bgr(cv::Rect(5, 5, 50, 40)).clone(), decoded), 30.0);
}

// Every cut payload is refused whole; a region fails when the cut falls before its end, and needs none of the bytes
// after its last row.
TEST(ColourJpeg, RejectsEveryTruncationOfWhatItDecodes) {
    const cv::Mat bgr = colourPattern(64, 64);
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeColourJpeg(bgr, 90, bytes).isOk());
    ColourJpegDecoder decoder;
    cv::Mat out;
    const cv::Rect top(8, 0, 16, 16);
    const cv::Rect bottom(8, 48, 16, 16);
    int top_ok_when_cut = 0;
    for (size_t len = 0; len < bytes.size(); ++len) {
        const std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(len));
        EXPECT_FALSE(decoder.decode(prefix.data(), prefix.size(), 64, 64, out).isOk()) << "prefix " << len;
        EXPECT_FALSE(decoder.decodeRegion(prefix.data(), prefix.size(), 64, 64, bottom, out).isOk()) << len;
        top_ok_when_cut += decoder.decodeRegion(prefix.data(), prefix.size(), 64, 64, top, out).isOk() ? 1 : 0;
    }
    EXPECT_GT(top_ok_when_cut, 0) << "a region above the cut needs none of the bytes after it";
    EXPECT_TRUE(decoder.decode(bytes.data(), bytes.size(), 64, 64, out).isOk());
    EXPECT_TRUE(decoder.decodeRegion(bytes.data(), bytes.size(), 64, 64, bottom, out).isOk());
}

TEST(ColourJpeg, CorruptBytesNeverCrash) {
    const cv::Mat bgr = colourPattern(32, 24);
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeColourJpeg(bgr, 90, bytes).isOk());
    ColourJpegDecoder decoder;
    cv::Mat out;
    int failures = 0;
    for (size_t i = 0; i < bytes.size(); ++i) {
        std::vector<uint8_t> corrupt = bytes;
        corrupt[i] ^= 0xa5;
        const Status st = decoder.decode(corrupt.data(), corrupt.size(), 32, 24, out);
        if (!st.isOk()) ++failures;
        if (st.isOk()) {
            EXPECT_EQ(out.size(), cv::Size(32, 24));
        }
    }
    EXPECT_GT(failures, 0);  // the markers and tables are checked; entropy-coded damage may pass as noise
}

// The decoder moved from TurboJPEG to libjpeg's API (for regions): it must give TurboJPEG's pixels exactly, for
// the agent's 4:2:0, for 4:4:4, for greyscale files and for sizes that are not whole blocks.
TEST(ColourJpeg, DecodesTheSamePixelsAsTurboJpeg) {
    tjhandle tj = tjInitDecompress();
    ASSERT_NE(tj, nullptr);
    tjhandle tjc = tjInitCompress();
    ASSERT_NE(tjc, nullptr);
    ColourJpegDecoder decoder;
    for (const int samp : {TJSAMP_420, TJSAMP_444, TJSAMP_422, TJSAMP_GRAY}) {
        for (const cv::Size size : {cv::Size(640, 480), cv::Size(33, 17), cv::Size(1, 1)}) {
            const cv::Mat bgr = colourPattern(size.width, size.height);
            unsigned char* jpeg = nullptr;
            unsigned long bytes = 0;
            ASSERT_EQ(tjCompress2(tjc, bgr.data, bgr.cols, static_cast<int>(bgr.step[0]), bgr.rows, TJPF_BGR, &jpeg,
                                  &bytes, samp, 90, TJFLAG_FASTDCT),
                      0);
            cv::Mat theirs(size, CV_8UC3);
            ASSERT_EQ(tjDecompress2(tj, jpeg, bytes, theirs.data, size.width, static_cast<int>(theirs.step[0]),
                                    size.height, TJPF_BGR, TJFLAG_FASTDCT),
                      0);
            cv::Mat ours;
            const Status st = decoder.decode(jpeg, bytes, size.width, size.height, ours);
            tjFree(jpeg);
            ASSERT_TRUE(st.isOk()) << st.toString();
            EXPECT_EQ(cv::norm(ours, theirs, cv::NORM_INF), 0.0) << "subsampling " << samp << ", " << size;
        }
    }
    tjDestroy(tjc);
    tjDestroy(tj);
}

int pixelsNot(const cv::Mat& bgr, cv::Vec3b value) {
    int n = 0;
    for (int v = 0; v < bgr.rows; ++v) {
        for (int u = 0; u < bgr.cols; ++u) n += bgr.at<cv::Vec3b>(v, u) != value ? 1 : 0;
    }
    return n;
}

// A region's pixels are the whole image's, wherever the region lies (block edges or not, at the image's edges,
// one pixel, all of it, partly outside); rows outside it are never written.
TEST(ColourJpeg, ARegionDecodesTheSamePixelsAsTheWholeImage) {
    ColourJpegDecoder decoder;
    cv::RNG rng(16);
    for (const bool subsample : {true, false}) {
        ColourJpegParams params;
        params.subsample_420 = subsample;
        for (const cv::Size size : {cv::Size(640, 480), cv::Size(37, 29)}) {
            std::vector<uint8_t> bytes;
            ASSERT_TRUE(ColourJpegEncoder(params).encode(colourPattern(size.width, size.height), bytes).isOk());
            cv::Mat whole;
            ASSERT_TRUE(decoder.decode(bytes.data(), bytes.size(), size.width, size.height, whole).isOk());
            std::vector<cv::Rect> regions = {{0, 0, size.width, size.height},
                                             {0, 0, 1, 1},
                                             {size.width - 1, size.height - 1, 1, 1},
                                             {-20, -20, 45, 40},
                                             {size.width / 2, size.height / 2, size.width, size.height}};
            for (int i = 0; i < 40; ++i) {
                const int x = rng.uniform(0, size.width);
                const int y = rng.uniform(0, size.height);
                regions.emplace_back(x, y, rng.uniform(1, size.width - x + 1), rng.uniform(1, size.height - y + 1));
            }
            for (const cv::Rect& roi : regions) {
                cv::Mat part(size, CV_8UC3, cv::Scalar(1, 2, 3));
                const Status st = decoder.decodeRegion(bytes.data(), bytes.size(), size.width, size.height, roi, part);
                ASSERT_TRUE(st.isOk()) << st.toString() << " " << roi;
                const cv::Rect in = roi & cv::Rect(cv::Point(), size);
                EXPECT_EQ(cv::norm(part(in), whole(in), cv::NORM_INF), 0.0) << roi << " of " << size;
                EXPECT_EQ(pixelsNot(part.rowRange(0, in.y), {1, 2, 3}), 0) << "rows above " << roi << " written";
                EXPECT_EQ(pixelsNot(part.rowRange(in.y + in.height, size.height), {1, 2, 3}), 0)
                    << "rows below " << roi << " written";
            }
        }
    }
}

TEST(ColourJpeg, TheHeaderAloneIsChecked) {
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeColourJpeg(colourPattern(640, 480), 90, bytes).isOk());
    ColourJpegDecoder decoder;
    EXPECT_TRUE(decoder.checkHeader(bytes.data(), bytes.size(), 640, 480).isOk());
    const Status wrong = decoder.checkHeader(bytes.data(), bytes.size(), 64, 48);
    EXPECT_EQ(wrong.code(), StatusCode::kDataLoss);
    EXPECT_NE(wrong.message().find("JPEG is 640x480, camera says 64x48"), std::string::npos) << wrong.message();
    const std::vector<uint8_t> garbage(300, 0x5a);
    EXPECT_EQ(decoder.checkHeader(garbage.data(), garbage.size(), 640, 480).code(), StatusCode::kDataLoss);
    // The header says nothing of the entropy data: a payload cut after it passes, and fails when decoded.
    const std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(bytes.size() / 2));
    EXPECT_TRUE(decoder.checkHeader(cut.data(), cut.size(), 640, 480).isOk());
    cv::Mat out;
    EXPECT_EQ(decoder.decode(cut.data(), cut.size(), 640, 480, out).code(), StatusCode::kDataLoss);
    // And the decoder is whole again after the failure.
    EXPECT_TRUE(decoder.decode(bytes.data(), bytes.size(), 640, 480, out).isOk());
}

TEST(ColourJpeg, RejectsWrongSizeGarbageAndBadInput) {
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeColourJpeg(colourPattern(64, 48), 90, bytes).isOk());
    cv::Mat out;
    EXPECT_EQ(decodeColourJpeg(bytes.data(), bytes.size(), 640, 480, out).code(), StatusCode::kDataLoss);
    EXPECT_TRUE(out.empty());  // refused before allocating
    EXPECT_EQ(decodeColourJpeg(bytes.data(), bytes.size(), 0, 48, out).code(), StatusCode::kOutOfRange);
    EXPECT_EQ(decodeColourJpeg(bytes.data(), bytes.size(), 64, 9000, out).code(), StatusCode::kOutOfRange);
    const std::vector<uint8_t> garbage(300, 0x5a);
    EXPECT_EQ(decodeColourJpeg(garbage.data(), garbage.size(), 64, 48, out).code(), StatusCode::kDataLoss);
    EXPECT_EQ(decodeColourJpeg(nullptr, 0, 64, 48, out).code(), StatusCode::kDataLoss);
    // A header claiming 65000 x 65000 (SOF0 height/width patched) is refused on the header.
    std::vector<uint8_t> lying = bytes;
    for (size_t i = 0; i + 8 < lying.size(); ++i) {
        if (lying[i] == 0xff && lying[i + 1] == 0xc0) {
            lying[i + 5] = lying[i + 7] = 0xfd;
            lying[i + 6] = lying[i + 8] = 0xe8;
            break;
        }
    }
    EXPECT_FALSE(decodeColourJpeg(lying.data(), lying.size(), 64, 48, out).isOk());
    std::vector<uint8_t> enc_out;
    EXPECT_EQ(encodeColourJpeg(cv::Mat(4, 4, CV_8UC1), 90, enc_out).code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(encodeColourJpeg(colourPattern(4, 4), 0, enc_out).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace facescan::wire
