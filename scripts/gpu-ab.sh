#!/usr/bin/env bash
# gpu-ab.sh OLD.tar.gz COURSE_DIR [ROUNDS] - the CUDA backend of an older
# commit against this checkout's, on one GPU, in one run: both trees built
# side by side, then `harness ab --config` (docs/harness-verdicts.md, "A/B") runs
# every case with both builds, interleaved with the first of each pair
# alternating, ROUNDS (default 5) times each, and judges the new build
# against the old one per case, with both images compared. Cases: the
# report's seven scenes at their own size (configs/cuda-course.conf), the
# dragon at 3840x2160, and the dragon by brute force. Metric: render_ms (the
# median of raytrace's timed launches); METRIC=kernel_min_ms for the fastest
# launch.
#   OLD.tar.gz  `git archive OLD | gzip` of the older commit
#   COURSE_DIR  the course scenes (Group/name.txt)
# Writes ab.txt under $OUT (or /tmp/gpu-ab).
set -euo pipefail
OLD_TGZ=$1; COURSE=$(cd "$2" && pwd); ROUNDS=${3:-5}
SRC=$(cd "$(dirname "$0")/.." && pwd)
OUTDIR=${OUT:-/tmp/gpu-ab}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
mkdir -p "$OUTDIR" "$WORK/old"
tar -xzf "$OLD_TGZ" -C "$WORK/old"
build() { # SRCDIR BUILDDIR TARGET...
    local src=$1 dir=$2
    shift 2
    meson setup "$dir" "$src" -Dgpu_arch=9.0 -Dcourse_dir=none > "$dir.log" 2>&1 &&
        ninja -C "$dir" "$@" >> "$dir.log" 2>&1 || { tail -20 "$dir.log"; return 1; }
}
build "$WORK/old" "$WORK/b-old" renderer/raytrace & p1=$!
build "$SRC" "$WORK/b-new" renderer/raytrace harness/harness & p2=$!
wait $p1 && wait $p2
ab=("$WORK/b-new/harness/harness" ab --config "$SRC/configs/cuda-course.conf" "$WORK/b-old/renderer/raytrace"
    "$WORK/b-new/renderer/raytrace" --rounds "$ROUNDS" --metric "${METRIC:-render_ms}" --set "scene_dir=$COURSE")
set +e
{
    rc=0
    "${ab[@]}" || rc=1
    "${ab[@]}" --set scenes=dragon --set resolution=3840x2160 || rc=1
    "${ab[@]}" --set scenes=dragon --set accel=none || rc=1
    exit $rc
} | tee "$OUTDIR/ab.txt"
exit "${PIPESTATUS[0]}"
