// Inputs of facescan-bench recon (docs/design.md s6): synthetic[:OPTIONS] rendered by the project's synthetic Kinect
// (with its ground truth), TUM RGB-D folders and 7-Scenes folders (with their reference poses), depth cameras' own
// recordings (mkv:, bag:). Everything is loaded before the timed loop.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "recon/camera.hpp"
#include "recon/frame.hpp"
#include "recon/sensor.hpp"
#include "recon/status.hpp"
#include "synth/kinect_simulator.hpp"
#include "synth/sequence_options.hpp"

namespace facescan::bench {

struct Sequence {
    recon::Intrinsics k;
    std::vector<recon::RgbdFrame> frames;
    std::vector<cv::Mat> masks;                            // per frame, empty = whole frame
    std::vector<std::optional<recon::Pose>> T_ref_camera;  // reference poses (first camera = identity), when known
    std::string mask_source = "none";
    std::optional<synth::KinectSimulator> sim;  // synthetic input only
    synth::SyntheticSpec spec;                  // synthetic input only: what was rendered
    std::vector<int> head_pixels;               // synthetic input only: head-labelled pixels per frame (truth)
    recon::SensorModel sensor;                  // the camera (synthetic: its sensor=; otherwise a Kinect v1)
};

// SRC: synthetic[:OPTIONS] | tum:DIR | 7scenes:DIR | mkv:FILE (Azure Kinect, Femto) | bag:FILE (RealSense);
// frames > 0 limits
// (synthetic: sets) the frame count.
Status loadSequence(const std::string& input, int frames, Sequence& seq);

}  // namespace facescan::bench
