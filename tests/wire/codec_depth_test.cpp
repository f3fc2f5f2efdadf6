// Lossless depth codecs: bit-exact round trips on real and pattern frames, and decoders that refuse every
// truncated, corrupt, mismatched or oversized payload with a Status (never a crash).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "test_data.hpp"
#include "wire/codecs.hpp"
#include "wire/packed_delta_codec.hpp"
#include "wire/rvl_codec.hpp"

namespace facescan::wire {
namespace {

constexpr DepthCodecId kAllCodecs[] = {DepthCodecId::kRaw16,          DepthCodecId::kRvl,       DepthCodecId::kZstd,
                                       DepthCodecId::kRvlZstd,        DepthCodecId::kDeltaZstd, DepthCodecId::kPng,
                                       DepthCodecId::kPackedDeltaZstd};
static_assert(std::size(kAllCodecs) == kDepthCodecCount, "every codec is tested");

// A test pattern with the structure of a Kinect v1 face frame: an ellipsoidal head at 0.7 m before a wall at
// 1.8 m, depth quantised the way the sensor's 1/8-pixel disparity is (f 575.8 px, baseline 0.075 m), holes.
cv::Mat facePattern(int w, int h, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> noise_px(0.0, 0.08);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    cv::Mat depth(h, w, CV_16UC1);
    for (int v = 0; v < h; ++v) {
        for (int u = 0; u < w; ++u) {
            const double x = (u - 0.5 * w) / (0.18 * w);
            const double y = (v - 0.45 * h) / (0.26 * h);
            const double r2 = x * x + y * y;
            double z_m = 1.8 + 0.0004 * v;  // wall, slightly tilted
            if (r2 < 1.0) z_m = 0.7 - 0.09 * std::sqrt(1.0 - r2);
            const double disparity_px = 575.8 * 0.075 / z_m + noise_px(rng);
            const double quantised_px = std::round(disparity_px * 8.0) / 8.0;
            const bool hole = u01(rng) < 0.03 || (r2 > 0.95 && r2 < 1.15 && u > w / 2);  // dropouts, edge shadow
            depth.at<uint16_t>(v, u) =
                hole ? 0 : static_cast<uint16_t>(std::lround(1000.0 * 575.8 * 0.075 / quantised_px));
        }
    }
    return depth;
}

cv::Mat noisePattern(int w, int h, uint32_t seed) {
    cv::Mat depth(h, w, CV_16UC1);
    cv::RNG rng(seed);
    rng.fill(depth, cv::RNG::UNIFORM, 0, 65536);
    return depth;
}

void expectRoundTrip(const cv::Mat& depth, DepthCodecId codec, const std::string& what) {
    DepthCodecParams params;
    params.codec = codec;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeDepth(depth, params, bytes).isOk()) << what << " " << depthCodecName(codec);
    cv::Mat decoded;
    const Status st = decodeDepth(codec, bytes.data(), bytes.size(), depth.cols, depth.rows, decoded);
    ASSERT_TRUE(st.isOk()) << what << " " << depthCodecName(codec) << ": " << st.toString();
    ASSERT_EQ(decoded.type(), CV_16UC1);
    ASSERT_EQ(decoded.size(), depth.size());
    EXPECT_EQ(cv::norm(decoded, depth, cv::NORM_INF), 0.0) << what << " " << depthCodecName(codec);
}

class DepthCodecTest : public ::testing::TestWithParam<DepthCodecId> {};

TEST_P(DepthCodecTest, RoundTripsPatternsBitExact) {
    const DepthCodecId codec = GetParam();
    expectRoundTrip(facePattern(640, 480, 1), codec, "face 640x480");
    expectRoundTrip(cv::Mat::zeros(480, 640, CV_16UC1), codec, "all zero");
    expectRoundTrip(cv::Mat(480, 640, CV_16UC1, cv::Scalar(65535)), codec, "all 65535");
    expectRoundTrip(noisePattern(640, 480, 2), codec, "uniform noise");
    expectRoundTrip(cv::Mat(1, 1, CV_16UC1, cv::Scalar(1234)), codec, "1x1");
    expectRoundTrip(cv::Mat(1, 1, CV_16UC1, cv::Scalar(0)), codec, "1x1 zero");
    expectRoundTrip(facePattern(7, 3, 3), codec, "7x3");
    expectRoundTrip(facePattern(641, 479, 4), codec, "641x479");
    expectRoundTrip(noisePattern(1, 333, 5), codec, "1x333 noise");
    // Alternating 0 / max: the worst case of RVL's run and delta codes.
    cv::Mat alternating(31, 17, CV_16UC1);
    for (int i = 0; i < static_cast<int>(alternating.total()); ++i) alternating.at<uint16_t>(i) = i % 2 ? 65535 : 0;
    expectRoundTrip(alternating, codec, "alternating 0/65535");
    // A view into a larger image (row stride != width) encodes the view only.
    const cv::Mat big = facePattern(320, 240, 6);
    expectRoundTrip(big(cv::Rect(13, 7, 101, 55)), codec, "ROI");
}

TEST_P(DepthCodecTest, RoundTripsRealKinectFramesBitExact) {
    FACESCAN_REQUIRE_DATA(data, ".");
    const std::vector<std::filesystem::path> files = {data / "biwi_subject01_5frames/depth/frame_00000.png",
                                                      data / "biwi_subject01_5frames/depth/frame_00004.png",
                                                      data / "7scenes_tsdf_fusion/rgbd-frames/frame-000150.depth.png",
                                                      data / "pcl_kinect_person/person_depth_mm.png"};
    int tested = 0;
    for (const auto& file : files) {
        if (!std::filesystem::exists(file)) continue;
        const cv::Mat depth = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
        ASSERT_EQ(depth.type(), CV_16UC1) << file;
        expectRoundTrip(depth, GetParam(), file.filename().string());
        ++tested;
    }
    if (tested == 0) GTEST_SKIP() << "no real depth frames found under " << data;
}

TEST_P(DepthCodecTest, RejectsEveryTruncationAndPadding) {
    const DepthCodecId codec = GetParam();
    const cv::Mat depth = facePattern(16, 12, 7);
    DepthCodecParams params;
    params.codec = codec;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeDepth(depth, params, bytes).isOk());
    DepthDecoder decoder;
    cv::Mat out;
    for (size_t len = 0; len < bytes.size(); ++len) {
        const std::vector<uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(len));
        EXPECT_FALSE(decoder.decode(codec, prefix.data(), prefix.size(), 16, 12, out).isOk()) << "prefix " << len;
    }
    std::vector<uint8_t> padded = bytes;
    padded.push_back(0);
    EXPECT_FALSE(decoder.decode(codec, padded.data(), padded.size(), 16, 12, out).isOk());
    EXPECT_FALSE(decoder.decode(codec, nullptr, 0, 16, 12, out).isOk());
    ASSERT_TRUE(decoder.decode(codec, bytes.data(), bytes.size(), 16, 12, out).isOk());  // still usable
}

