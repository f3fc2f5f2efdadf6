// The synthetic Kinect as a frame source: the project's one renderer (facescan_synth) filming a head scan.
// Depth leaves here in units of 0.2 mm (TUM's 5000 per metre), finer than the Kinect's own quantisation at
// face range (about 1.4 mm at 0.7 m), so converting to raw units adds no error of its own.
#include <cstdlib>
#include <sstream>

#include "capture/frame_source.hpp"
#include "synth/kinect_simulator.hpp"

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

// Parses "frames=120,distance=0.7,yaw=35,pitch=12,seed=3,noise=0,subject=builtin".
Status parseOptions(const std::string& text, synth::SequenceParams& seq, std::string& subject) {
    std::stringstream items(text);
    std::string item;
    while (std::getline(items, item, ',')) {
        if (item.empty()) continue;
        const auto eq = item.find('=');
        if (eq == std::string::npos) return invalidArgument("synthetic option '" + item + "' is not key=value");
        const std::string key = item.substr(0, eq);
        const std::string value = item.substr(eq + 1);
        char* end = nullptr;
        const double number = std::strtod(value.c_str(), &end);
        const bool numeric = end && *end == '\0' && !value.empty();
        if (key == "subject") {
            subject = value;
            continue;
        }
        if (!numeric) return invalidArgument("synthetic option " + key + "=" + value + ": expected a number");
        if (key == "frames") {
            seq.frames = static_cast<int>(number);
        } else if (key == "distance") {
            seq.distance_m = static_cast<float>(number);
        } else if (key == "yaw") {
            seq.yaw_amplitude_deg = static_cast<float>(number);
        } else if (key == "pitch") {
            seq.pitch_amplitude_deg = static_cast<float>(number);
        } else if (key == "seed") {
            seq.seed = static_cast<uint64_t>(number);
        } else if (key == "noise") {
            seq.noise = number != 0;
        } else if (key == "period") {
            seq.yaw_period_frames = static_cast<float>(number);
            seq.pitch_period_frames = static_cast<float>(number / 2);
        } else {
            return invalidArgument("unknown synthetic option '" + key +
                                   "' (known: frames, distance, yaw, pitch, period, seed, noise, subject)");
        }
    }
    return seq.validate();
}

}  // namespace

StatusOr<std::unique_ptr<FrameSource>> openSyntheticSource(const std::string& options_text,
                                                           const SourceOptions& options) {
    synth::SequenceParams seq;
    std::string subject = "auto";
    RETURN_IF_ERROR(parseOptions(options_text, seq, subject));
    if (options.max_frames > 0) seq.frames = std::min(seq.frames, options.max_frames);

    synth::HeadModel head;
    if (subject == "auto") {
        head = synth::defaultHead();
    } else if (subject == "builtin") {
        head = synth::builtinHead();
    } else if (subject == "scan") {
        const auto dir = synth::findLeePerrySmith();
        if (!dir) return notFound("subject=scan: the Lee Perry-Smith scan was not found (set FACESCAN_DATA_DIR)");
        ASSIGN_OR_RETURN(head, synth::loadHeadScan(*dir));
    } else {
        ASSIGN_OR_RETURN(head, synth::loadHeadScan(subject));
    }

    SourceInfo info;
    info.intrinsics = recon::Intrinsics::kinectV1();
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
