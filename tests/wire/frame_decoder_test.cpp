// The server's frame decoder (wire/messages.hpp): colour decoded up front or on demand gives the same pixels, on
// demand it decodes only what is asked for and each frame's own, a payload of the wrong size or no JPEG is refused
// with the frame either way, and damage in the entropy data costs the colour only, with a reason.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "wire/messages.hpp"

namespace facescan::wire {
namespace {

cv::Mat colourFrame(int seed) {
    cv::Mat bgr(480, 640, CV_8UC3);
    cv::RNG rng(static_cast<uint64>(seed));
    rng.fill(bgr, cv::RNG::UNIFORM, 0, 256);
    cv::GaussianBlur(bgr, bgr, {9, 9}, 3.0);  // texture JPEG keeps, so frames differ visibly
    return bgr;
}

EncodedFrame encodeFrame(const cv::Mat& bgr) {
    EncodedFrame out;
    const cv::Mat depth(480, 640, CV_16UC1, cv::Scalar(700));
    EXPECT_TRUE(FrameEncoder().encode(depth, bgr, out).isOk());
    return out;
}

CameraInfoData camera() {
    CameraInfoData c;
    c.session_id = "decoder";
    return c;
}

double maxDiff(const cv::Mat& a, const cv::Mat& b, const cv::Rect& roi) {
    return cv::norm(a(roi), b(roi), cv::NORM_INF);
}

TEST(FrameDecoder, ColourOnDemandIsTheColourDecodedUpFront) {
    const EncodedFrame enc = encodeFrame(colourFrame(1));
    const facescan_wire_RgbdFrame msg = toMessage("decoder", enc);
    FrameDecoder eager_decoder;
    recon::RgbdFrame eager;
    ASSERT_TRUE(eager_decoder.decode(msg, camera(), ColourDecode::kEager, eager).isOk());
    ASSERT_EQ(eager.colour_bgr.size(), cv::Size(640, 480));
    EXPECT_EQ(eager.colour_on_demand, nullptr);

    FrameDecoder decoder;
    recon::RgbdFrame frame;
    ASSERT_TRUE(decoder.decode(msg, camera(), ColourDecode::kOnDemand, frame).isOk());
    EXPECT_TRUE(frame.colour_bgr.empty()) << "nothing is decoded before a stage asks";
    ASSERT_NE(frame.colour_on_demand, nullptr);
    EXPECT_FLOAT_EQ(frame.depth_m.at<float>(100, 100), 0.7f);
    const cv::Rect head(250, 120, 150, 200);
    const cv::Mat& part = recon::frameColour(frame, head);
    ASSERT_EQ(part.size(), cv::Size(640, 480));
    EXPECT_EQ(maxDiff(part, eager.colour_bgr, head), 0.0);
    // Only the region's rows were decoded: a row well above it is not the frame's.
    EXPECT_GT(maxDiff(part, eager.colour_bgr, cv::Rect(0, 10, 640, 1)), 0.0);
    // A region inside the one decoded is served as it is; the whole image is decoded when asked for.
    EXPECT_EQ(maxDiff(recon::frameColour(frame, {260, 150, 20, 20}), eager.colour_bgr, head), 0.0);
    const cv::Mat& whole = recon::frameColour(frame, {0, 0, 640, 480});
    EXPECT_EQ(cv::norm(whole, eager.colour_bgr, cv::NORM_INF), 0.0);
    EXPECT_TRUE(decoder.colourStatus().isOk());

    // The next frame is its own, not the last one's region.
    const EncodedFrame enc2 = encodeFrame(colourFrame(2));
    ASSERT_TRUE(decoder.decode(toMessage("decoder", enc2), camera(), ColourDecode::kOnDemand, frame).isOk());
    ASSERT_TRUE(eager_decoder.decode(toMessage("decoder", enc2), camera(), ColourDecode::kEager, eager).isOk());
    EXPECT_EQ(maxDiff(recon::frameColour(frame, {260, 150, 20, 20}), eager.colour_bgr, {260, 150, 20, 20}), 0.0);
    // Released (its bytes are about to be recycled): nothing more is decoded from them.
    decoder.releaseColour();
    EXPECT_TRUE(recon::frameColour(frame, {0, 0, 640, 480}).empty());
}

TEST(FrameDecoder, ColourLeftOutOrUnregisteredHasNoSource) {
    const EncodedFrame enc = encodeFrame(colourFrame(3));
    FrameDecoder decoder;
    recon::RgbdFrame frame;
    ASSERT_TRUE(decoder.decode(toMessage("decoder", enc), camera(), ColourDecode::kNone, frame).isOk());
    EXPECT_TRUE(frame.colour_bgr.empty());
    EXPECT_EQ(frame.colour_on_demand, nullptr);
    CameraInfoData unregistered = camera();
    unregistered.colour_registered = false;
    ASSERT_TRUE(decoder.decode(toMessage("decoder", enc), unregistered, ColourDecode::kOnDemand, frame).isOk());
    EXPECT_EQ(frame.colour_on_demand, nullptr);
}

TEST(FrameDecoder, ColourOfTheWrongSizeOrNoJpegIsRefusedWithTheFrame) {
    EncodedFrame enc = encodeFrame(colourFrame(4));
    ASSERT_TRUE(encodeColourJpeg(colourFrame(4)(cv::Rect(0, 0, 320, 240)).clone(), 90, enc.colour).isOk());
    FrameDecoder decoder;
    recon::RgbdFrame frame;
    for (const ColourDecode mode : {ColourDecode::kEager, ColourDecode::kOnDemand}) {
        const Status st = decoder.decode(toMessage("decoder", enc), camera(), mode, frame);
        EXPECT_EQ(st.code(), StatusCode::kDataLoss);
        EXPECT_NE(st.message().find("JPEG is 320x240, camera says 640x480"), std::string::npos) << st.message();
        EXPECT_EQ(frame.colour_on_demand, nullptr);
    }
    enc.colour.assign(4000, 0x5a);
    EXPECT_EQ(decoder.decode(toMessage("decoder", enc), camera(), ColourDecode::kOnDemand, frame).code(),
              StatusCode::kDataLoss);
}

TEST(FrameDecoder, DamagedColourCostsTheColourOnlyAndSaysWhy) {
    EncodedFrame enc = encodeFrame(colourFrame(5));
    enc.colour.resize(enc.colour.size() / 3);  // the header is whole, two thirds of the image data are gone
    FrameDecoder decoder;
    recon::RgbdFrame frame;
    ASSERT_TRUE(decoder.decode(toMessage("decoder", enc), camera(), ColourDecode::kOnDemand, frame).isOk())
        << "the depth is good, and the colour's header too";
    ASSERT_NE(frame.colour_on_demand, nullptr);
    EXPECT_TRUE(recon::frameColour(frame, {200, 300, 100, 100}).empty());
    EXPECT_EQ(decoder.colourStatus().code(), StatusCode::kDataLoss);
    EXPECT_NE(decoder.colourStatus().message().find("JPEG data corrupt or truncated"), std::string::npos)
        << decoder.colourStatus().message();
    EXPECT_TRUE(recon::frameColour(frame, {200, 300, 10, 10}).empty()) << "no second try on the same bytes";
    // The next good frame decodes as if nothing had happened.
    const EncodedFrame good = encodeFrame(colourFrame(6));
    ASSERT_TRUE(decoder.decode(toMessage("decoder", good), camera(), ColourDecode::kOnDemand, frame).isOk());
    EXPECT_FALSE(recon::frameColour(frame, {200, 300, 100, 100}).empty());
    EXPECT_TRUE(decoder.colourStatus().isOk());
}

}  // namespace
}  // namespace facescan::wire