TEST_P(DepthCodecTest, CorruptBytesNeverCrashAndHeaderDamageIsCaught) {
    const DepthCodecId codec = GetParam();
    const cv::Mat depth = facePattern(24, 18, 8);
    DepthCodecParams params;
    params.codec = codec;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeDepth(depth, params, bytes).isOk());
    DepthDecoder decoder;
    cv::Mat out;
    for (size_t i = 0; i < bytes.size(); ++i) {
        for (const uint8_t mask : {uint8_t{0x01}, uint8_t{0x80}, uint8_t{0xff}}) {
            std::vector<uint8_t> corrupt = bytes;
            corrupt[i] ^= mask;
            const Status st = decoder.decode(codec, corrupt.data(), corrupt.size(), 24, 18, out);
            // Every header byte is checked; body damage either fails or yields some 24x18 image (raw16 has no
            // redundancy to notice a flipped bit), but never a crash or a wrong-sized image.
            if (i < kDepthHeaderBytes) {
                EXPECT_FALSE(st.isOk()) << "header byte " << i;
            }
            if (st.isOk()) {
                EXPECT_EQ(out.size(), cv::Size(24, 18));
            }
        }
    }
}

TEST_P(DepthCodecTest, RejectsWrongExpectedSizeAndCodecTag) {
    const DepthCodecId codec = GetParam();
    DepthCodecParams params;
    params.codec = codec;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeDepth(facePattern(40, 30, 9), params, bytes).isOk());
    cv::Mat out;
    EXPECT_EQ(decodeDepth(codec, bytes.data(), bytes.size(), 41, 30, out).code(), StatusCode::kDataLoss);
    EXPECT_EQ(decodeDepth(codec, bytes.data(), bytes.size(), 40, 29, out).code(), StatusCode::kDataLoss);
    EXPECT_EQ(decodeDepth(codec, bytes.data(), bytes.size(), 0, 30, out).code(), StatusCode::kOutOfRange);
    EXPECT_EQ(decodeDepth(codec, bytes.data(), bytes.size(), 40, 5000, out).code(), StatusCode::kOutOfRange);
    const auto other = static_cast<DepthCodecId>((static_cast<int>(codec) + 1) % kDepthCodecCount);
    EXPECT_EQ(decodeDepth(other, bytes.data(), bytes.size(), 40, 30, out).code(), StatusCode::kDataLoss);
}

