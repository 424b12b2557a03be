set datafile missing 'nan'
set termoption noenhanced
set ylabel 'kernel time / best shape of the scene'
set xlabel 'block shape (BXxBY threads = pixel tile)'
set title 'CUDA-BVH kernel time by block shape, NVIDIA H100 (median of 15 launches)'
set key outside right top
set grid ytics
set xtics rotate by -45
set yrange [0.95:*]
plot 'plots/gpu-blocks.dat' using 1:3:xtic(2) with linespoints lc 1 pt 7 title 'dragon persistent', 'plots/gpu-blocks.dat' using 1:4 with linespoints lc 1 dt 2 pt 6 title 'dragon grid', 'plots/gpu-blocks.dat' using 1:5 with linespoints lc 2 pt 7 title 'arm-reach persistent', 'plots/gpu-blocks.dat' using 1:6 with linespoints lc 2 dt 2 pt 6 title 'arm-reach grid', 'plots/gpu-blocks.dat' using 1:7 with linespoints lc 3 pt 7 title 'bottle persistent', 'plots/gpu-blocks.dat' using 1:8 with linespoints lc 3 dt 2 pt 6 title 'bottle grid', 'plots/gpu-blocks.dat' using 1:9 with linespoints lc 4 pt 7 title 'test_reasonable persistent', 'plots/gpu-blocks.dat' using 1:10 with linespoints lc 4 dt 2 pt 6 title 'test_reasonable grid', 'plots/gpu-blocks.dat' using 1:11 with linespoints lc 5 pt 7 title 'ShadowTest persistent', 'plots/gpu-blocks.dat' using 1:12 with linespoints lc 5 dt 2 pt 6 title 'ShadowTest grid'
