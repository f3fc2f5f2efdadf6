// The texture's colour keyframes (service/texture_keyframes.hpp).
#include "service/texture_keyframes.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "wire/colour_codec.hpp"

namespace facescan::service {
namespace {

float angleDeg(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
    return std::acos(std::clamp(a.dot(b), -1.0f, 1.0f)) * 180.0f / 3.14159265f;
}

}  // namespace

Status KeyframeParams::validate() const {
    if (max_keyframes < 0 || max_keyframes > 256) return invalidArgument("texture.max_keyframes must be in [0, 256]");
    if (max_bytes < (size_t{1} << 20) || max_bytes > (size_t{1} << 30)) {
        return invalidArgument("texture.max_mib must be in [1, 1024] MiB");
    }
    if (!(min_angle_deg >= 0 && min_angle_deg <= 90)) {
        return invalidArgument("texture.keyframe_deg must be in [0, 90] degrees");
    }
    return Status::ok();
}

void TextureKeyframes::clear() {
    if (!frames_.empty()) ++version_;
    frames_.clear();
    bytes_ = 0;
}

std::vector<wire::ReplicaKeyframe> TextureKeyframes::save() const {
    std::vector<wire::ReplicaKeyframe> out;
    out.reserve(frames_.size());
    for (const Frame& f : frames_) out.push_back({f.seq, f.jpeg, f.T_world_depth});
    return out;
}

void TextureKeyframes::restore(const std::vector<wire::ReplicaKeyframe>& frames) {
    clear();
    ++version_;
    for (const wire::ReplicaKeyframe& k : frames) {
        if (k.jpeg.empty() || !k.T_world_depth.matrix().allFinite()) continue;
        frames_.push_back(Frame{k.seq, k.jpeg, k.T_world_depth, k.T_world_depth.linear().col(2).normalized()});
        bytes_ += k.jpeg.size();
    }
    while (!frames_.empty() &&
           (static_cast<int>(frames_.size()) > params_.max_keyframes || bytes_ > params_.max_bytes)) {
        bytes_ -= frames_.front().jpeg.size();
        frames_.erase(frames_.begin());
    }
}

bool TextureKeyframes::offer(uint32_t seq, wire::ColourCodecId codec, const std::vector<uint8_t>& colour,
                             const recon::Pose& T_world_depth) {
    if (params_.max_keyframes == 0 || colour.empty()) return false;
    ++offered_;
    if (codec != wire::ColourCodecId::kJpeg) {
        ++raw_skipped_;
        return false;
    }
    if (colour.size() > params_.max_bytes || !T_world_depth.matrix().allFinite()) return false;
    const Eigen::Vector3f axis = T_world_depth.linear().col(2).normalized();
    float nearest = 180.0f;
    for (const Frame& f : frames_) nearest = std::min(nearest, angleDeg(axis, f.axis));
    if (!frames_.empty() && nearest < params_.min_angle_deg) return false;
    // Room: evict the most redundant keyframe (the one nearest another) while the bounds would be exceeded, but
    // only while the new frame widens the coverage more than that one does.
    while (static_cast<int>(frames_.size()) >= params_.max_keyframes || bytes_ + colour.size() > params_.max_bytes) {
        if (frames_.empty()) return false;
        size_t worst = 0;
        float worst_gap = std::numeric_limits<float>::max();
        for (size_t i = 0; i < frames_.size(); ++i) {
            float gap = 180.0f;
            for (size_t j = 0; j < frames_.size(); ++j) {
                if (j != i) gap = std::min(gap, angleDeg(frames_[i].axis, frames_[j].axis));
            }
            if (gap < worst_gap) worst_gap = gap, worst = i;
        }
        if (nearest <= worst_gap) return false;
        bytes_ -= frames_[worst].jpeg.size();
        frames_.erase(frames_.begin() + static_cast<long>(worst));
    }
    frames_.push_back(Frame{seq, colour, T_world_depth, axis});
    bytes_ += colour.size();
    ++version_;
    return true;
}

std::vector<recon::TextureView> TextureKeyframes::views(const wire::CameraInfoData& camera,
                                                        std::vector<std::string>* notes) const {
    std::vector<recon::TextureView> out;
    const recon::Intrinsics& k = camera.colourIntrinsics();
    wire::ColourJpegDecoder decoder;
    for (const Frame& f : frames_) {
        recon::TextureView v;
        v.colour = k;
        const Status s = decoder.decode(f.jpeg.data(), f.jpeg.size(), k.width_px, k.height_px, v.colour_bgr);
        if (!s.isOk()) {
            if (notes) notes->push_back("colour of frame " + std::to_string(f.seq) + " left out: " + s.message());
            continue;
        }
        // world -> depth camera -> colour camera.
        v.T_colour_mesh = camera.T_colour_depth * f.T_world_depth.inverse();
        out.push_back(std::move(v));
    }
    return out;
}

}  // namespace facescan::service
