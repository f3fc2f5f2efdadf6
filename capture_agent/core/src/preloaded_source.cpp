// A recording read into memory before streaming (facescan-agent --preload): models a capture PC that does not share
// the server's cores. Reading (PNG decoding, rendering) happens once, up front; next() then hands out the stored
// frames without copying pixels, so the agent's per-frame cost is its encoding and DDS writes alone.
#include <utility>
#include <vector>

#include "capture/frame_source.hpp"

namespace facescan::capture {
namespace {

class PreloadedSource final : public FrameSource {
 public:
    PreloadedSource(SourceInfo info, std::vector<CapturedFrame> frames)
        : info_(std::move(info)), frames_(std::move(frames)) {
        info_.expected_frames = static_cast<int>(frames_.size());
        info_.description += " (preloaded)";
    }

    const SourceInfo& info() const override { return info_; }

    StatusOr<bool> next(CapturedFrame& out) override {
        if (next_ >= frames_.size()) return false;
        const CapturedFrame& f = frames_[next_++];
        // cv::Mat assignment shares the stored pixels: the encoder only reads them.
        out.depth_raw = f.depth_raw;
        out.colour_bgr = f.colour_bgr;
        out.timestamp_ns = f.timestamp_ns;
        out.index = f.index;
        return true;
    }

 private:
    SourceInfo info_;
    std::vector<CapturedFrame> frames_;
    size_t next_ = 0;
};

}  // namespace

StatusOr<std::unique_ptr<FrameSource>> preloadSource(std::unique_ptr<FrameSource> source,
                                                     const std::function<void(int, int)>& progress) {
    if (!source) return invalidArgument("preload: no source");
    const SourceInfo info = source->info();
    if (!info.is_recording) {
        return invalidArgument(
            "--preload needs a recording (tum:DIR, oni:FILE, mkv:FILE, bag:FILE or synthetic), not a live camera (" +
            info.description + ")");
    }
    std::vector<CapturedFrame> frames;
    if (info.expected_frames > 0) frames.reserve(static_cast<size_t>(info.expected_frames));
    for (;;) {
        CapturedFrame f;
        ASSIGN_OR_RETURN(const bool got, source->next(f));
        if (!got) break;
        frames.push_back(std::move(f));
        if (progress) progress(static_cast<int>(frames.size()), info.expected_frames);
    }
    if (frames.empty()) return dataLoss("preload: " + info.description + " holds no frame");
    return std::unique_ptr<FrameSource>(std::make_unique<PreloadedSource>(info, std::move(frames)));
}

}  // namespace facescan::capture
