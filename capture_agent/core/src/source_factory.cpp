// openSource: the command-line spec of a frame source to an opened source (frame_source.hpp).
#include "capture/frame_source.hpp"
#include "capture/recording_sources.hpp"

namespace facescan::capture {

StatusOr<std::unique_ptr<FrameSource>> openSource(const std::string& spec, const SourceOptions& options) {
    const auto colon = spec.find(':');
    const std::string kind = spec.substr(0, colon);
    const std::string rest = colon == std::string::npos ? std::string() : spec.substr(colon + 1);
    if (kind == "openni2") return openOpenNi2Device(rest, options);
    if (kind == "oni") {
        if (rest.empty()) return invalidArgument("oni: needs a file, e.g. --source oni:scan.oni");
        return openOniFile(rest, options);
    }
    if (kind == "tum") {
        if (rest.empty()) return invalidArgument("tum: needs a folder, e.g. --source tum:rgbd_dataset_freiburg1_xyz");
        return openTumSource(rest, options);
    }
    if (kind == "mkv") {
        if (rest.empty()) return invalidArgument("mkv: needs a file, e.g. --source mkv:scan.mkv (Azure Kinect, Femto)");
        return openMkvSource(rest, options);
    }
    if (kind == "bag") {
        if (rest.empty()) return invalidArgument("bag: needs a file, e.g. --source bag:scan.bag (RealSense)");
        return openBagSource(rest, options);
    }
    if (kind == "synthetic") return openSyntheticSource(rest, options);
    return invalidArgument("unknown source '" + spec +
                           "': use openni2[:URI], oni:FILE, tum:DIR, mkv:FILE, bag:FILE or synthetic[:key=value,...]");
}

}  // namespace facescan::capture
