#!/bin/bash
# harness plot draws what was swept (docs/harness-table.md, "Plots"):
#   - a CUDA block sweep as one heatmap panel per scene and configuration,
#     best cell framed, and no speedup plot (no worker count swept);
#   - a swept size (a numeric param) against the metric on log-log axes;
#   - titles naming the study, metric and machine; legends without the
#     words every series shares; one-configuration series not drawn as
#     scaling lines; more than eight distinct colours; scene bars with
#     error bars.
# usage: test-plot.sh HARNESS SOURCE_ROOT
set -u
. "$(dirname "$0")/common.sh"
test_setup plot "$1" "$1"
SRC=$(cd "$2" && pwd)
command -v gnuplot > /dev/null || fail "gnuplot missing (scripts/install-deps.sh installs gnuplot-nox)"
svg_ok() { [ -s "$1.png" ] && grep -q '<svg' "$1.svg" || fail "$1: no PNG or SVG"; }

echo "== 1. a block sweep: a heatmap per scene, no speedup plot"
"$H" plot "$SRC/results/gpu-blocks-harness.csv" -o blk > blk.out 2> blk.err || { cat blk.out blk.err; fail "plot"; }
svg_ok blk-blocks
[ -e blk-speedup.png ] && fail "a speedup plot for a study that sweeps no worker count"
grep -q 'speedup plot left out' blk.err || fail "no word on the left-out speedup plot: $(cat blk.err)"
grep -q 'set multiplot layout 2,4' blk-blocks.gp || fail "5 panels not laid out 2 x 4"
[ "$(grep -c 'with boxxyerror' blk-blocks.gp)" -eq 10 ] || fail "not 5 panels per terminal"
# dragon's fastest cell in the CSV is 4x8 at 0.432 ms (table), framed
grep -q "dragon cuda/bvh: best 4x8, 0.432 ms" blk-blocks.gp || fail "dragon's best cell not 4x8"
grep -q "set object 1 rect from -0.5,2.5 to 0.5,3.5" blk-blocks.gp || fail "the best cell's frame is not at 4x8"
grep -q "cuda-blocks: median render_ms (ms) by CUDA block width x height" blk-blocks.gp || fail "no study/metric title"
grep -q "on Intel(R) Xeon(R) Processor, 16 cores" blk-blocks.gp || fail "no machine in the title"
grep -q "set style histogram errorbars" blk-scenes.gp || fail "scene bars without error bars"
grep -q "^set linetype 17 " blk-scenes.gp || fail "fewer than 17 distinct colours for 17 configurations"
grep -q '(no size swept' blk.out || fail "no word on the left-out sweep plot"

echo "== 2. a swept size on log-log axes, one line per series"
cat > sw.conf <<'EOF'
study: sweep
command: sh -c 'echo "cost: $(( {n} * {n} ))"' sh
param n: 10 20 40 80
param tag: a b
metric cost: 'cost: ([0-9]+)' unit ms
repeats: 2
pin: none
EOF
"$H" run sw.conf -o sw.csv -q > run.out 2>&1 || { cat run.out; fail "sweep study"; }
"$H" plot sw.csv -o sw > sw.out 2> sw.err || { cat sw.out sw.err; fail "plot of the sweep"; }
svg_ok sw-sweep
grep -q 'set logscale xy' sw-sweep.gp || fail "the sweep is not on log axes"
grep -q "sweep: cost against n" sw-sweep.gp || fail "no title naming the metric and the param"
grep -q "'n (log scale)'" sw-sweep.gp || fail "no x label naming the param"
[ "$(grep -c 'with yerrorlines' sw-sweep.gp)" -eq 2 ] || fail "not one line per tag"
grep -q "title 'tag=a'" sw-sweep.gp || fail "legend not reduced to what differs (tag=a)"
# the points: n and its square, in increasing n
[ "$(awk 'NF == 4 && $1 == 40 { print $2 }' sw-sweep.dat | sort -u)" = 1600 ] || fail "wrong sweep data: $(cat sw-sweep.dat)"
[ -e sw-speedup.png ] && fail "a speedup plot for a study that sweeps no worker count"

echo "== 3. a worker sweep: title, legend, single configurations"
"$H" plot "$SRC/results/cpu-2core-mpi-scaling-bvh.csv" -o mpi > mpi.out 2> mpi.err || { cat mpi.err; fail "plot"; }
svg_ok mpi-speedup
grep -q "speedup of render_ms vs the same series at 1 worker" mpi-speedup.gp || fail "no metric in the title"
grep -q "set xlabel 'MPI ranks (log2 scale)'" mpi-speedup.gp || fail "the x label does not say ranks"
grep -q "log2 scale" <(grep ylabel mpi-speedup.gp) || fail "the speedup's log axis is not labelled as such"
grep -q "not drawn as scaling" mpi.err || fail "no word on the one-configuration series: $(cat mpi.err)"
grep -q "title 'serial" mpi-speedup.gp && fail "the serial configuration is drawn as a scaling series"
grep -q "all series: " mpi-speedup.gp || fail "the words all series share are not in the title"
echo "PASS"
