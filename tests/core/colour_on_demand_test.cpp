// Colour on demand (recon::ColourSource): the server decodes a frame's JPEG only where a stage reads it.
// A scan whose colour comes from a source must be the scan with the colour given up front, bit for bit, even when
// the source leaves every pixel outside the region asked for wrong; a frame only tracked asks for none; and colour
// that cannot be had is the same as none.
#include <gtest/gtest.h>

#include <optional>
#include <vector>

#include "recon/scan_step.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::recon {
namespace {

// Gives the frame's colour inside the region asked for, and magenta outside it: a stage that read beyond its
// region would put magenta in the model.
class RegionOnlyColour final : public ColourSource {
 public:
    void reset(const cv::Mat* bgr) {
        bgr_ = bgr;
        asked.clear();
    }
    const cv::Mat& colour(const cv::Rect& roi_px) override {
        asked.push_back(roi_px);
        if (bgr_ == nullptr || fail) return none_;
        out_.create(bgr_->size(), CV_8UC3);
        out_.setTo(cv::Scalar(255, 0, 255));
        const cv::Rect in = roi_px & cv::Rect(cv::Point(), bgr_->size());
        (*bgr_)(in).copyTo(out_(in));
        return out_;
    }
    std::vector<cv::Rect> asked;  // this frame's requests
    bool fail = false;            // the payload is damaged: nothing can be had

 private:
    const cv::Mat* bgr_ = nullptr;
    cv::Mat out_;
    const cv::Mat none_;
};

enum class Colour { kUpFront, kOnDemand, kDamaged, kNone };

struct Scan {
    std::vector<Pose> poses;
    std::vector<bool> fused, detected;
    std::vector<std::vector<cv::Rect>> asked;  // per frame, on demand only
    Mesh mesh;
};

// The gentle turn through scanFrame, fusing every other frame from frame 12 (the load's last economy step).
Scan scan(Colour colour) {
    synth::SequenceParams sp;
    EXPECT_TRUE(synth::applyScenario("gentle", sp).isOk());
    sp.frames = 30;
    sp.seed = 23;
    const synth::KinectSimulator sim(synth::builtinHead(), sp);
    Reconstructor rec(sim.intrinsics(), ReconParams::faceDefaults());
    StatusOr<FacePipeline> pipeline =
        FacePipeline::create({}, sim.intrinsics(), ColourCamera::registeredTo(sim.intrinsics()));
    EXPECT_TRUE(pipeline.isOk());
    RegionOnlyColour source;
    source.fail = colour == Colour::kDamaged;
    Scan out;
    RgbdFrame rendered;
    RgbdFrame frame;
    ScanStep step;
    for (int i = 0; i < sp.frames; ++i) {
        if (i == 12) rec.setFuseEvery(2);
        sim.render(i, rendered);
        frame.depth_m = rendered.depth_m;
        frame.timestamp_ns = rendered.timestamp_ns;
        frame.colour_bgr = colour == Colour::kUpFront ? rendered.colour_bgr : cv::Mat();
        const bool on_demand = colour == Colour::kOnDemand || colour == Colour::kDamaged;
        frame.colour_on_demand = on_demand ? &source : nullptr;
        source.reset(&rendered.colour_bgr);
        scanFrame(*pipeline, rec, frame, step);
        EXPECT_TRUE(step.frame.tracked) << "frame " << i << ": " << step.frame.reason;
        out.poses.push_back(step.frame.tracking.T_world_camera);
        out.fused.push_back(step.frame.integrated);
        out.detected.push_back(step.head.detection_ran);
        out.asked.push_back(source.asked);
    }
    out.mesh = rec.extractMesh();
    return out;
}

void expectSameScan(const Scan& a, const Scan& b) {
    ASSERT_EQ(a.poses.size(), b.poses.size());
    for (size_t i = 0; i < a.poses.size(); ++i) {
        EXPECT_TRUE(a.poses[i].isApprox(b.poses[i], 0.0f)) << "frame " << i;
        EXPECT_EQ(a.fused[i], b.fused[i]) << "frame " << i;
    }
    ASSERT_EQ(a.mesh.n_vertices(), b.mesh.n_vertices());
    ASSERT_GT(a.mesh.n_vertices(), 1000u);
    int differ = 0;
    for (const auto v : a.mesh.vertices()) {
        differ += a.mesh.point(v) != b.mesh.point(v) || a.mesh.color(v) != b.mesh.color(v) ? 1 : 0;
    }
    EXPECT_EQ(differ, 0) << "vertices with another position or colour";
}

TEST(ColourOnDemand, GivesTheScanOfColourUpFrontAndDecodesOnlyWhatIsRead) {
    const Scan up_front = scan(Colour::kUpFront);
    const Scan on_demand = scan(Colour::kOnDemand);
    expectSameScan(up_front, on_demand);
    int tracked_only = 0;
    for (size_t i = 0; i < on_demand.asked.size(); ++i) {
        const std::vector<cv::Rect>& asked = on_demand.asked[i];
        if (on_demand.detected[i]) {
            // Detection reads the whole image, first.
            ASSERT_FALSE(asked.empty()) << "frame " << i;
            EXPECT_EQ(asked.front(), cv::Rect(0, 0, 640, 480)) << "frame " << i;
        }
        if (!on_demand.fused[i] && !on_demand.detected[i]) {
            EXPECT_TRUE(asked.empty()) << "frame " << i << " was only tracked, but its colour was decoded";
            ++tracked_only;
        }
        if (on_demand.fused[i]) {
            // Fusion reads the head's region: a fraction of the image.
            ASSERT_FALSE(asked.empty()) << "frame " << i;
            EXPECT_LT(asked.back().area(), 640 * 480 / 3) << "frame " << i << ": " << asked.back();
        }
    }
    EXPECT_GE(tracked_only, 8) << "frames 12-29 fuse every other frame";
}

TEST(ColourOnDemand, ColourThatCannotBeHadIsColourNotGiven) {
    const Scan none = scan(Colour::kNone);
    const Scan damaged = scan(Colour::kDamaged);
    expectSameScan(none, damaged);
}

// A source that hands back colour of another shape gives none (integration and detection read it per depth pixel).
TEST(ColourOnDemand, ColourOfAnotherShapeIsColourNotGiven) {
    class Wrong final : public ColourSource {
     public:
        const cv::Mat& colour(const cv::Rect&) override { return mat; }
        cv::Mat mat;
    } source;
    RgbdFrame frame;
    frame.depth_m = cv::Mat(48, 64, CV_32FC1, cv::Scalar(0.7f));
    frame.colour_on_demand = &source;
    source.mat = cv::Mat(24, 32, CV_8UC3, cv::Scalar(1, 2, 3));
    EXPECT_TRUE(frameColour(frame, {0, 0, 64, 48}).empty()) << "smaller than the depth";
    source.mat = cv::Mat(48, 64, CV_8UC1, cv::Scalar(1));
    EXPECT_TRUE(frameColour(frame, {0, 0, 64, 48}).empty()) << "one channel";
    source.mat = cv::Mat(48, 64, CV_8UC3, cv::Scalar(1, 2, 3));
    EXPECT_EQ(frameColour(frame, {0, 0, 64, 48}).data, source.mat.data) << "the right shape is handed on as it is";
}

}  // namespace
}  // namespace facescan::recon