TEST_P(DepthCodecTest, RejectsOversizedHeaderClaimsBeforeAllocating) {
    const DepthCodecId codec = GetParam();
    DepthCodecParams params;
    params.codec = codec;
    std::vector<uint8_t> bytes;
    ASSERT_TRUE(encodeDepth(facePattern(40, 30, 10), params, bytes).isOk());
    cv::Mat out;
    // Claim 4096 x 4096 (within the absolute cap) while the camera says 40 x 30: refused on the header.
    std::vector<uint8_t> lying = bytes;
    lying[6] = 0x00, lying[7] = 0x10, lying[8] = 0x00, lying[9] = 0x10;
    EXPECT_EQ(decodeDepth(codec, lying.data(), lying.size(), 40, 30, out).code(), StatusCode::kDataLoss);
    EXPECT_TRUE(out.empty());
    // 65535 x 65535: over the absolute cap whatever is expected.
    lying[6] = lying[7] = lying[8] = lying[9] = 0xff;
    EXPECT_EQ(decodeDepth(codec, lying.data(), lying.size(), 4096, 4096, out).code(), StatusCode::kOutOfRange);
    EXPECT_TRUE(out.empty());
    // A body size that disagrees with the bytes present.
    lying = bytes;
    lying[15] = 0x7f;
    EXPECT_EQ(decodeDepth(codec, lying.data(), lying.size(), 40, 30, out).code(), StatusCode::kDataLoss);
}

TEST_P(DepthCodecTest, EncoderReusesOutputBufferAfterWarmUp) {
    DepthCodecParams params;
    params.codec = GetParam();
    if (params.codec == DepthCodecId::kPng) GTEST_SKIP() << "the PNG baseline allocates inside OpenCV's imencode";
    DepthEncoder encoder(params);
    const cv::Mat depth = facePattern(64, 48, 11);
    std::vector<uint8_t> out;
    ASSERT_TRUE(encoder.encode(depth, out).isOk());
    ASSERT_TRUE(encoder.encode(depth, out).isOk());
    const uint8_t* data = out.data();
    const size_t capacity = out.capacity();
    ASSERT_TRUE(encoder.encode(depth, out).isOk());
    EXPECT_EQ(out.data(), data);
    EXPECT_EQ(out.capacity(), capacity);
}

std::string codecTestName(const ::testing::TestParamInfo<DepthCodecId>& info) {
    std::string name = depthCodecName(info.param);
    std::replace(name.begin(), name.end(), '-', '_');
    return name;
}
INSTANTIATE_TEST_SUITE_P(AllCodecs, DepthCodecTest, ::testing::ValuesIn(kAllCodecs), codecTestName);

TEST(RvlCodec, MatchesWilsonsNibbleLayout) {
    // Pixels {0, 0, 5}: zeros 2 -> nibble 2; non-zeros 1 -> nibble 1; delta 5 zigzags to 10 = 0b001'010 ->
    // nibbles 0xA (010 + continue) then 0x1. Four nibbles, most significant first, zero-padded: 0x21A10000.
    const uint16_t pixels[] = {0, 0, 5};
    uint8_t out[rvl::maxEncodedBytes(3)] = {};
    ASSERT_EQ(rvl::encode(pixels, 3, out), 4u);
    uint32_t word = 0;
    std::memcpy(&word, out, 4);
    EXPECT_EQ(word, 0x21A10000u);
    uint16_t back[3] = {9, 9, 9};
    ASSERT_TRUE(rvl::decode(out, 4, back, 3).isOk());
    EXPECT_EQ(back[0], 0);
    EXPECT_EQ(back[1], 0);
    EXPECT_EQ(back[2], 5);
    // A non-zero run must not decode to zero: delta -5 after nothing gives 0 - 5 < 0.
    const uint32_t bad = 0x01900000u;  // zeros 0, non-zeros 1, zigzag 9 (= -5)
    std::memcpy(out, &bad, 4);
    EXPECT_EQ(rvl::decode(out, 4, back, 1).code(), StatusCode::kDataLoss);
}

