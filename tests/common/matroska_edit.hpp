// Test recordings made from a real Matroska recording's own bytes, edited the way Matroska allows: an element
// blanked out by a Void element of the same size, clusters appended (the capture repeated later in time, the
// header's duration grown to match). A minimal EBML walk finds the elements. Used by the mkv: reader's tests.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

namespace facescan::testing::matroska {

namespace fs = std::filesystem;

inline std::vector<uint8_t> readFile(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
inline void writeFile(const fs::path& path, const std::vector<uint8_t>& bytes) {
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

struct Element {
    uint32_t id = 0;
    size_t start = 0, body = 0, end = 0;  // the element, its payload, one past it
};
inline uint64_t readVint(const std::vector<uint8_t>& d, size_t& at, bool keep_marker) {
    int length = 1;
    while (length <= 8 && !(d.at(at) & (0x80 >> (length - 1)))) ++length;
    uint64_t v = keep_marker ? d[at] : d[at] & (0xFF >> length);
    for (int i = 1; i < length; ++i) v = (v << 8) | d.at(at + static_cast<size_t>(i));
    at += static_cast<size_t>(length);
    return v;
}
inline std::vector<Element> children(const std::vector<uint8_t>& d, size_t from, size_t to) {
    std::vector<Element> out;
    while (from < to) {
        Element e;
        e.start = from;
        e.id = static_cast<uint32_t>(readVint(d, from, true));
        const uint64_t size = readVint(d, from, false);
        e.body = from;
        e.end = std::min(to, from + static_cast<size_t>(size));
        out.push_back(e);
        from = e.end;
    }
    return out;
}
inline Element find(const std::vector<Element>& list, uint32_t id) {
    for (const Element& e : list)
        if (e.id == id) return e;
    ADD_FAILURE() << "no element " << std::hex << id;
    return {};
}
constexpr uint32_t kSegment = 0x18538067, kCluster = 0x1F43B675, kTracks = 0x1654AE6B, kTrackEntry = 0xAE,
                   kAttachments = 0x1941A469, kTimecode = 0xE7, kSimpleBlock = 0xA3, kCrc = 0xBF, kInfo = 0x1549A966,
                   kDuration = 0x4489;

// Blanks out an element: a Void (0xEC) with an 8-byte size covering exactly its bytes.
inline void blank(std::vector<uint8_t>& d, const Element& e) {
    const size_t size = e.end - e.start - 9;
    d[e.start] = 0xEC;
    d[e.start + 1] = 0x01;
    for (int i = 0; i < 7; ++i) d[e.start + 2 + static_cast<size_t>(i)] = static_cast<uint8_t>(size >> (8 * (6 - i)));
}

// The recording's top level: the Segment's children.
inline std::vector<Element> segmentChildren(const std::vector<uint8_t>& d) {
    const Element segment = find(children(d, 0, d.size()), kSegment);
    return children(d, segment.body, segment.end);
}

// The recording with its one capture repeated `copies` times 200 ms apart (the recorder's 5 fps), leaving out the
// colour block of copy `no_colour_copy`: the copies are clusters appended after the original, the Segment's size
// made unknown (as a recorder still writing leaves it).
inline std::vector<uint8_t> repeated(std::vector<uint8_t> d, int copies, int no_colour_copy) {
    const std::vector<Element> top = segmentChildren(d);
    Element cluster;
    for (const Element& e : top)
        if (e.id == kCluster && e.end - e.body > cluster.end - cluster.body) cluster = e;  // the capture's
    const Element segment = find(children(d, 0, d.size()), kSegment);
    for (size_t i = 0; i < 8; ++i) d[segment.start + 4 + i] = i == 0 ? 0x01 : 0xFF;
    const std::vector<Element> inside = children(d, cluster.body, cluster.end);
    const Element timecode = find(inside, kTimecode);
    uint64_t base = 0;
    for (size_t i = timecode.body; i < timecode.end; ++i) base = (base << 8) | d[i];
    std::vector<uint8_t> tail;
    for (int copy = 1; copy < copies; ++copy) {
        std::vector<uint8_t> body;
        const uint64_t t = base + static_cast<uint64_t>(copy) * 200000;  // TimecodeScale: microseconds
        body.insert(body.end(), {0xE7, 0x84});
        for (int i = 3; i >= 0; --i) body.push_back(static_cast<uint8_t>(t >> (8 * i)));
        for (const Element& e : inside) {
            if (e.id == kTimecode || e.id == kCrc) continue;  // a new time; no checksum over changed bytes
            if (e.id == kSimpleBlock && copy == no_colour_copy && (d[e.body] & 0x7F) == 1) continue;  // COLOR
            body.insert(body.end(), d.begin() + static_cast<long>(e.start), d.begin() + static_cast<long>(e.end));
        }
        tail.insert(tail.end(), {0x1F, 0x43, 0xB6, 0x75, 0x01});
        for (int i = 6; i >= 0; --i) tail.push_back(static_cast<uint8_t>(body.size() >> (8 * i)));
        tail.insert(tail.end(), body.begin(), body.end());
    }
    d.insert(d.end(), tail.begin(), tail.end());
    // The header's duration (a float in the same units as the clusters' times) grows by the copies' 200 ms each.
    const Element info = find(segmentChildren(d), kInfo);
    const Element duration = find(children(d, info.body, info.end), kDuration);
    const size_t bytes = duration.end - duration.body;
    uint64_t bits = 0;
    for (size_t i = duration.body; i < duration.end; ++i) bits = (bits << 8) | d[i];
    double value = 0;
    if (bytes == 8) {
        std::memcpy(&value, &bits, 8);
    } else {
        const auto bits32 = static_cast<uint32_t>(bits);
        float f = 0;
        std::memcpy(&f, &bits32, 4);
        value = f;
    }
    value += (copies - 1) * 200000.0;
    if (bytes == 8) {
        std::memcpy(&bits, &value, 8);
    } else {
        const auto f = static_cast<float>(value);
        uint32_t bits32 = 0;
        std::memcpy(&bits32, &f, 4);
        bits = bits32;
    }
    for (size_t i = 0; i < bytes; ++i) d[duration.end - 1 - i] = static_cast<uint8_t>(bits >> (8 * i));
    return d;
}

}  // namespace facescan::testing::matroska
