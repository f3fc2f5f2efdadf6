// RVL (Wilson 2017), written from the paper's listing with bounds checks on every read for network input.
#include "wire/rvl_codec.hpp"

#include <bit>
#include <cstring>
#include <string>

namespace facescan::wire::rvl {
namespace {

static_assert(std::endian::native == std::endian::little, "RVL words are stored little-endian");

// Variable-length codes of 3-bit groups, least significant group first; a nibble's high bit says "more follows".
class NibbleWriter {
 public:
    explicit NibbleWriter(uint8_t* out) : out_(out) {}

    void put(uint32_t value) {
        do {
            uint32_t nibble = value & 0x7u;
            value >>= 3;
            if (value) nibble |= 0x8u;
            word_ = (word_ << 4) | nibble;
            if (++nibbles_ == 8) flush();
        } while (value);
    }
    size_t finish() {
        if (nibbles_ > 0) {
            word_ <<= 4 * (8 - nibbles_);  // pad the last word with zero nibbles, as Wilson's encoder does
            flush();
        }
        return bytes_;
    }

 private:
    void flush() {
        std::memcpy(out_ + bytes_, &word_, 4);
        bytes_ += 4;
        word_ = 0;
        nibbles_ = 0;
    }
    uint8_t* out_;
    size_t bytes_ = 0;
    uint32_t word_ = 0;
    int nibbles_ = 0;
};

class NibbleReader {
 public:
    NibbleReader(const uint8_t* data, size_t size) : p_(data), end_(data + size) {}

    // False when the stream ends inside a code or a code is longer than 10 groups (30 bits; no valid count or
    // delta needs more than 25).
    bool get(uint32_t& value) {
        uint32_t v = 0;
        for (int shift = 0; shift <= 27; shift += 3) {
            if (nibbles_ == 0) {
                if (end_ - p_ < 4) return false;
                std::memcpy(&word_, p_, 4);
                p_ += 4;
                nibbles_ = 8;
            }
            const uint32_t nibble = word_ >> 28;
            word_ <<= 4;
            --nibbles_;
            v |= (nibble & 0x7u) << shift;
            if (!(nibble & 0x8u)) {
                value = v;
                return true;
            }
        }
        return false;
    }
    // The encoder pads only the last word, with zero nibbles, and writes nothing after it.
    bool atCleanEnd() const { return p_ == end_ && word_ == 0; }

 private:
    const uint8_t* p_;
    const uint8_t* end_;
    uint32_t word_ = 0;
    int nibbles_ = 0;
};

}  // namespace

size_t encode(const uint16_t* pixels, size_t pixel_count, uint8_t* out) {
    NibbleWriter writer(out);
    const uint16_t* p = pixels;
    const uint16_t* const end = pixels + pixel_count;
    int32_t previous = 0;
    while (p != end) {
        const uint16_t* run = p;
        while (p != end && *p == 0) ++p;
        writer.put(static_cast<uint32_t>(p - run));
        run = p;
        while (p != end && *p != 0) ++p;
        writer.put(static_cast<uint32_t>(p - run));
        for (; run != p; ++run) {
            const int32_t delta = static_cast<int32_t>(*run) - previous;
            writer.put(static_cast<uint32_t>(delta * 2) ^ static_cast<uint32_t>(delta >> 31));  // zigzag
            previous = *run;
        }
    }
    return writer.finish();
}

Status decode(const uint8_t* data, size_t size, uint16_t* pixels, size_t pixel_count) {
    if (size % 4 != 0) return dataLoss("RVL stream of " + std::to_string(size) + " bytes is not whole 32-bit words");
    NibbleReader reader(data, size);
    size_t i = 0;
    int32_t previous = 0;
    while (i < pixel_count) {
        uint32_t zeros = 0;
        uint32_t nonzeros = 0;
        if (!reader.get(zeros) || !reader.get(nonzeros)) {
            return dataLoss("RVL stream truncated or corrupt after " + std::to_string(i) + " of " +
                            std::to_string(pixel_count) + " pixels");
        }
        if (zeros == 0 && nonzeros == 0) return dataLoss("RVL stream has an empty run pair (corrupt)");
        if (zeros > pixel_count - i || nonzeros > pixel_count - i - zeros) {
            return dataLoss("RVL run overflows the image at pixel " + std::to_string(i));
        }
        std::memset(pixels + i, 0, size_t{zeros} * sizeof(uint16_t));
        i += zeros;
        for (uint32_t k = 0; k < nonzeros; ++k) {
            uint32_t code = 0;
            if (!reader.get(code)) return dataLoss("RVL stream truncated inside a run of values");
            const int32_t delta = static_cast<int32_t>(code >> 1) ^ -static_cast<int32_t>(code & 1u);
            const int32_t current = previous + delta;
            if (current <= 0 || current > 65535) {
                return dataLoss("RVL value out of range in a non-zero run at pixel " + std::to_string(i));
            }
            pixels[i++] = static_cast<uint16_t>(current);
            previous = current;
        }
    }
    if (!reader.atCleanEnd()) return dataLoss("RVL stream has trailing data after the last pixel");
    return Status::ok();
}

}  // namespace facescan::wire::rvl
