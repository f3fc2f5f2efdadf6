// Saves frames as a TUM RGB-D folder that the agent's own tum: source reads back (`--source tum:DIR`), so that
// frames no server confirmed before the agent stopped can be streamed into any server later:
//   depth/NNNNNN.png   16-bit, 5000 units per metre (every TUM folder's scale: the tum: source's default)
//   rgb/NNNNNN.jpg     the JPEG the agent sent, byte for byte (a frame never sent: encoded here, as it would
//                      have been)
//   depth.txt rgb.txt  "timestamp path", one line per frame, written as each frame is saved: a folder cut short
//                      (a second Ctrl-C) still replays the frames saved before
//   intrinsics.txt     "fx fy cx cy" of the depth camera
//   sensor.txt         "NAME MIN_M MAX_M": the camera, when the source or --sensor named it
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "capture/frame_source.hpp"
#include "wire/messages.hpp"

namespace facescan::capture {

class TumRecorder {
 public:
    // Fills `dir`, which must not exist yet or be empty (AlreadyExists otherwise: nothing is ever overwritten).
    static StatusOr<TumRecorder> create(const std::filesystem::path& dir, const SourceInfo& source,
                                        int jpeg_quality = 90);
    // A frame as it went on the wire: depth decoded, colour kept as it was encoded.
    Status add(const wire::EncodedFrame& frame);
    // A frame that was captured but never encoded.
    Status add(const CapturedFrame& frame);
    int frames() const { return frames_; }
    const std::filesystem::path& dir() const { return dir_; }

 private:
    Status addDepth(const cv::Mat& raw, int64_t timestamp_ns, std::string& name);
    Status addColour(const std::string& name, const std::string& extension, const uint8_t* data, size_t size);

    std::filesystem::path dir_;
    SourceInfo source_;
    std::ofstream depth_list_;
    std::ofstream rgb_list_;
    bool has_rgb_list_ = false;
    int jpeg_quality_ = 90;
    int frames_ = 0;
    double last_timestamp_s_ = -1;
    cv::Mat depth_tum_;  // scratch: depth in TUM units
    cv::Mat scratch_;    // scratch: decoded depth
    cv::Mat colour_;     // the colour image being written (a view)
};

// A folder under `parent` for `name` that did not exist before: parent/name, else parent/name-2, name-3, ...
// (created here, empty, so that no other agent takes it meanwhile).
StatusOr<std::filesystem::path> createFreshDir(const std::filesystem::path& parent, const std::string& name);

// Where the agent saves frames no server confirmed, unless told: $XDG_STATE_HOME/facescan/unconfirmed, else
// ~/.local/state/facescan/unconfirmed (the XDG default), else ./facescan-unconfirmed.
std::filesystem::path defaultSaveDir();

}  // namespace facescan::capture
