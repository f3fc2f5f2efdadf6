// The synthetic Kinect as a frame source: the project's one renderer (facescan_synth) filming a head scan.
// Depth leaves here in units of 0.2 mm (TUM's 5000 per metre), finer than the Kinect's own quantisation at
// face range (about 1.4 mm at 0.7 m), so converting to raw units adds no error of its own.
#include <algorithm>

#include "capture/frame_source.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::capture {
namespace {

constexpr float kSyntheticDepthUnitsM = 0.0002f;

class SyntheticSource final : public FrameSource {
 public:
    SyntheticSource(synth::KinectSimulator sim, SourceInfo info, SourceOptions options)
        : sim_(std::move(sim)), info_(std::move(info)), options_(options) {}

    const SourceInfo& info() const override { return info_; }

    StatusOr<bool> next(CapturedFrame& out) override {
        if (next_ >= info_.expected_frames) return false;
        sim_.render(next_, frame_);
        recon::depthMetresToRaw(frame_.depth_m, kSyntheticDepthUnitsM, out.depth_raw);
        if (options_.colour) {
            frame_.colour_bgr.copyTo(out.colour_bgr);
        } else {
            out.colour_bgr.release();
        }
        out.timestamp_ns = frame_.timestamp_ns;
        out.index = static_cast<uint32_t>(next_++);
        return true;
    }

 private:
    synth::KinectSimulator sim_;
    SourceInfo info_;
    SourceOptions options_;
    recon::RgbdFrame frame_;
    int next_ = 0;
};

}  // namespace

StatusOr<std::unique_ptr<FrameSource>> openSyntheticSource(const std::string& options_text,
                                                           const SourceOptions& options) {
    ASSIGN_OR_RETURN(synth::SyntheticSpec spec, synth::parseSyntheticOptions(options_text));
    synth::SequenceParams& seq = spec.sequence;
    if (options.max_frames > 0) seq.frames = std::min(seq.frames, options.max_frames);
    ASSIGN_OR_RETURN(synth::HeadModel head, synth::loadSubject(spec.subject));

    SourceInfo info;
    info.intrinsics = spec.intrinsics;
    info.sensor = spec.sensor_model;
    info.sensor_known = true;
    info.depth_units_m = kSyntheticDepthUnitsM;
    info.colour_registered = true;
    info.has_colour = options.colour;
    info.rate_hz = seq.fps;
    info.is_recording = true;
    info.expected_frames = seq.frames;
    info.description = "synthetic:" + head.name;
    synth::KinectSimulator sim(std::move(head), seq, info.intrinsics);
    return std::unique_ptr<FrameSource>(std::make_unique<SyntheticSource>(std::move(sim), std::move(info), options));
}

}  // namespace facescan::capture
