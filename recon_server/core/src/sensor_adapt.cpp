#include "recon/sensor_adapt.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace facescan::recon {
namespace {

int scaledCount(int count, float ratio) { return std::max(1, static_cast<int>(std::lround(count * ratio))); }

// Where scans are made: near the near end of the advised range, where the noise is lowest (a quarter of the way
// in: 0.625 m for the Kinect's 0.5-1.0 m, where its scans sit, nose at 0.6 m).
float workingDistanceM(const AdviceParams& advice) { return advice.near_m + 0.25f * (advice.far_m - advice.near_m); }

}  // namespace

void adaptToSensor(const SensorModel& sensor, const Intrinsics& depth, ReconParams& recon, FacePipelineParams& face,
                   AdviceParams& advice) {
    const SensorModel kinect = SensorModel::kinectV1();
    const Intrinsics kinect_k = Intrinsics::kinectV1();
    // Ratios to the Kinect v1 the defaults were tuned on (exactly 1 for a Kinect v1 itself).
    const float near_ratio = sensor.min_depth_m / kinect.min_depth_m;
    const float far_ratio = sensor.max_depth_m / kinect.max_depth_m;
    const float focal_ratio = 0.5f * (depth.fx_px + depth.fy_px) / kinect_k.fx_px;  // pixels per radian
    const float area_ratio = focal_ratio * focal_ratio;  // a head's pixels at a given distance grow with f^2

    // Depth windows: nothing nearer than the sensor measures, nothing beyond its range.
    face.detector.min_depth_m = sensor.min_depth_m;
    face.detector.max_depth_m = sensor.max_depth_m;
    face.segmenter.min_depth_m = sensor.min_depth_m;
    face.segmenter.max_depth_m = sensor.max_depth_m;
    // The filter keeps a margin inside the segmenter's window (0.3-3 m on the Kinect's 0.4-4 m).
    recon.filter.min_depth_m *= near_ratio;
    recon.filter.max_depth_m *= far_ratio;
    if (!(recon.filter.max_depth_m > recon.filter.min_depth_m)) recon.filter.max_depth_m = sensor.max_depth_m;

    // Distance advice: the Kinect's 0.5-1.0 m is 1.25-2.5 times its near limit. Nearer than that the face's
    // edges fall under the near limit as it turns; farther, the noise (growing with z^2 for structured light
    // and stereo) coarsens the model. Never beyond what the sensor measures.
    advice.near_m *= near_ratio;
    advice.far_m = std::min(advice.far_m * near_ratio, sensor.max_depth_m);
    if (!(advice.far_m > advice.near_m)) advice.far_m = sensor.max_depth_m;

    // Thresholds in pixels: a head of the same size at the same distance covers area_ratio times the pixels.
    recon.min_head_pixels = scaledCount(recon.min_head_pixels, area_ratio);
    face.model.min_pixels = scaledCount(face.model.min_pixels, area_ratio);
    recon.roi_margin_px = scaledCount(recon.roi_margin_px, focal_ratio);
    // The depth-only finder's blobs are found at about 160 pixels across (level 2 of VGA) whatever the resolution.
    const int finder_level = pyramidLevelOfWidth(depth.width_px, kinect_k.width_px >> face.finder.level, 3);
    const float level_ratio = static_cast<float>(1 << face.finder.level) / static_cast<float>(1 << finder_level);
    face.finder.min_blob_px = scaledCount(face.finder.min_blob_px, area_ratio * level_ratio * level_ratio);
    face.finder.level = finder_level;

    // The model's resolution follows the depth noise at the working distance: the Kinect's 1.51 mm voxels and
    // mu = 5 mm (Meyer's) suit its 1.3 mm there. A camera measuring with less noise gets finer voxels (down to 2/3
    // of the Kinect's, ~1 mm, where the block pool and the per-frame cost stay within a face scan's budget) and a
    // truncation band narrowed in proportion to the noise, which must still span 2 voxels for the ray cast to
    // find the surface. A wide band on a curved surface biases it outwards (measured with facescan-bench recon on
    // the near-range synthetic sensor: +0.21 mm at mu = 3 mm, +0.13 at 2.5, 0.00 at 2.0, all with 1 mm voxels).
    // Unknown noise, or no less than the Kinect's: Meyer's volume as it is.
    if (sensor.noise.known()) {
        const float noise_ratio =
            sensor.noise.sigmaM(workingDistanceM(advice)) / kinect.noise.sigmaM(workingDistanceM(AdviceParams{}));
        if (noise_ratio > 0.0f && noise_ratio < 1.0f) {
            const float finer = std::max(noise_ratio, 2.0f / 3.0f);
            const int resolution =
                kBlockSide * static_cast<int>(std::lround(static_cast<float>(recon.tsdf.resolution_vox) / finer /
                                                          static_cast<float>(kBlockSide)));
            const float area = static_cast<float>(resolution) / static_cast<float>(recon.tsdf.resolution_vox);
            recon.tsdf.max_blocks =
                static_cast<int>(std::lround(static_cast<float>(recon.tsdf.max_blocks) * area * area));
            recon.tsdf.resolution_vox = resolution;
            recon.tsdf.trunc_dist_m = std::max(recon.tsdf.trunc_dist_m * noise_ratio, 2.0f * recon.tsdf.voxelSizeM());
        }
    }
}

std::string describeSensor(const SensorModel& sensor, const AdviceParams& advice, const TsdfParams& tsdf) {
    char text[256];
    std::snprintf(text, sizeof(text), "%s (%s), %.2f-%.2f m; advised %.2f-%.2f m", sensor.name.c_str(),
                  sensorFamilyName(sensor.family), sensor.min_depth_m, sensor.max_depth_m, advice.near_m, advice.far_m);
    std::string out = text;
    if (sensor.noise.known()) {
        const float z = workingDistanceM(advice);
        std::snprintf(text, sizeof(text), "; depth noise %.2f mm at %.2f m", 1000.0f * sensor.noise.sigmaM(z), z);
        out += text;
    } else {
        out += "; depth noise not known";
    }
    std::snprintf(text, sizeof(text), "; model %.2f mm voxels, truncation %.1f mm%s", 1000.0f * tsdf.voxelSizeM(),
                  1000.0f * tsdf.trunc_dist_m,
                  sensor.noise.known() && tsdf.trunc_dist_m < TsdfParams{}.trunc_dist_m
                      ? " (finer than a Kinect's: less depth noise)"
                      : "");
    out += text;
    return out;
}

}  // namespace facescan::recon
