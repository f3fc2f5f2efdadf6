// The text form of a synthetic sequence, shared by every program that renders one (the agent's `synthetic:`
// source, facescan-bench recon and synth): "scenario=wide,frames=200,seed=3,subject=builtin". A scenario sets the
// motion and events of one robustness case; the other keys override single parameters after it,
// whatever their order.
#pragma once

#include <string>

#include "recon/camera.hpp"
#include "recon/sensor.hpp"
#include "recon/status.hpp"
#include "synth/head_model.hpp"
#include "synth/kinect_simulator.hpp"

namespace facescan::synth {

struct SyntheticSpec {
    SequenceParams sequence;
    std::string scenario = "gentle";
    std::string subject = "auto";  // auto (the scan when found, else built-in) | builtin | scan | FILE
    // The synthetic camera (sensor=NAME): its depth stream, noise and range, and the camera description an agent
    // sends for it.
    std::string sensor = "kinect-v1";
    recon::Intrinsics intrinsics = recon::Intrinsics::kinectV1();
    recon::SensorModel sensor_model = recon::SensorModel::kinectV1();
};

// The synthetic sensors, each a noise model with its source (synth::NoiseParams), its depth stream and the
// distance its scans are made at:
//   kinect-v1   the Kinect v1 (Nguyen et al. 2012), 640x480, head at 0.7 m (nose at 0.6 m)
//   truedepth   a near-range structured-light camera (TrueDepth-like), 320x240, 0.2-0.5 m, nose at 0.3 m
//   d415        an active stereo camera (RealSense D415-like; realsense-d415 is an alias), 848x480, 0.3-3 m,
//               nose at 0.45 m
//   azure-kinect a time-of-flight camera (Azure Kinect NFOV unbinned), 640x576, 0.5-3.86 m, nose at 0.65 m
// Sets spec.intrinsics, spec.sensor_model and, in spec.sequence, the noise model, distance and wall.
Status applySyntheticSensor(const std::string& name, SyntheticSpec& spec);

// The named scenarios, one per robustness case the tracker must survive:
//   gentle    the default: yaw +-35 deg, pitch +-12 deg, 300 frames (up to 0.7 deg a frame)
//   wide      yaw +-60, pitch +-20, up to 2.8 deg a frame, torso, 300 frames
//   chin      nods the chin 30 deg down onto the chest and back, twice (slight yaw), 180 frames
//   gap       walks out of view for 1 s from frame 90 and back turned (head yaw +-20, pitch +-8, turn -20: the
//             head returns 31 deg from its last pose before the gap), 240 frames
//   occluder  the gentle sequence with a hand-sized occluder across the face for 1 s from frame 120
//   orbit     the camera moves around a still head: yaw +-40 deg, pitch +-10 deg about the head, 300 frames
// Unknown names give the list.
Status applyScenario(const std::string& name, SequenceParams& p);

// Parses "key=value,..." (see syntheticOptionsHelp()); validates the result.
StatusOr<SyntheticSpec> parseSyntheticOptions(const std::string& text);

// Loads the subject named by SyntheticSpec::subject ("lps" is an alias of "scan").
StatusOr<HeadModel> loadSubject(const std::string& subject);

// One paragraph for --help texts: the keys, their units and the scenarios.
const char* syntheticOptionsHelp();

}  // namespace facescan::synth
