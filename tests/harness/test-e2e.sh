#!/bin/sh
# End-to-end: runs configs/quick.conf for real with the built raytrace, then
# checks the CSV rows, `harness table`, `harness compare` against itself and
# that gnuplot made non-empty PNG (and SVG) files. A missing gnuplot fails
# it (scripts/install-deps.sh installs gnuplot-nox).
# usage: test-e2e.sh HARNESS RAYTRACE SOURCE_ROOT
set -u
. "$(dirname "$0")/common.sh" # need_pgrep, pids_matching
need_pgrep
# meson passes build-relative paths; make them absolute before the cd
abs() { (cd "$(dirname "$1")" && echo "$(pwd)/$(basename "$1")") || fail "no such file $1"; }
H=$(abs "$1") RT=$(abs "$2") SRC=$3
cd "$SRC" || fail "no source root $SRC"
[ -f scenes/demo.txt ] || fail "scenes/demo.txt missing (the project's demo scene)"
T=$(mktemp -d /tmp/hx-e2e-XXXXXX)
trap 'rm -rf "$T"' EXIT
# a build without OpenMP runs the serial part of the study only
CONF=configs/quick.conf
if "$RT" -V 2>/dev/null | grep -q 'openmp(not built)'; then
  sed 's/^backend:.*/backend: serial/' configs/quick.conf > "$T/quick.conf"
  CONF=$T/quick.conf
fi
"$H" run "$CONF" --raytrace "$RT" --dry-run > "$T/dry" || fail "dry-run failed"
want=$(grep -c '^\[[0-9]*\] scene=' "$T/dry")
[ "$want" -gt 0 ] || fail "dry-run lists no runs"
"$H" run "$CONF" --raytrace "$RT" -o "$T/quick.csv" 2> "$T/log" || { cat "$T/log"; fail "run failed"; }
cat "$T/log"
rows=$(($(wc -l < "$T/quick.csv") - 1))
[ "$rows" -eq "$want" ] || fail "CSV has $rows rows, dry-run planned $want"
head -1 "$T/quick.csv" | grep -q '^study,run_id,repeat,utc,' || fail "CSV header"
bad=$(grep -c -E ',(error|crash|timeout|wrong-image|refused),' "$T/quick.csv")
[ "$bad" -eq 0 ] || { grep -E ',(error|crash|timeout|wrong-image|refused),' "$T/quick.csv" | head -3; fail "$bad failed rows"; }
[ "$(grep -c -E ',ok,,0,' "$T/quick.csv")" -eq "$rows" ] || fail "not every row ok with exit 0"
grep -q -E ',[0-9a-f]{16},' "$T/quick.csv" || fail "no image hash in the rows"
grep -q 'harness overhead' "$T/log" || fail "no overhead line"
grep -q ',gcc [0-9.]* -O[0-3s] -ffp-contract=off -fno-math-errno' "$T/quick.csv" ||
    grep -q ',clang [0-9.]* -O' "$T/quick.csv" || fail "no build_flags column from raytrace -V"
"$H" table "$T/quick.csv" > "$T/table.md" || fail "table failed"
cat "$T/table.md"
grep -q '### Per configuration' "$T/table.md" || fail "no per-configuration table"
grep -q '### Scenes x configurations' "$T/table.md" || fail "no cross table"
grep -q '| demo | serial' "$T/table.md" || fail "no demo rows in the table"
grep -q ' 3/3 ' "$T/table.md" || fail "expected 3 ok samples per configuration"
"$H" compare "$T/quick.csv" "$T/quick.csv" > "$T/cmp" || { cat "$T/cmp"; fail "compare with itself failed"; }
# the guard of a render that would run for hours (docs/scene-format.md, "Deep
# recursion"): inside 16 nested glass shells that reflect and transmit, every
# ray doubles at every bounce (2^32 rays a pixel); the study's timeout ends it
# as TLE
mkdir "$T/deep"
{ printf 'film_resolution: 2 2\nmax_depth: 32\nmaterial: 0 0 0 0 0 0 .5 .5 .5 10 .5 .5 .5 1.5\n'
  for r in $(seq 1 16); do echo "sphere: 0 0 0 $r"; done; } > "$T/deep/deep.txt"