TEST(PackedDeltaCodec, TokensAreRanksOfUsedValues) {
    // Values {1000, 1007, 0, 60000}: used set {0, 1000, 1007, 60000} -> ranks {1, 2, 0, 3}; deltas from the left
    // (pixel 0 from rank 0): 1, 1, -2, 3 -> zigzag 2, 2, 3, 6: one byte each after the 8 KB value map.
    const uint16_t pixels[] = {1000, 1007, 0, 60000};
    std::vector<uint16_t> table(65536);
    std::vector<uint8_t> tokens(packed::maxTokenBytes(4));
    ASSERT_EQ(packed::encode(pixels, 4, 1, table.data(), tokens.data()), packed::kValueMapBytes + 4);
    EXPECT_EQ(tokens[0], 1);                      // value 0
    EXPECT_EQ(tokens[125], (1 << 0) | (1 << 7));  // values 1000 and 1007 share byte 125
    const uint8_t* t = tokens.data() + packed::kValueMapBytes;
    EXPECT_EQ(std::vector<int>(t, t + 4), (std::vector<int>{2, 2, 3, 6}));
    uint16_t back[4] = {};
    ASSERT_TRUE(packed::decode(tokens.data(), packed::kValueMapBytes + 4, 4, 1, table.data(), back).isOk());
    EXPECT_TRUE(std::equal(back, back + 4, pixels));
    // A rank past the value map, bytes left over, a short map, an empty map, a cut escape: all DATA_LOSS.
    std::vector<uint8_t> bad = tokens;
    bad[packed::kValueMapBytes + 3] = 8;  // rank 0 + 4 past the 4 values
    EXPECT_EQ(packed::decode(bad.data(), packed::kValueMapBytes + 4, 4, 1, table.data(), back).code(),
              StatusCode::kDataLoss);
    EXPECT_EQ(packed::decode(tokens.data(), packed::kValueMapBytes + 4, 3, 1, table.data(), back).code(),
              StatusCode::kDataLoss);
    EXPECT_EQ(packed::decode(tokens.data(), 100, 1, 1, table.data(), back).code(), StatusCode::kDataLoss);
    std::vector<uint8_t> empty(packed::kValueMapBytes + 1, 0);
    EXPECT_EQ(packed::decode(empty.data(), empty.size(), 1, 1, table.data(), back).code(), StatusCode::kDataLoss);
    bad = tokens;
    bad[packed::kValueMapBytes] = 0xff;  // escape with one byte left
    EXPECT_EQ(packed::decode(bad.data(), packed::kValueMapBytes + 2, 1, 1, table.data(), back).code(),
              StatusCode::kDataLoss);
}

// The token format as wire/packed_delta_codec.hpp states it, one token at a time: the oracle for the decoder, which
// takes runs of 8 one-byte tokens at once. The same outcome, message included, for every stream.
Status referencePackedDecode(const std::vector<uint8_t>& t, int width, int height, std::vector<uint16_t>& pixels) {
    if (t.size() < packed::kValueMapBytes) {
        return dataLoss("packed depth tokens truncated in the value map (" + std::to_string(t.size()) + " bytes)");
    }
    std::vector<uint16_t> value_of;
    for (uint32_t v = 0; v < 65536; ++v) {
        if (t[v / 8] & (1u << (v % 8))) value_of.push_back(static_cast<uint16_t>(v));
    }
    if (value_of.empty()) return dataLoss("packed depth value map is empty");
    size_t at = packed::kValueMapBytes;
    uint16_t above = 0;
    for (int r = 0; r < height; ++r) {
        uint16_t pred = above;
        for (int c = 0; c < width; ++c) {
            if (at >= t.size()) {
                return dataLoss("packed depth tokens end at pixel " + std::to_string(size_t(r) * width + c));
            }
            uint32_t z = t[at++];
            if (z == 0xff) {
                if (t.size() - at < 2) return dataLoss("packed depth tokens end inside an escaped token");
                z = t[at] | t[at + 1] << 8;
                at += 2;
            }
            const auto delta = static_cast<uint16_t>((z >> 1) ^ (0u - (z & 1)));
            const auto rank = static_cast<uint16_t>(pred + delta);
            if (rank >= value_of.size()) {
                return dataLoss("packed depth rank " + std::to_string(rank) + " outside the value map's " +
                                std::to_string(value_of.size()) + " values");
            }
            pixels[size_t(r) * width + c] = value_of[rank];
            pred = rank;
            if (c == 0) above = rank;
        }
    }
    if (at != t.size()) {
        return dataLoss("packed depth tokens have " + std::to_string(t.size() - at) + " bytes left over");
    }
    return Status::ok();
}

