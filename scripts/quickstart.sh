#!/usr/bin/env bash
# quickstart.sh - the README's first command: installs what is missing
# (Debian packages), builds raybench, and runs the main job: a quick scaling
# study of scenes/demo.txt (configs/quick.conf), then prints its table and
# says where the CSV, the table, the plots and the HTML report went.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
[ -f build/build.ninja ] || meson setup build
ninja -C build
h=build/harness/harness
"$h" run configs/quick.conf -o results/quick.csv --overwrite
"$h" table results/quick.csv | tee results/quick-table.md
"$h" plot results/quick.csv -o plots/quick
"$h" report results/quick.csv -o results/quick-report > /dev/null
echo
echo "quickstart: one CSV row per run:  results/quick.csv"
echo "quickstart: speedup/efficiency:   results/quick-table.md"
echo "quickstart: plots (PNG and SVG):  $(ls plots/quick-*.png | tr '\n' ' ')"
echo "quickstart: the report (HTML):    results/quick-report/index.html"
