#!/usr/bin/env bash
# gpu-ab.sh OLD.tar.gz COURSE_DIR [REPEATS] - the CUDA backend of an older
# commit against this checkout's, on one GPU, in one run: both trees built
# side by side, then REPEATS (default 5) rounds, each rendering every case
# with both builds in alternating order (interleaved, so that clock and
# thermal drift fall on both alike). Cases: the report's seven scenes at
# their own size, the dragon at 3840x2160, and the dragon by brute force.
# Each render is raytrace's default timing (median of its timed launches).
# Prints one CSV row per render, then per case the median over rounds of each
# build's render_ms (the median launch) and of its kernel_min_ms (the fastest
# launch, printed to 0.1 us), their ratios new/old, and whether the images
# and counters are identical.
#   OLD.tar.gz  `git archive OLD | gzip` of the older commit
#   COURSE_DIR  the course scenes (Group/name.txt)
# Writes ab.csv and ab-summary.txt under $OUT (or /tmp/gpu-ab).
set -euo pipefail
OLD_TGZ=$1; COURSE=$(cd "$2" && pwd); REPEATS=${3:-5}
SRC=$(cd "$(dirname "$0")/.." && pwd)
OUTDIR=${OUT:-/tmp/gpu-ab}
WORK=$(mktemp -d)
mkdir -p "$OUTDIR" "$WORK/old"
tar -xzf "$OLD_TGZ" -C "$WORK/old"
build() { # SRCDIR BUILDDIR
    meson setup "$2" "$1" -Dgpu_arch=9.0 -Dharness=false -Dcourse_dir=none >"$2.log" 2>&1 &&
        ninja -C "$2" renderer/raytrace >>"$2.log" 2>&1 || { tail -20 "$2.log"; return 1; }
}
build "$WORK/old" "$WORK/b-old" & p1=$!
build "$SRC" "$WORK/b-new" & p2=$!
wait $p1 && wait $p2
cases="InterestingScenes/dragon:bvh: InterestingScenes/arm-reach:bvh: InterestingScenes/bottle:bvh:
       InterestingScenes/bottle-nolabel:bvh: TriangleExamples/test_reasonable:bvh: InterestingScenes/ShadowTest:bvh:
       SphereExamples/bear:bvh: InterestingScenes/dragon:bvh:3840x2160 InterestingScenes/dragon:none:"
csv="$OUTDIR/ab.csv"
echo "round,build,scene,accel,size,render_ms,image_fnv1a,rays,node_visits,kernel_min_ms" >"$csv"
key() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
for r in $(seq "$REPEATS"); do
    order="old new"; [ $((r % 2)) -eq 0 ] && order="new old"
    for c in $cases; do
        IFS=: read -r scene accel size <<<"$c"
        for b in $order; do
            rec=$("$WORK/b-$b/renderer/raytrace" -q --backend cuda --accel "$accel" ${size:+-r "$size"} \
                -o "$WORK/img.ppm" "$COURSE/$scene.txt")
            echo "$r,$b,$(basename "$scene"),$accel,${size:-scene},$(key "$rec" render_ms),$(key "$rec" image_fnv1a),$(key "$rec" rays),$(key "$rec" node_visits),$(key "$rec" kernel_min_ms)" | tee -a "$csv"
        done
    done
done
# per case: medians, ratio, identical images and counters
awk -F, 'NR > 1 { k = $3 "," $4 "," $5; t[k "," $2] = t[k "," $2] " " $6; m[k "," $2] = m[k "," $2] " " $10; h[k "," $2] = h[k "," $2] " " $7 "/" $8 "/" $9; keys[k] = 1 }
    function median(s,   a, n, i, j, x) { n = split(s, a, " "); for (i = 2; i <= n; i++) { x = a[i]; for (j = i - 1; j >= 1 && a[j] > x; j--) a[j + 1] = a[j]; a[j + 1] = x }
                                           return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2 }
    END { printf "%-32s %10s %10s %7s %12s %12s %7s %s\n", "case", "old ms", "new ms", "ratio", "old min ms", "new min ms", "ratio", "images+counters"
          for (k in keys) { o = median(t[k ",old"]); n = median(t[k ",new"]); mo = median(m[k ",old"]); mn = median(m[k ",new"])
                            split(h[k ",old"], ho, " "); split(h[k ",new"], hn, " "); same = "identical"
                            for (i in ho) if (ho[i] != hn[i] || ho[i] != ho[1]) same = "DIFFER"
                            printf "%-32s %10.4f %10.4f %7.3f %12.4f %12.4f %7.3f %s\n", k, o, n, n / o, mo, mn, mn / mo, same } }' "$csv" | tee "$OUTDIR/ab-summary.txt"
rm -rf "$WORK"