TEST(PackedDeltaCodec, DecoderAgreesWithTheFormatOnEveryStream) {
    // Rows of 1..40 pixels (runs of 8 and their remainders), deltas past one byte (escapes inside and between
    // runs), then the stream as encoded, with bytes overwritten (ranks past the map, stray escapes), cut short, or
    // with a byte too many.
    std::mt19937 rng(16);
    std::vector<uint16_t> rank_of(65536), value_of(65536);
    int decoded = 0, refused = 0;
    for (int trial = 0; trial < 4000; ++trial) {
        const int w = 1 + static_cast<int>(rng() % 40), h = 1 + static_cast<int>(rng() % 5);
        const uint32_t spread = 1 + rng() % 3000;
        std::vector<uint16_t> px(size_t(w) * h);
        for (auto& v : px) v = rng() % 10 == 0 ? 0 : static_cast<uint16_t>(500 + rng() % spread);
        std::vector<uint8_t> tokens(packed::maxTokenBytes(px.size()));
        tokens.resize(packed::encode(px.data(), w, h, rank_of.data(), tokens.data()));
        const size_t body = tokens.size() - packed::kValueMapBytes;
        switch (trial % 4) {
            case 1:
                for (int i = 0; i < 3; ++i) tokens[packed::kValueMapBytes + rng() % body] = static_cast<uint8_t>(rng());
                break;
            case 2: tokens.resize(packed::kValueMapBytes + rng() % (body + 1)); break;
            case 3: tokens.push_back(static_cast<uint8_t>(rng())); break;
            default: break;
        }
        std::vector<uint16_t> want(px.size()), got(px.size());
        const Status expected = referencePackedDecode(tokens, w, h, want);
        const Status status = packed::decode(tokens.data(), tokens.size(), w, h, value_of.data(), got.data());
        ASSERT_EQ(status.toString(), expected.toString()) << "trial " << trial << ", " << w << "x" << h;
        if (!status.isOk()) {
            ++refused;
            continue;
        }
        ++decoded;
        ASSERT_EQ(got, want) << "trial " << trial;
        if (trial % 4 == 0) {
            ASSERT_EQ(got, px) << "trial " << trial;  // untouched: the frame itself
        }
    }
    EXPECT_GT(decoded, 1000);
    EXPECT_GT(refused, 1000);
}

TEST(PackedDeltaCodec, BeatsPlainDeltasOnDisparityQuantisedDepth) {
    // The reason the codec exists: Kinect depth uses a sparse subset of millimetre values. On the Kinect-like
    // pattern the packed codec must be smaller than plain deltas (measured on real frames: 8.8:1 vs 6.8:1).
    const cv::Mat depth = facePattern(640, 480, 7);
    std::vector<uint8_t> packed_bytes, delta_bytes;
    DepthCodecParams params;
    params.codec = DepthCodecId::kPackedDeltaZstd;
    ASSERT_TRUE(encodeDepth(depth, params, packed_bytes).isOk());
    params.codec = DepthCodecId::kDeltaZstd;
    ASSERT_TRUE(encodeDepth(depth, params, delta_bytes).isOk());
    EXPECT_LT(double(packed_bytes.size()), 0.9 * double(delta_bytes.size()))
        << packed_bytes.size() << " vs " << delta_bytes.size();
}

TEST(DepthCodecNames, TagsAndNamesRoundTrip) {
    for (const DepthCodecId codec : kAllCodecs) {
        EXPECT_EQ(depthCodecFromName(depthCodecName(codec)), codec);
        const auto from_tag = depthCodecFromTag(static_cast<uint32_t>(codec));
        ASSERT_TRUE(from_tag.isOk());
        EXPECT_EQ(*from_tag, codec);
    }
    EXPECT_FALSE(depthCodecFromTag(kDepthCodecCount).isOk());
    EXPECT_FALSE(depthCodecFromName("lzma").has_value());
}

TEST(DepthCodecParams, ValidateRejectsBadLevels) {
    DepthCodecParams params;
    EXPECT_TRUE(params.validate().isOk());
    params.zstd_level = 40;
    EXPECT_FALSE(params.validate().isOk());
    params = {};
    params.zstd_fast_step = -1;
    EXPECT_FALSE(params.validate().isOk());
    params.zstd_level = 40;
    std::vector<uint8_t> out;
    EXPECT_EQ(DepthEncoder(params).encode(facePattern(8, 8, 1), out).code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(DepthEncoder().encode(cv::Mat(8, 8, CV_32FC1), out).code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(DepthEncoder().encode(cv::Mat(), out).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace facescan::wire
