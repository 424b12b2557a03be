#!/bin/sh
# A stand-in for raytrace that the runner tests drive into every outcome,
# chosen by the scene file's base name: ok*, crash, hang, fail, wrong, silent,
# slow (0.3 s), gate (waits, at most 60 s, until the file $FAKE_GATE exists),
# escape (leaves a process in a session of its own, its pid in
# $FAKE_ESCAPE_PID, then hangs).
backend=serial accel=bvh threads=1
while [ $# -gt 1 ]; do
  case "$1" in
    --backend) backend=$2; shift 2 ;;
    --accel) accel=$2; shift 2 ;;
    --threads) threads=$2; shift 2 ;;
    -o|--resolution|--max-depth|--tile|--schedule|--mpi-schedule|--block) shift 2 ;;
    *) shift ;;
  esac
done
scene=$(basename "$1" .txt)
# the CPU this process runs on (field 39 of /proc/self/stat), as raytrace's cores=
cpu=$(cut -d' ' -f39 /proc/self/stat)
hash=00000000000000aa
case "$scene" in
  crash) kill -SEGV $$ ;;
  hang) sleep "${FAKE_HANG_S:-31}" & wait; exit 0 ;;   # the grandchild must die with the group
  slow) sleep 0.3 ;;
  gate) i=0; while [ ! -e "${FAKE_GATE:-/nonexistent}" ] && [ $i -lt 600 ]; do sleep 0.1; i=$((i + 1)); done ;;
  escape) setsid sleep 32 < /dev/null > /dev/null 2>&1 & echo $! > "$FAKE_ESCAPE_PID"; sleep "${FAKE_HANG_S:-31}" & wait; exit 0 ;;
  fail) echo "raytrace: $1:3: bad thing" >&2; exit 1 ;;
  silent) exit 0 ;;
  wrong) [ "$accel" = none ] && hash=00000000000000bb ;;
esac
echo "progress noise"
echo "record: scene=$scene width=4 height=3 backend=$backend accel=$accel threads=$threads ranks=1 parse_ms=0.1 build_ms=0.1 render_ms=1.250 write_ms=0.1 total_ms=1.5 rays=100 primary_rays=12 shadow_rays=40 secondary_rays=48 node_visits=500 prim_tests=300 mrays_per_s=0.1 image_fnv1a=$hash tile=32x32 cores=$cpu newkey=1"
