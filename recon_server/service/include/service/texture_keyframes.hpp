// The colour frames a session keeps for the texture atlas it bakes on finish (recon/texture_atlas.hpp): the JPEG
// bytes as received (a 1280x720 frame is about 100 KB as JPEG, 2.7 MB decoded), with the pose of the depth camera
// when the frame was tracked, under a bound on their count and bytes. A frame is kept when its view of the head
// differs from every kept one by at least min_angle_deg, so the keyframes cover the head rather than pile up where
// the person held still; once the bound is reached, a frame that would widen the coverage more than the most
// redundant keyframe replaces it.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/status.hpp"
#include "recon/texture_atlas.hpp"
#include "wire/messages.hpp"
#include "wire/replica_codec.hpp"

namespace facescan::service {

struct KeyframeParams {
    int max_keyframes = 24;               // count; 0 = no texture (no colour kept)
    size_t max_bytes = size_t{32} << 20;  // bytes of colour payload kept per session at most
    float min_angle_deg = 6.0f;           // degrees between the viewing directions of two keyframes

    Status validate() const;
};

class TextureKeyframes {
 public:
    explicit TextureKeyframes(KeyframeParams params = {}) : params_(params) {}

    // A tracked frame's colour payload (codec as on the wire) and the depth camera's pose in the model's frame.
    // Only JPEG payloads are kept (raw colour would cost 30 times the memory). True when it was kept.
    bool offer(uint32_t seq, wire::ColourCodecId codec, const std::vector<uint8_t>& colour,
               const recon::Pose& T_world_depth);

    size_t count() const { return frames_.size(); }
    size_t bytes() const { return bytes_; }
    size_t offered() const { return offered_; }
    size_t rawSkipped() const { return raw_skipped_; }  // colour frames not kept because they were not JPEG
    void clear();
    // Grows whenever the kept set changes: a replica carries the keyframes only when they changed since its last.
    uint64_t version() const { return version_; }

    // For a replica, and back from one after a takeover: the scan's texture then still has the views the old owner
    // kept. Restored frames beyond this session's bounds (another server's settings) are dropped, oldest first.
    std::vector<wire::ReplicaKeyframe> save() const;
    void restore(const std::vector<wire::ReplicaKeyframe>& frames);

    // The keyframes decoded for baking: each view at the colour camera's resolution and pose (T_colour_depth after
    // the depth camera's). A frame that does not decode is left out with a note (the rest still texture).
    std::vector<recon::TextureView> views(const wire::CameraInfoData& camera, std::vector<std::string>* notes) const;

 private:
    struct Frame {
        uint32_t seq = 0;
        std::vector<uint8_t> jpeg;
        recon::Pose T_world_depth = recon::Pose::Identity();
        Eigen::Vector3f axis = Eigen::Vector3f::UnitZ();  // the depth camera's viewing direction, world frame
    };
    KeyframeParams params_;
    std::vector<Frame> frames_;
    size_t bytes_ = 0;
    size_t offered_ = 0;
    size_t raw_skipped_ = 0;
    uint64_t version_ = 0;
};

}  // namespace facescan::service
