#include "synth/sequence_options.hpp"

#include <cstdlib>
#include <sstream>
#include <utility>
#include <vector>

namespace facescan::synth {
namespace {

// Splits "a=1,b=2" into pairs; an item without '=' is an error.
Status splitItems(const std::string& text, std::vector<std::pair<std::string, std::string>>& items) {
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
        if (item.empty()) continue;
        const auto eq = item.find('=');
        if (eq == std::string::npos) return invalidArgument("synthetic option '" + item + "' is not key=value");
        items.emplace_back(item.substr(0, eq), item.substr(eq + 1));
    }
    return Status::ok();
}

}  // namespace

Status applyScenario(const std::string& name, SequenceParams& p) {
    p = SequenceParams{};
    if (name == "gentle") return Status::ok();
    if (name == "wide") {
        // Peak speeds 60 * 2 pi / 150 = 2.51 deg/frame (yaw) and 20 * 2 pi / 110 = 1.14 (pitch): at most
        // 2.76 deg a frame together.
        p.yaw_amplitude_deg = 60.0f;
        p.pitch_amplitude_deg = 20.0f;
        p.yaw_period_frames = 150.0f;
        p.pitch_period_frames = 110.0f;
        return Status::ok();
    }
    if (name == "chin") {
        p.frames = 180;
        p.nod = true;
        p.pitch_amplitude_deg = 30.0f;
        p.pitch_period_frames = 90.0f;
        p.yaw_amplitude_deg = 10.0f;
        return Status::ok();
    }
    if (name == "gap") {
        p.frames = 240;
        p.yaw_amplitude_deg = 20.0f;
        p.pitch_amplitude_deg = 8.0f;
        // Leaves at yaw +19 deg and comes back at 8 - 20 = -12 deg: 31 deg from the last pose before the gap.
        p.gap_start_frame = 90;
        p.gap_turn_deg = -20.0f;
        return Status::ok();
    }
    if (name == "occluder") {
        p.occluder_start_frame = 120;
        return Status::ok();
    }
    if (name == "orbit") {
        // The camera moves around a still head: +-40 deg about the vertical and +-10 about the horizontal, at
        // most 40 * 2 pi / 300 = 0.84 deg a frame (and 0.42 pitch), the background sliding through the image.
        p.orbit = true;
        p.yaw_amplitude_deg = 40.0f;
        p.pitch_amplitude_deg = 10.0f;
        p.sway_amplitude_m = 0.0f;
        return Status::ok();
    }
    return invalidArgument("unknown synthetic scenario '" + name +
                           "' (known: gentle, wide, chin, gap, occluder, orbit)");
}

Status applySyntheticSensor(const std::string& name, SyntheticSpec& spec) {
    SequenceParams& p = spec.sequence;
    if (name == "kinect-v1") {
        p.noise_model = NoiseParams{};
        spec.intrinsics = recon::Intrinsics::kinectV1();
        spec.sensor_model = recon::SensorModel::kinectV1();
        spec.sensor = name;
        return Status::ok();
    }
    // The other sensors: the agent's preset of that camera (its range and depth stream), the synthetic noise
    // model, and where its scans are made.
    const char* preset_name = nullptr;
    if (name == "truedepth") {
        preset_name = "truedepth";
    } else if (name == "d415" || name == "realsense-d415") {
        preset_name = "realsense-d415";
    } else if (name == "azure-kinect") {
        preset_name = "azure-kinect";
    } else {
        return invalidArgument("unknown synthetic sensor '" + name +
                               "' (known: kinect-v1, truedepth, d415, azure-kinect)");
    }
    ASSIGN_OR_RETURN(const recon::SensorPreset preset, recon::findSensorPreset(preset_name));
    spec.intrinsics = preset.nominal_depth;
    spec.sensor_model = preset.sensor;
    if (name == "truedepth") {
        p.noise_model = NoiseParams::nearRangeStructuredLight();
        p.distance_m = 0.4f;  // the nose tip (0.1 m in front of the head frame's origin) at 0.3 m
        p.wall_distance_m = 1.0f;
    } else if (preset_name == std::string("realsense-d415")) {
        p.noise_model = NoiseParams::activeStereo(spec.intrinsics.fx_px);
        p.distance_m = 0.55f;  // nose at 0.45 m, a quarter into the advised 0.375-0.75 m
    } else {
        p.noise_model = NoiseParams::timeOfFlight();
        p.distance_m = 0.75f;  // nose at 0.65 m, just inside the advised 0.625-1.25 m
    }
    // The model's sigma(z), as the camera description carries it: a + b (z - z0)^2 expanded.
    const NoiseParams& n = p.noise_model;
    spec.sensor_model.noise = {n.axial_a_m + n.axial_b_per_m * n.axial_z0_m * n.axial_z0_m,
                               -2.0f * n.axial_b_per_m * n.axial_z0_m, n.axial_b_per_m};
    spec.sensor = name;
    return Status::ok();
}