printf 'study: deep\nscene_dir: %s\nscenes: deep\nrepeats: 2\ntimeout: 2\npin: none\n' "$T/deep" > "$T/deep.conf"
start=$(date +%s)
"$H" run "$T/deep.conf" --raytrace "$RT" -o "$T/deep.csv" -q 2> "$T/deep.log"
took=$(( $(date +%s) - start ))
[ "$(grep -c ',timeout,' "$T/deep.csv")" -eq 2 ] || { cat "$T/deep.log" "$T/deep.csv"; fail "the deep render was not ended as TLE"; }
[ $took -le 10 ] || fail "the deep study took $took s with a 2 s timeout"
# the same under mpirun: when the harness kills the run, no rank may
# outlive it (they would overlap the next run)
if command -v mpirun > /dev/null && ! "$RT" -V | grep -q 'mpi(not built)'; then
    printf 'study: deepmpi\nscene_dir: %s\nscenes: deep\nbackend: mpi\nranks: 2\nrepeats: 1\ntimeout: 3\npin: none\noversubscribe: allow\n' \
        "$T/deep" > "$T/deepmpi.conf"
    "$H" run "$T/deepmpi.conf" --raytrace "$RT" -o "$T/deepmpi.csv" -q 2> "$T/deepmpi.log"
    grep -q ',timeout,' "$T/deepmpi.csv" || { cat "$T/deepmpi.log" "$T/deepmpi.csv"; fail "the MPI deep render was not ended as TLE"; }
    pids_matching "$T/deep/deep.txt"
    left=$PIDS
    [ -z "$left" ] || { ps -fp $left; fail "MPI ranks outlived the harness's kill"; }
fi
# the scene cache across a study's repeats: the first run builds, the
# others load (the record's cache= in the extra column), with one image
if "$RT" -q --cache "$T/probe" -r 8x6 -o "$T/p.ppm" scenes/demo.txt > /dev/null 2>&1; then
    printf 'study: cached\nscene_dir: %s/scenes\nscenes: glass\nresolution: 64x48\nrepeats: 3\nwarmup: 0\npin: none\nscene_cache: %s/sc\n' \
        "$SRC" "$T" > "$T/cached.conf"
    "$H" run "$T/cached.conf" --raytrace "$RT" -o "$T/cached.csv" -q 2> "$T/cached.log" || { cat "$T/cached.log"; fail "cached study failed"; }
    [ "$(grep -c 'cache=built' "$T/cached.csv")" -eq 1 ] && [ "$(grep -c 'cache=loaded' "$T/cached.csv")" -eq 2 ] ||
        { cat "$T/cached.csv"; fail "the study did not build once and load twice"; }
    [ "$(ls "$T/sc"/*.rbc | wc -l)" -eq 1 ] || fail "one cache entry expected in $T/sc"
    printf 'study: nocache\nscene_dir: %s/scenes\nscenes: glass\nresolution: 64x48\nrepeats: 2\nwarmup: 0\npin: none\nscene_cache: off\n' \
        "$SRC" > "$T/nocache.conf"
    "$H" run "$T/nocache.conf" --raytrace "$RT" -o "$T/nocache.csv" -q 2> /dev/null || fail "scene_cache: off failed"
    [ "$(grep -c 'cache=off' "$T/nocache.csv")" -eq 2 ] || fail "scene_cache: off still passed --cache"
fi
command -v gnuplot > /dev/null || fail "gnuplot missing (scripts/install-deps.sh installs gnuplot-nox)"
"$H" plot "$T/quick.csv" -o "$T/quick" || fail "plot failed"
for k in speedup efficiency scenes; do
  for ext in png svg gp dat; do
    [ -s "$T/quick-$k.$ext" ] || fail "quick-$k.$ext missing or empty"
  done
done
# error bars from the spread, and a y range from the data, not a fixed box
grep -q 'yerrorlines' "$T/quick-speedup.gp" || fail "no error bars in the speedup plot"
grep -q 'set yrange \[0.4:' "$T/quick-speedup.gp" && fail "the speedup plot has the old fixed range"
echo "e2e test passed"
