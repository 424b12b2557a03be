set logscale xy
set xlabel "triangles"
set ylabel "ms"
set key top left
set grid
set title "Large scenes: time against size (results/large-scenes-h100.csv)"
plot "plots/large-scenes-h100.dat" u 1:2 w lp t "parse, 1 thread", "" u 1:3 w lp t "parse, 16 threads", \
     "" u 1:4 w lp t "BVH build, 1 thread", "" u 1:5 w lp t "BVH build, 16 threads", \
     "" u 1:7 w lp t "render", "" u 1:8 w lp t "load from the scene cache"
