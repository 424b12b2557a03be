#!/bin/sh
# gpu_timeline.sh RAYTRACE SCENE_DIR - RAYBENCH_CUDA_TIMELINE (docs/gpu.md):
# the per-warp records of a render must cover the whole launch and agree with
# its counters, for the grid schedule (one and two lanes per pixel) and the
# persistent one:
#   one row per chunk (a warp's 32 pixels, or 16 pixel pairs), every chunk of
#   the launch present once; end >= start; the steps of all chunks add up to
#   the record's node_visits + prim_tests exactly;
# and a file that cannot be written is a one-line error, exit 1, no image.
# Exit 77 without a GPU or without the course scenes.
set -u
. "$(dirname "$0")/../course.sh"
RT=$1; DIR=$(course_path "$2")
command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q '^GPU ' || { echo "SKIP: no GPU"; exit 77; }
[ -d "$DIR" ] || { echo "SKIP: no course scenes at $DIR"; exit 77; }
TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT
field() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
fail=0
SC="$DIR/InterestingScenes/dragon.txt"
# sched pairs block size chunks(expected)
for run in "grid 0 8x8 128x96 384" "grid 1 8x8 128x96 768" "grid 1 16x4 100x60 390" "persistent 0 4x8 128x96 384" \
           "grid 0 32x2 100x60 240"; do
    set -- $run
    rm -f "$TMP/t.csv"
    rec=$(RAYBENCH_CUDA_SCHED=$1 RAYBENCH_CUDA_PAIRS=$2 RAYBENCH_CUDA_RUNS=2 RAYBENCH_CUDA_TIMELINE="$TMP/t.csv" \
          "$RT" -q --backend cuda --block "$3" -r "$4" -o "$TMP/x.ppm" "$SC") || { echo "FAIL $run: render"; fail=1; continue; }
    steps=$(( $(field "$rec" node_visits) + $(field "$rec" prim_tests) ))
    res=$(awk -F, -v want="$5" -v steps="$steps" '
        NR == 1 { if ($0 != "chunk,x,y,sm,start_ns,end_ns,steps_max,steps_sum,pairs") { print "bad header: " $0; bad = 1 } next }
        { n++; if (seen[$1]++) { print "chunk " $1 " twice"; bad = 1 }
          if ($6 + 0 < $5 + 0) { print "chunk " $1 " ends before it starts"; bad = 1 }
          if ($7 + 0 > $8 + 0) { print "chunk " $1 ": slowest lane above the sum"; bad = 1 }
          s += $8 }
        END { if (n != want) { print "rows " n " != " want; bad = 1 }
              if (s != steps) { print "steps " s " != record " steps; bad = 1 }
              if (!bad) printf "ok: %d chunks, %d steps", n, s; exit bad }' "$TMP/t.csv")
    rc=$?
    echo "$run: $res"
    [ $rc -eq 0 ] || fail=1
done
# An unwritable file: one line naming it, exit 1, no image.
rm -f "$TMP/x.ppm"
msg=$(RAYBENCH_CUDA_TIMELINE="$TMP/no/such/dir/t.csv" RAYBENCH_CUDA_RUNS=1 "$RT" -q --backend cuda -r 64x48 -o "$TMP/x.ppm" "$SC" 2>&1 >/dev/null)
rc=$?
echo "unwritable timeline: exit $rc: $msg"
[ $rc -eq 1 ] && [ "$(printf '%s\n' "$msg" | wc -l)" -eq 1 ] && case $msg in *"$TMP/no/such/dir/t.csv"*) true ;; *) false ;; esac \
    && [ ! -e "$TMP/x.ppm" ] || { echo "FAIL: expected one line naming the file, exit 1, no image"; fail=1; }
exit $fail
