// The bench's trajectory ruler: a sequence's estimated camera poses against its reference poses (ATE and RPE, as in
// the TUM RGB-D benchmark), for facescan-bench recon.
#pragma once

#include <optional>
#include <vector>

#include "recon_input.hpp"

namespace facescan::bench {

struct PoseErrors {
    int frames = 0;
    double ate_rmse_mm = 0, ate_max_mm = 0, rpe_mm = 0, rpe_deg = 0, rpe_max_mm = 0, rpe_max_deg = 0;
};

// ATE: the estimate and the reference share the first camera's frame, so no alignment is applied (an honest
// figure that includes drift). RPE: per consecutive pair of tracked frames.
PoseErrors poseErrors(const Sequence& seq, const std::vector<std::optional<recon::Pose>>& estimate);

}  // namespace facescan::bench
