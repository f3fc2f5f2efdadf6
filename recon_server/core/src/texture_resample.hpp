// Resampling a colour image at a sub-pixel position, for the texture bake (texture_bake.cpp): bilinear, and Keys'
// cubic convolution. Internal to recon_core.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <opencv2/core.hpp>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace facescan::recon::texture_detail {

// img: CV_8UC3, at least 2 x 2; (x, y) in pixels (the centre of pixel x is x); BGR 0-255.
inline Eigen::Vector3f bilinear(const cv::Mat& img, float x, float y) {
    const int x0 = std::clamp(static_cast<int>(std::floor(x)), 0, img.cols - 2);
    const int y0 = std::clamp(static_cast<int>(std::floor(y)), 0, img.rows - 2);
    const float fx = std::clamp(x - x0, 0.0f, 1.0f), fy = std::clamp(y - y0, 0.0f, 1.0f);
    const cv::Vec3b* r0 = img.ptr<cv::Vec3b>(y0);
    const cv::Vec3b* r1 = img.ptr<cv::Vec3b>(y0 + 1);
    Eigen::Vector3f out;
    for (int c = 0; c < 3; ++c) {
        const float top = r0[x0][c] * (1 - fx) + r0[x0 + 1][c] * fx;
        const float bottom = r1[x0][c] * (1 - fx) + r1[x0 + 1][c] * fx;
        out[c] = top * (1 - fy) + bottom * fy;
    }
    return out;
}

// Keys' cubic convolution (a = -0.5, Catmull-Rom) over the 4 x 4 pixels around (x, y): it keeps more of a
// pixel's detail than bilinear interpolation when the atlas resamples the colour image finer than its pixels.
inline Eigen::Vector3f bicubic(const cv::Mat& img, float x, float y) {
    // floor without a libm call (the baseline x86-64 has no rounding instruction)
    auto floorInt = [](float v) {
        const int i = static_cast<int>(v);
        return static_cast<float>(i) > v ? i - 1 : i;
    };
    const int x0 = floorInt(x), y0 = floorInt(y);
    const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
    auto weights = [](float t, float w[4]) {
        const float t2 = t * t, t3 = t2 * t;
        w[0] = -0.5f * t3 + t2 - 0.5f * t;
        w[1] = 1.5f * t3 - 2.5f * t2 + 1.0f;
        w[2] = -1.5f * t3 + 2.0f * t2 + 0.5f * t;
        w[3] = 0.5f * t3 - 0.5f * t2;
    };
    float wx[4], wy[4];
    weights(fx, wx);
    weights(fy, wy);
    float b = 0, g = 0, r = 0;
    if (x0 >= 1 && y0 >= 1 && x0 + 2 < img.cols && y0 + 2 < img.rows) {
        // Inside the image (nearly always): the 4 x 4 pixels straight from the rows, the rows' 12 bytes weighted
        // down the columns first, then across.
        float column[12] = {};
#if defined(__SSE2__)
        // Four lanes at a time (the compiler left the loop below scalar, a conversion and a multiply a byte).
        // The same sums in the same order as the loop.
        const __m128i zero = _mm_setzero_si128();
        __m128 c0 = _mm_setzero_ps(), c1 = _mm_setzero_ps(), c2 = _mm_setzero_ps();
        for (int j = 0; j < 4; ++j) {
            const uint8_t* p = img.ptr<uint8_t>(y0 - 1 + j) + 3 * (x0 - 1);
            // 8 bytes and 4 bytes: no read past the 12 (the last row's end may be the image's).
            int32_t last4 = 0;
            std::memcpy(&last4, p + 8, sizeof last4);
            const __m128i first8 = _mm_unpacklo_epi8(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)), zero);
            const __m128i rest = _mm_unpacklo_epi8(_mm_cvtsi32_si128(last4), zero);
            const __m128 w = _mm_set1_ps(wy[j]);
            c0 = _mm_add_ps(c0, _mm_mul_ps(w, _mm_cvtepi32_ps(_mm_unpacklo_epi16(first8, zero))));
            c1 = _mm_add_ps(c1, _mm_mul_ps(w, _mm_cvtepi32_ps(_mm_unpackhi_epi16(first8, zero))));
            c2 = _mm_add_ps(c2, _mm_mul_ps(w, _mm_cvtepi32_ps(_mm_unpacklo_epi16(rest, zero))));
        }
        _mm_storeu_ps(column, c0);
        _mm_storeu_ps(column + 4, c1);
        _mm_storeu_ps(column + 8, c2);
#else
        for (int j = 0; j < 4; ++j) {
            const uint8_t* p = img.ptr<uint8_t>(y0 - 1 + j) + 3 * (x0 - 1);
            for (int k = 0; k < 12; ++k) column[k] += wy[j] * static_cast<float>(p[k]);
        }
#endif
        b = wx[0] * column[0] + wx[1] * column[3] + wx[2] * column[6] + wx[3] * column[9];
        g = wx[0] * column[1] + wx[1] * column[4] + wx[2] * column[7] + wx[3] * column[10];
        r = wx[0] * column[2] + wx[1] * column[5] + wx[2] * column[8] + wx[3] * column[11];
    } else {
        for (int j = 0; j < 4; ++j) {
            const cv::Vec3b* row = img.ptr<cv::Vec3b>(std::clamp(y0 - 1 + j, 0, img.rows - 1));
            for (int i = 0; i < 4; ++i) {
                const cv::Vec3b& p = row[std::clamp(x0 - 1 + i, 0, img.cols - 1)];
                const float w = wx[i] * wy[j];
                b += w * p[0], g += w * p[1], r += w * p[2];
            }
        }
    }
    const Eigen::Vector3f out(b, g, r);
    return out.cwiseMax(0.0f).cwiseMin(255.0f);
}

}  // namespace facescan::recon::texture_detail
