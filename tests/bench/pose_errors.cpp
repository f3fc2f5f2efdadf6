#include "pose_errors.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace facescan::bench {
namespace {

using recon::Pose;

// Via the quaternion: acos of the trace loses everything below ~0.03 deg in float.
float rotationDeg(const Pose& t) { return Eigen::AngleAxisf(t.linear()).angle() * 57.2957795f; }

}  // namespace

PoseErrors poseErrors(const Sequence& seq, const std::vector<std::optional<Pose>>& estimate) {
    PoseErrors e;
    double ate2 = 0;
    int pairs = 0;
    for (size_t i = 0; i < estimate.size(); ++i) {
        if (!estimate[i] || !seq.T_ref_camera[i]) continue;
        const double d = (estimate[i]->translation() - seq.T_ref_camera[i]->translation()).norm() * 1000.0;
        ate2 += d * d;
        e.ate_max_mm = std::max(e.ate_max_mm, d);
        ++e.frames;
        if (i == 0 || !estimate[i - 1] || !seq.T_ref_camera[i - 1]) continue;
        const Pose rel_est = estimate[i - 1]->inverse() * *estimate[i];
        const Pose rel_ref = seq.T_ref_camera[i - 1]->inverse() * *seq.T_ref_camera[i];
        const Pose err = rel_ref.inverse() * rel_est;
        const double mm = err.translation().norm() * 1000.0, deg = rotationDeg(err);
        e.rpe_mm += mm;
        e.rpe_deg += deg;
        e.rpe_max_mm = std::max(e.rpe_max_mm, mm);
        e.rpe_max_deg = std::max(e.rpe_max_deg, deg);
        ++pairs;
    }
    if (e.frames > 0) e.ate_rmse_mm = std::sqrt(ate2 / e.frames);
    if (pairs > 0) {
        e.rpe_mm /= pairs;
        e.rpe_deg /= pairs;
    }
    return e;
}

}  // namespace facescan::bench
