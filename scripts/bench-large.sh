#!/usr/bin/env bash
# bench-large.sh [OPTIONS] - loading and rendering large scenes, from 10K to
# 4M triangles (docs/performance.md, "Large scenes"), in one run:
#   - per scene: parse_ms, build_ms (1 thread and all), sah_cost, render_ms,
#     the scene cache's load and the whole command from a warm cache;
#   - Intel Embree 3's high-quality build on the same threads (when
#     build/benchmarks/embree-build exists);
# every measurement repeated, the builds interleaved (1 thread, all threads,
# Embree, and again), medians reported.
#   --build DIR      the build folder (default build)
#   --threads N      "all" threads (default: nproc)
#   --sizes LIST     triangle counts (default "10000 30000 100000 300000 1000000 4000000")
#   --repeats R      (default 3)
#   --backend B      the render's backend (default openmp; cuda on the GPU machine)
#   --resolution WxH the render's size (default 640x360; one run, no warm-up:
#                    the command's total_ms is the time to the first image)
#   --out PREFIX     writes PREFIX.csv and PREFIX.md (default /tmp/bench-large)
# Scenes are scenegen's sphere fields (--seed 1), written to a temporary
# folder and removed after. Plot: scripts/bench-large-plot.sh PREFIX.csv.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=build THREADS=$(nproc) SIZES="10000 30000 100000 300000 1000000 4000000" REPEATS=3
BACKEND=openmp RES=640x360 OUTP=/tmp/bench-large
while [ $# -gt 0 ]; do
    case $1 in
        --build) BUILD=$2 ;; --threads) THREADS=$2 ;; --sizes) SIZES=$2 ;; --repeats) REPEATS=$2 ;;
        --backend) BACKEND=$2 ;; --resolution) RES=$2 ;; --out) OUTP=$2 ;;
        *) echo "bench-large: unknown option $1 (see the header)" >&2; exit 2 ;;
    esac
    shift 2
done
RT=$BUILD/renderer/raytrace GEN=$BUILD/renderer/scenegen EMB=$BUILD/benchmarks/embree-build
[ -x "$RT" ] && [ -x "$GEN" ] || { echo "bench-large: build $BUILD first (ninja -C $BUILD)" >&2; exit 1; }
[ -x "$EMB" ] || EMB=
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
key() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
csv=$OUTP.csv
echo "triangles,what,threads,repeat,parse_ms,build_ms,render_ms,total_ms,sah_cost,cache" > "$csv"
row() { # TRIS WHAT THREADS REPEAT RECORD
    echo "$1,$2,$3,$4,$(key "$5" parse_ms),$(key "$5" build_ms),$(key "$5" render_ms),$(key "$5" total_ms),$(key "$5" sah_cost),$(key "$5" cache)" >> "$csv"
}
render() { "$RT" -q --backend "$BACKEND" -r "$RES" --runs 1 --warmup 0 -o "$TMP/img.ppm" "$@"; }
echo "== $(date -u +%FT%TZ) bench-large: $(uname -n), $(nproc) CPUs, threads $THREADS, backend $BACKEND, $RES"
for n in $SIZES; do
    s=$TMP/s$n.txt
    "$GEN" --triangles "$n" --seed 1 --resolution "$RES" -o "$s" 2> "$TMP/gen"
    tris=$(sed -n 's/.*: \([0-9]*\) triangles/\1/p' "$TMP/gen")
    echo "-- $tris triangles ($(du -h "$s" | cut -f1))"
    for r in $(seq "$REPEATS"); do
        rec=$(render --build-threads 1 "$s"); row "$tris" load 1 "$r" "$rec"
        rec=$(render --build-threads "$THREADS" "$s"); row "$tris" load "$THREADS" "$r" "$rec"
        if [ -n "$EMB" ]; then
            ms=$("$EMB" --threads "$THREADS" "$s" | sed -n 's/.* ms=//p')
            echo "$tris,embree-build,$THREADS,$r,,$ms,,,," >> "$csv"
        fi
    done
    rm -rf "$TMP/cache"
    render --build-threads "$THREADS" --cache "$TMP/cache" "$s" > /dev/null
    for r in $(seq "$REPEATS"); do
        rec=$(render --build-threads "$THREADS" --cache "$TMP/cache" "$s"); row "$tris" cached "$THREADS" "$r" "$rec"
    done
    rm -f "$s"
done
# medians per (triangles, what, threads)
awk -F, 'NR > 1 { k = $1 "," $2 "," $3; for (c = 5; c <= 8; c++) v[k, c] = v[k, c] " " $c; keys[k] = 1; sah[k] = $9 }
    function med(s,   a, n, i, j, x) { n = split(s, a, " "); if (n == 0) return "";
        for (i = 2; i <= n; i++) { x = a[i] + 0; for (j = i - 1; j >= 1 && a[j] + 0 > x; j--) a[j + 1] = a[j]; a[j + 1] = x }
        return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2 }
    END { print "| triangles | what | threads | parse ms | build ms | render ms | total ms | SAH cost |"
          print "|---|---|---|---|---|---|---|---|"
          for (k in keys) { split(k, f, ","); printf "| %s | %s | %s | %s | %s | %s | %s | %s |\n", f[1], f[2], f[3],
              med(v[k, 5]), med(v[k, 6]), med(v[k, 7]), med(v[k, 8]), sah[k] } }' "$csv" | sort -t'|' -k2,2n -k3,3 -k4,4n > "$OUTP.md"
cat "$OUTP.md"
echo "== wrote $csv and $OUTP.md"
