// libFuzzer targets: a whole recording reader over a recording held in memory (a memfd, opened by its /proc path as
// any file). Whatever it opens must give frames of its stated size or a Status, never a crash. Built once per
// reader (tests/fuzz/CMakeLists.txt), FUZZ_RECORDING_OPEN naming it:
//   - fuzz_mkv, openMkvSource: libavformat's Matroska demuxer, the track and attachment checks, the calibration,
//     the depth and colour frames;
//   - fuzz_bag, openBagSource: ROS's rosbag storage library reading the bag's records and index, the RealSense
//     topics, camera_info, Depth Units and extrinsics, then the images.
#include <sys/mman.h>
#include <unistd.h>

#include <string>

#include "capture/recording_sources.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace facescan::capture;
    static const int fd = memfd_create("fuzz_recording", 0);
    if (fd < 0) __builtin_trap();
    if (ftruncate(fd, 0) != 0 || pwrite(fd, data, size, 0) != static_cast<ssize_t>(size)) __builtin_trap();
    const std::string path = "/proc/self/fd/" + std::to_string(fd);
    SourceOptions options;
    options.max_frames = 4;
    auto source = FUZZ_RECORDING_OPEN(path, options);
    if (!source.isOk()) {
        if (source.status().message().empty()) __builtin_trap();
        return 0;
    }
    const SourceInfo& info = (*source)->info();
    CapturedFrame frame;
    for (int i = 0; i < 5; ++i) {
        auto got = (*source)->next(frame);
        if (!got.isOk() || !*got) break;
        if (frame.depth_raw.cols != info.intrinsics.width_px || frame.depth_raw.rows != info.intrinsics.height_px ||
            frame.depth_raw.type() != CV_16UC1)
            __builtin_trap();
        if (!frame.colour_bgr.empty() && frame.colour_bgr.cols != info.colour_intrinsics.width_px) __builtin_trap();
    }
    return 0;
}
