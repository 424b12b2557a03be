#!/usr/bin/env bash
# device-workloads.sh - the third-party workloads of docs/harness.md
# ("Third-party workloads") on a large machine: configs/hpcc.conf over 1..16
# MPI ranks and configs/xz.conf over 1..16 threads, at the sizes below
# (STUDIES="hpcc xz", WORKERS, REPEATS, HPCC_N, XZ_MIB); the CSVs, tables
# and plots go to $OUT. Run from the repository root through the
# device tool with carry [".devwl"]. Where hpcc is not installed (no network
# there), the Debian packages in .devwl/debs are unpacked under /tmp/wl-pkgs:
#   mkdir -p .devwl/debs && (cd .devwl/debs && apt-get download hpcc libblas3 libgfortran5)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/device-workloads}
mkdir -p "$OUT"
if ! command -v hpcc > /dev/null; then
    for f in .devwl/debs/*.deb; do dpkg -x "$f" /tmp/wl-pkgs; done
    export PATH=/tmp/wl-pkgs/usr/bin:$PATH
    export LD_LIBRARY_PATH=/tmp/wl-pkgs/usr/lib/x86_64-linux-gnu:/tmp/wl-pkgs/usr/lib/x86_64-linux-gnu/blas${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
[ "$(id -u)" != 0 ] || export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
[ -f build-wl/build.ninja ] || meson setup build-wl -Dcuda=disabled -Dcourse_dir=none > /dev/null
ninja -C build-wl harness/harness > /dev/null
H=build-wl/harness/harness
W=${WORKERS:-1..16 *2}
run_hpcc() { # N=5000 (a 200 MB matrix): with the reference BLAS about 1.5 minutes a run at 1 rank
    $H run configs/hpcc.conf -o "$OUT/hpcc.csv" --overwrite --set ranks="$W" --set n="${HPCC_N:-5000}" \
        --set nb=128 --set repeats="${REPEATS:-2}" --set timeout="${HPCC_TIMEOUT:-5m}" 2>&1 | tail -3
    $H table "$OUT/hpcc.csv" --metric triad_gbs > "$OUT/hpcc-triad-table.md"
}
run_xz() { # 128 MiB, 32 blocks of 4 MiB: two per thread at 16 threads
    $H run configs/xz.conf -o "$OUT/xz.csv" --overwrite --set threads="$W" --set mib="${XZ_MIB:-128}" \
        --set repeats="${REPEATS:-3}" 2>&1 | tail -3
    $H table "$OUT/xz.csv" --metric maxrss_kib > "$OUT/xz-memory-table.md"
}
for s in ${STUDIES:-hpcc xz}; do # STUDIES: one or both, one per device call if time is short
    "run_$s"
    $H table "$OUT/$s.csv" > "$OUT/$s-table.md"
    $H table "$OUT/$s.csv" --wide > "$OUT/$s-table-wide.md"
    $H plot "$OUT/$s.csv" -o "$OUT/$s" > /dev/null 2>&1 || echo "plot of $s failed (gnuplot?)"
    cat "$OUT/$s-table.md"
done
