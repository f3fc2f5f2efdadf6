// What a session's finish costs the sessions still scanning (facescan-bench texture --stall): a scanning thread
// (one session's worker: the reconstruction of a sequence, frame after frame, as fast as it goes) beside a thread
// that runs a finish, every thread of the process on one core (a server whose cores the sessions fill). Measured
// as the scanning thread's frames per second alone and while the finish runs, for a finish run as the server ran
// it before (at the worker's priority, with the parallel pool) and as it runs it now (FrameLoad::leaveToFinish).
#pragma once

#include <functional>
#include <string>

#include "recon_input.hpp"

namespace facescan::bench {

struct StallFigures {
    double alone_fps = 0;                                                        // the scanning thread on its own
    double beside_fps = 0;                                                       // while the finish runs
    double finish_wall_s = 0;                                                    // how long the finish took, wall clock
    double share() const { return alone_fps > 0 ? beside_fps / alone_fps : 0; }  // what the scan kept
};

// `finish` runs on its own thread; `as_server`: it calls FrameLoad::leaveToFinish first, as the server's finish
// does. Fails (a message) when the process cannot be held to one core.
StatusOr<StallFigures> measureFinishStall(const Sequence& seq, const std::function<void()>& finish, bool as_server);

}  // namespace facescan::bench
