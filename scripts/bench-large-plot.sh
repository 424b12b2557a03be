#!/bin/sh
# bench-large-plot.sh CSV [PREFIX] - the growth of parse, build and render
# time with the triangle count from scripts/bench-large.sh's CSV, log-log,
# medians: parse and build on one thread and on all, Embree's build where
# measured, the render, and the load from the scene cache. Writes PREFIX.dat,
# PREFIX.gp, PREFIX.png and PREFIX.svg (default plots/large-scenes). Needs
# gnuplot (not on the GPU machine: plot the CSV that came back).
set -eu
CSV=$1
P=${2:-plots/large-scenes}
# columns: triangles, parse 1, parse N, build 1, build N, embree N, render N, cache load N
awk -F, 'NR == 1 { next }
    { t[$1] = 1; k = $1 "," $2 "," ($3 == 1 ? 1 : "n"); p[k] = p[k] " " $5; b[k] = b[k] " " $6; r[k] = r[k] " " $7 }
    function med(s,   a, n, i, j, x) { n = split(s, a, " "); if (n == 0) return "NaN";
        for (i = 2; i <= n; i++) { x = a[i] + 0; for (j = i - 1; j >= 1 && a[j] + 0 > x; j--) a[j + 1] = a[j]; a[j + 1] = x }
        return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2 }
    END { print "# triangles parse1 parseN build1 buildN embreeN renderN cacheloadN"
          for (x in t) print x, med(p[x ",load,1"]), med(p[x ",load,n"]), med(b[x ",load,1"]), med(b[x ",load,n"]),
                                med(b[x ",embree-build,n"]), med(r[x ",load,n"]), med(p[x ",cached,n"]) }' "$CSV" |
    sort -n > "$P.dat"
threads=$(awk -F, 'NR > 1 && $2 == "load" && $3 != 1 { print $3; exit }' "$CSV")
embree=""
grep -q ',embree-build,' "$CSV" && embree="\"\" u 1:6 w lp t \"Embree build, $threads threads\", "
cat > "$P.gp" <<GP
set logscale xy
set xlabel "triangles"
set ylabel "ms"
set key top left
set grid
set title "Large scenes: time against size ($CSV)"
plot "$P.dat" u 1:2 w lp t "parse, 1 thread", "" u 1:3 w lp t "parse, $threads threads", \\
     "" u 1:4 w lp t "BVH build, 1 thread", "" u 1:5 w lp t "BVH build, $threads threads", \\
     $embree"" u 1:7 w lp t "render", "" u 1:8 w lp t "load from the scene cache"
GP
gnuplot -e "set terminal pngcairo size 900,600; set output '$P.png'; load '$P.gp'"
gnuplot -e "set terminal svg size 900,600; set output '$P.svg'; load '$P.gp'"
echo "wrote $P.dat $P.gp $P.png $P.svg"
