#!/bin/sh
# gpu-plot.sh [CSV] [PREFIX] - the block-size plot from scripts/gpu-run.sh's
# sweep (results/gpu-blocks.csv): kernel time per block shape, one line per
# scene and schedule, normalised to the scene's best shape so that scenes of
# different cost share one axis. Writes PREFIX.dat, PREFIX.gp, PREFIX.png and
# PREFIX.svg (default plots/gpu-blocks). Needs gnuplot (not on the GPU machine:
# run it here on the CSV that came back).
set -eu
CSV=${1:-results/gpu-blocks.csv}
P=${2:-plots/gpu-blocks}
SHAPES="8x4 4x8 8x8 16x8 16x16 32x4 32x8 32x16 32x32 64x4 64x8 128x1 256x1 512x1 1024x1 13x7"
SCENES=$(awk -F, 'NR > 1 { if (!($2 in s)) { s[$2] = 1; printf "%s ", $2 } }' "$CSV")  # column 2: scene
# columns: index, shape, then per scene: persistent, grid (ms / best ms of that scene)
awk -F, -v shapes="$SHAPES" -v scenes="$SCENES" '
    NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next }
    { ms = $c["render_ms"]; k = $c["scene"] SUBSEP $c["block"] SUBSEP $1; t[k] = ms
      if (!($c["scene"] in best) || ms < best[$c["scene"]]) best[$c["scene"]] = ms }
    END {
        ns = split(shapes, sh, " "); nc = split(scenes, sc, " ")
        printf "# index shape"; for (j = 1; j <= nc; j++) printf " %s-persistent %s-grid", sc[j], sc[j]; printf "\n"
        for (i = 1; i <= ns; i++) {
            printf "%d %s", i - 1, sh[i]
            for (j = 1; j <= nc; j++) for (m = 0; m < 2; m++) {
                k = sc[j] SUBSEP sh[i] SUBSEP (m ? "grid" : "persistent")
                printf " %s", (k in t) ? sprintf("%.4f", t[k] / best[sc[j]]) : "nan"
            }
            printf "\n"
        }
    }' "$CSV" >"$P.dat"
n=$(echo $SCENES | wc -w)
{
    echo "set datafile missing 'nan'"
    echo "set termoption noenhanced"
    echo "set ylabel 'kernel time / best shape of the scene'"
    echo "set xlabel 'block shape (BXxBY threads = pixel tile)'"
    echo "set title 'CUDA-BVH kernel time by block shape, NVIDIA H100 (median of 15 launches)'"
    echo "set key outside right top"
    echo "set grid ytics"
    echo "set xtics rotate by -45"
    echo "set yrange [0.95:*]"
    printf "plot "
    j=0
    for s in $SCENES; do
        col=$((3 + 2 * j))
        printf "'%s' using 1:%d%s with linespoints lc %d pt 7 title '%s persistent', " "$P.dat" $col "$([ $j -eq 0 ] && echo ":xtic(2)")" $((j + 1)) "$s"
        printf "'%s' using 1:%d with linespoints lc %d dt 2 pt 6 title '%s grid'" "$P.dat" $((col + 1)) $((j + 1)) "$s"
        j=$((j + 1))
        [ $j -lt $n ] && printf ", "
    done
    echo
} >"$P.gp"
gnuplot -e "set terminal pngcairo size 1100,600; set output '$P.png'" "$P.gp"
gnuplot -e "set terminal svg size 1100,600; set output '$P.svg'" "$P.gp"
echo "wrote $P.png $P.svg"
