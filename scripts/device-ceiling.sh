#!/usr/bin/env bash
# device-ceiling.sh - docs/harness-noise.md's "Ceiling" on a large machine: the
# machine's own ceiling (`harness ceiling`) for the dragon at 1024x768, then
# the OpenMP (tiles, pixels) and MPI (dynamic, rows) strong-scaling studies
# there over 1..16 workers (1..32 where the machine has 32 cores), and their
# tables with efficiency against the ceiling. Then, with STUDIES, the
# third-party workloads of scripts/device-workloads.sh. Everything goes to
# $OUT. Run from the repository root through the device tool with carry
# [".devcarry", ".devwl"]: the dragon in .devcarry/scenes/course (see
# scripts/device-cpu-scaling.sh), and Debian 12's hwloc and pkgconf packages
# in .devwl/debs for a machine that has no libhwloc-dev (without hwloc the
# harness neither pins nor measures a ceiling):
#   mkdir -p .devwl/debs && (cd .devwl/debs && apt-get download libhwloc15 \
#       libhwloc-dev pkgconf pkgconf-bin libpkgconf3 hpcc libblas3 libgfortran5)
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/device-ceiling}
mkdir -p "$OUT"
T0=$(date +%s)
log() { echo "[$(($(date +%s) - T0))s] $*" | tee -a "$OUT/log.txt"; }
[ "$(id -u)" != 0 ] || export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

P=/tmp/wl-pkgs
if ! pkg-config --exists hwloc 2> /dev/null || ! command -v hpcc > /dev/null; then
    for f in .devwl/debs/*.deb; do dpkg -x "$f" "$P"; done
    sed -i "s|^prefix=.*|prefix=$P/usr|" "$P"/usr/lib/x86_64-linux-gnu/pkgconfig/hwloc.pc
    export PATH=$PATH:$P/usr/bin
    command -v pkg-config > /dev/null || ln -sf "$P/usr/bin/pkgconf" "$P/usr/bin/pkg-config"
    export PKG_CONFIG_PATH=$P/usr/lib/x86_64-linux-gnu/pkgconfig
    export LD_LIBRARY_PATH=$P/usr/lib/x86_64-linux-gnu:$P/usr/lib/x86_64-linux-gnu/blas${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
xx=()
[ -f /usr/include/xxhash.h ] || xx+=("-Dc_args=-I$PWD/.devcarry/include")
{ nproc; lscpu | head -20; mpirun --version | head -1; pkg-config --modversion hwloc; } > "$OUT/machine.txt" 2>&1
B=/tmp/build-ceiling
if [ ! -f $B/build.ninja ]; then
    meson setup $B -Dcuda=disabled -Dhwloc=enabled -Dcourse_dir=none "${xx[@]}" > "$OUT/setup.log" 2>&1 ||
        { log "setup failed"; tail -20 "$OUT/setup.log"; exit 1; }
fi
ninja -C $B harness/harness renderer/raytrace > "$OUT/build.log" 2>&1 || { log "build failed"; tail -20 "$OUT/build.log"; exit 1; }
H=$B/harness/harness
W='1..16 *2'
[ "$(nproc)" -ge 32 ] && W='1..32 *2'
S=(--set scene_dir=.devcarry/scenes/course --set resolution=1024x768)
log "built; workers $W"

if [[ " ${STUDIES:-ceiling cpu} " == *" ceiling "* ]]; then
    log "ceiling"
    "$H" ceiling configs/openmp-scaling-bvh.conf "${S[@]}" --set threads="$W" --set schedule=tiles \
        -o "$OUT/ceiling.csv" 2>&1 | tee -a "$OUT/log.txt"
fi
if [[ " ${STUDIES:-ceiling cpu} " == *" cpu "* ]]; then
    for s in openmp mpi; do
        log "$s study"
        k=threads
        [ $s = mpi ] && k=ranks
        "$H" run configs/$s-scaling-bvh.conf "${S[@]}" --set $k="$W" --set repeats="${REPEATS:-5}" -q \
            -o "$OUT/$s.csv" --overwrite > "$OUT/$s.log" 2>&1 || log "$s: exit $?"
        head -3 "$OUT/$s.log" | tee -a "$OUT/log.txt"
        "$H" table "$OUT/$s.csv" --ceiling "$OUT/ceiling.csv" > "$OUT/$s-table.md" 2>&1
        sed -n '1,/^### Amdahl/p' "$OUT/$s-table.md"
    done
fi
# An MPI start at one rank, alone (the hpcc study's first run once hung here)
if [[ " ${STUDIES:-} " == *" hpcc "* ]]; then
    d=$(mktemp -d)
    for np in 1 2; do
        sed -e 's/{n}/1000/; s/{nb}/128/' -e "s/{ranks}/$np/" configs/hpcc/hpccinf.txt.in > "$d/hpccinf.txt"
        t=$(date +%s%N)
        (cd "$d" && timeout 60 mpirun --bind-to core -np $np hpcc > /dev/null 2> "$OUT/hpcc-np$np.err")
        log "hpcc np=$np N=1000 by hand: rc $? in $((($(date +%s%N) - t) / 1000000)) ms"
    done
fi
for s in ${STUDIES:-}; do
    case $s in hpcc | xz) OUT=$OUT/wl STUDIES=$s bash scripts/device-workloads.sh 2>&1 | tail -40 ;; esac
done
log "done"
# the device tool brings back a few files: everything as one archive too
tar -C "$OUT" -czf /tmp/device-ceiling.tar.gz . && mv /tmp/device-ceiling.tar.gz "$OUT/all.tar.gz"
