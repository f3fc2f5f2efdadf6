#!/usr/bin/env bash
# The per-sensor table: every synthetic sensor (kinect-v1, truedepth, d415, azure-kinect) in every motion (gentle:
# the head turns +-35 deg; wide: +-60 deg, up to 2.8 deg a frame; orbit: the camera moves around the still head),
# scanned by facescan-bench recon as facescan-server scans it (its FacePipeline finds the head; every stage adapted
# to the camera), the final model measured against the true head. Prints one Markdown row per run:
#   tracked       frames tracked of the frames with the head in view (target: at least 98 %)
#   observable    completeness (2 mm) over the part of the face the sensor measured in some frame (target 0.99)
#   mean          the model's mean error (aligned), millimetres
#   1 frame       the same ruler on a single frame's surface: the sensor's single-frame error where it scans
#   sigma         the sensor model's depth sigma at the working distance (the `camera` line)
#   ratio         mean / 1 frame (target: at most 0.6)
#   ms/frame      the loop's wall clock per frame (a shared machine's figure: noisy)
#   usage: tests/bench/sensor_table.sh [FRAMES (default 150)] [SENSORS (default "kinect-v1 truedepth d415
#          azure-kinect")] [SCENARIOS (default "gentle wide orbit")]
#   env:   BUILD_DIR (default ./build), SUBJECT (synthetic subject=, default auto: the scan when found)
set -euo pipefail
cd "$(dirname "$0")/../.."
frames=${1:-150}
sensors=${2:-kinect-v1 truedepth d415 azure-kinect}
scenarios=${3:-gentle wide orbit}
BUILD_DIR=${BUILD_DIR:-$(pwd)/build}
bench=$BUILD_DIR/tests/bench/facescan-bench
[ -x "$bench" ] || { echo "sensor_table.sh: $bench missing: cmake --build $BUILD_DIR --target facescan-bench" >&2; exit 1; }
subject=${SUBJECT:-auto}

# The number after "key": in a JSON text.
num() { grep -o "\"$1\":[-0-9.e]*" <<<"$2" | head -1 | cut -d: -f2; }
# The object after "key": (no nested objects of the same depth matter here).
obj() { grep -o "\"$1\":{[^}]*}" <<<"$2" | head -1; }

echo "| sensor | motion | tracked | observable | mean mm | 1 frame mm | sigma mm | ratio | ms/frame |"
echo "|---|---|---|---|---|---|---|---|---|"
for sensor in $sensors; do
    for scenario in $scenarios; do
        input="synthetic:sensor=$sensor,scenario=$scenario,frames=$frames,subject=$subject"
        out=$("$bench" recon --input "$input" --gt-accuracy --mask pipeline --json 2>&1) || {
            echo "| $sensor | $scenario | failed: $(tail -1 <<<"$out") |"
            continue
        }
        json=$(tail -1 <<<"$out")
        sigma=$(grep -o "depth noise [0-9.]* mm at [0-9.]* m" <<<"$out" | head -1 | awk '{print $3 " at " $6 " m"}')
        acc=$(obj accuracy "$json")
        base=$(obj baseline "$json")
        scen=$(obj scenario "$json")
        mean=$(num mean_mm "$acc")
        one=$(num mean_mm "$base")
        awk -v s="$sensor" -v m="$scenario" -v t="$(num tracked_in_view "$scen")" -v n="$(num frames_in_view "$scen")" \
            -v c="$(num completeness_observed "$acc")" -v mean="$mean" -v one="$one" -v sigma="${sigma:-unknown}" \
            -v fps="$(num fps "$json")" 'BEGIN {
                printf "| %s | %s | %d/%d (%.1f %%) | %.3f | %.3f | %.3f | %s | %.2f | %.1f |\n", s, m, t, n,
                       100 * t / n, c, mean, one, sigma, mean / one, 1000 / fps }'
    done
done