StatusOr<SyntheticSpec> parseSyntheticOptions(const std::string& text) {
    std::vector<std::pair<std::string, std::string>> items;
    RETURN_IF_ERROR(splitItems(text, items));
    SyntheticSpec spec;
    for (const auto& [key, value] : items) {
        if (key == "scenario") spec.scenario = value;
    }
    RETURN_IF_ERROR(applyScenario(spec.scenario, spec.sequence));
    // The sensor after the scenario (which resets the sequence) and before the keys that override it.
    for (const auto& [key, value] : items) {
        if (key == "sensor") RETURN_IF_ERROR(applySyntheticSensor(value, spec));
    }
    SequenceParams& p = spec.sequence;
    for (const auto& [key, value] : items) {
        if (key == "scenario" || key == "sensor") continue;
        if (key == "subject" || key == "head") {
            spec.subject = value;
            continue;
        }
        char* end = nullptr;
        const double number = std::strtod(value.c_str(), &end);
        if (value.empty() || end == nullptr || *end != '\0') {
            return invalidArgument("synthetic option " + key + "=" + value + ": expected a number");
        }
        const float f = static_cast<float>(number);
        const int i = static_cast<int>(number);
        if (key == "frames") {
            p.frames = i;
        } else if (key == "distance") {
            p.distance_m = f;
        } else if (key == "yaw") {
            p.yaw_amplitude_deg = f;
        } else if (key == "pitch") {
            p.pitch_amplitude_deg = f;
        } else if (key == "period") {
            p.yaw_period_frames = f;
            p.pitch_period_frames = f / 2;
        } else if (key == "yaw_period") {
            p.yaw_period_frames = f;
        } else if (key == "pitch_period") {
            p.pitch_period_frames = f;
        } else if (key == "nod") {
            p.nod = number != 0;
        } else if (key == "seed") {
            p.seed = static_cast<uint64_t>(number);
        } else if (key == "noise") {
            p.noise = number != 0;
        } else if (key == "torso") {
            p.torso = number != 0;
        } else if (key == "shading") {
            p.shading = number != 0;
        } else if (key == "wall") {
            p.wall = number != 0;
        } else if (key == "orbit") {
            p.orbit = number != 0;
        } else if (key == "gap_start") {
            p.gap_start_frame = i;
        } else if (key == "gap_frames") {
            p.gap_frames = i;
        } else if (key == "gap_walk") {
            p.gap_walk_frames = i;
        } else if (key == "gap_turn") {
            p.gap_turn_deg = f;
        } else if (key == "gap_leave") {
            p.gap_leave = number != 0;
        } else if (key == "roll") {
            p.roll_deg = f;
        } else if (key == "roll_turn") {
            p.roll_turn_deg = f;
        } else if (key == "occluder_start") {
            p.occluder_start_frame = i;
        } else if (key == "occluder_frames") {
            p.occluder_frames = i;
        } else if (key == "occluder_front") {
            p.occluder_front_m = f;
        } else {
            return invalidArgument("unknown synthetic option '" + key + "'; " + syntheticOptionsHelp());
        }
    }
    RETURN_IF_ERROR(p.validate());
    return spec;
}

StatusOr<HeadModel> loadSubject(const std::string& subject) {
    if (subject == "auto") return defaultHead();
    if (subject == "builtin") return builtinHead();
    if (subject == "scan" || subject == "lps") {
        const auto dir = findLeePerrySmith();
        if (!dir) return notFound("subject=scan: the Lee Perry-Smith scan was not found (set FACESCAN_DATA_DIR)");
        return loadHeadScan(*dir);
    }
    return loadHeadScan(subject);
}

const char* syntheticOptionsHelp() {
    return "synthetic options (key=value, comma-separated): scenario=gentle|wide|chin|gap|occluder|orbit (sets the\n"
           "  motion and events; other keys override it), frames=N, distance=M (metres), yaw=DEG, pitch=DEG\n"
           "  (amplitudes), period=FRAMES (yaw; pitch gets half), yaw_period=FRAMES, pitch_period=FRAMES, nod=0|1\n"
           "  (pitch 0 -> amplitude -> 0), seed=N, noise=0|1, torso=0|1, shading=0|1 (0: unlit colour), wall=0|1,\n"
           "  orbit=0|1 (1: the camera moves around the still head; yaw and pitch drive the camera),\n"
           "  subject=auto|builtin|scan|FILE (head= is an alias), gap_start=FRAME (-1 none), gap_frames=N, gap_walk=N, "
           "gap_turn=DEG,\n"
           "  gap_leave=0|1 (0: turn in view instead of leaving), occluder_start=FRAME (-1 none),\n"
           "  occluder_frames=N, occluder_front=M (metres in front of the nose),\n"
           "  sensor=kinect-v1|truedepth|d415|azure-kinect (the camera: its resolution, noise and range, and its\n"
           "  distance unless distance= is given), roll=DEG (the camera turned about its optical axis: 90 or 270\n"
           "  portrait, 180 upside down; the image shows the scene turned clockwise by DEG), roll_turn=DEG (the\n"
           "  camera turns by DEG more over the sequence)";
}

}  // namespace facescan::synth
