#!/usr/bin/env bash
# device-cpu32.sh - the 32-core host (device kind nvidia-h100-x2 or
# nvidia-h200-x2): the machine's ceiling (harness ceiling) at 1, 16 and 32
# workers; the report's tables 1 and 2 at 1, 16 and 32 workers (BVH at
# 512x384 and 2048x1536, 5 repeats; brute force at 512x384, one T=1 run);
# the hybrid grid at 2048x1536; `harness ab` of the MPI backend at 32 ranks
# against an older commit. The code measured is .devcarry/head.tar.gz
# (git archive --prefix=head/ HEAD | gzip), the older one
# .devcarry/basempi.tar.gz (git archive --prefix=basempi/ OLD | gzip).
# Carry [".devcarry", ".devwl"] (scripts/device-ceiling.sh says what they
# hold). Everything goes to $OUT; $OUT/all.tgz holds it all.
set -u
R=$PWD; O=${OUT:-/tmp/device-cpu32}; mkdir -p "$O"; T0=$(date +%s)
log() { echo "[$(($(date +%s) - T0))s] $*" | tee -a "$O/log.txt"; }
left() { echo $((560 - ($(date +%s) - T0))); }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
P=/tmp/wl-pkgs
for f in .devwl/debs/*.deb; do dpkg -x "$f" "$P"; done
sed -i "s|^prefix=.*|prefix=$P/usr|" "$P"/usr/lib/x86_64-linux-gnu/pkgconfig/hwloc.pc
export PATH=$PATH:$P/usr/bin
command -v pkg-config > /dev/null || ln -sf "$P/usr/bin/pkgconf" "$P/usr/bin/pkg-config"
export PKG_CONFIG_PATH=$P/usr/lib/x86_64-linux-gnu/pkgconfig LD_LIBRARY_PATH=$P/usr/lib/x86_64-linux-gnu
tar xzf .devcarry/head.tar.gz -C /tmp; tar xzf .devcarry/basempi.tar.gz -C /tmp
course=$R/.devcarry/scenes/course
xx=(); [ -f /usr/include/xxhash.h ] || xx+=("-Dc_args=-I$R/.devcarry/include")
{ nproc; lscpu | grep -E 'Model name|NUMA|Socket|Thread'; mpirun --version | head -1; cd /tmp/head; git log -1 2>/dev/null; } > "$O/machine.txt" 2>&1
(cd /tmp/head && meson setup /tmp/bh -Dcuda=disabled -Dhwloc=enabled -Dcourse_dir=none "${xx[@]}" > "$O/setup.log" 2>&1 && ninja -C /tmp/bh > "$O/build.log" 2>&1) || { log "head build failed"; tail -30 "$O/build.log" "$O/setup.log"; exit 1; }
(cd /tmp/basempi && meson setup /tmp/bb -Dcuda=disabled -Dcourse_dir=none "${xx[@]}" > /dev/null 2>&1 && ninja -C /tmp/bb renderer/raytrace > "$O/base-build.log" 2>&1) || log "base build failed"
log built
H=/tmp/bh/harness/harness RT=/tmp/bh/renderer/raytrace
cd /tmp/head
dragon=$(find $course -name dragon.txt | head -1)
C=(--set scene_dir=$course)
for res in 512x384 2048x1536; do
  timeout 100 $H ceiling configs/openmp-scaling-bvh.conf "${C[@]}" --set resolution=$res --set threads="1 16 32" --set schedule=tiles --repeats 5 -o "$O/ceiling-$res.csv" > "$O/ceiling-$res.log" 2>&1 || log "ceiling $res rc $?"
done
log ceilings
tab() { $H table "$O/$1.csv" --ceiling "$O/ceiling-$2.csv" > "$O/$1-table.md" 2>&1; sed -n '/^| .*configuration/,/^$/p' "$O/$1-table.md" | head -16; }
for res in 512x384 2048x1536; do
  S=("${C[@]}" --set resolution=$res --set repeats=5 --set accel=bvh)
  timeout 100 $H run configs/report-table1-openmp.conf "${S[@]}" --set threads="1 16 32" -q -o "$O/t1-bvh-$res.csv" > /dev/null 2>&1 || log "t1 $res rc $?"
  tab t1-bvh-$res $res
  timeout 100 $H run configs/report-table2-mpi.conf "${S[@]}" --set ranks="1 16 32" -q -o "$O/t2-bvh-$res.csv" > /dev/null 2>&1 || log "t2 $res rc $?"
  tab t2-bvh-$res $res
done
log "bvh tables"
timeout 100 $H run configs/hybrid-dragon.conf "${C[@]}" --set resolution=2048x1536 --set backend=mpi --set ranks="2 4 8 16" --set threads="16 8 4 2" --set repeats=3 -q -o "$O/hybrid-2048x1536.csv" > /dev/null 2>&1 || log "hybrid rc $?"
$H table "$O/hybrid-2048x1536.csv" > "$O/hybrid-2048x1536-table.md" 2>&1; grep -E "P=[0-9]+ T=[0-9]+" "$O/hybrid-2048x1536-table.md" | grep -E "P=2 T=16|P=4 T=8|P=8 T=4|P=16 T=2" | head
log hybrid
cat > /tmp/m32.conf <<C2
study: mpi32
scene_dir: $course
scenes: dragon
backend: mpi
accel: bvh
mpi_schedule: dynamic
resolution: 512x384 2048x1536
ranks: 32
pin: close
repeats: 1
timeout: 60
C2
[ "$(left)" -gt 60 ] && timeout 90 $H ab --config /tmp/m32.conf /tmp/bb/renderer/raytrace $RT --rounds 5 > "$O/ab-mpi32.txt" 2> "$O/ab-mpi32.err"; log "ab rc $?"
grep -E '^(IMPROVEMENT|REGRESSION|INCONCLUSIVE|no change)' "$O/ab-mpi32.txt" | cut -c1-250
for res in 2048x1536; do echo "== $res" >> "$O/keys32.txt"
  timeout 60 mpirun --bind-to core -np 32 $RT --backend mpi -q -r $res $dragon -o /tmp/k.png 2>&1 | tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|rank_claims|rank_work_ms|rank_end_ms)=' >> "$O/keys32.txt"; done
log "brute force"
S=("${C[@]}" --set resolution=512x384 --set accel=none)
[ "$(left)" -gt 100 ] && timeout $(( $(left) - 50 )) $H run configs/report-table1-openmp.conf "${S[@]}" --set threads="1 32" --set backend=openmp --set schedule="tiles pixels" --set repeats=1 -q -o "$O/t1-none-512x384.csv" > /dev/null 2>&1 || log "t1 none rc $?"
tab t1-none-512x384 512x384
[ "$(left)" -gt 40 ] && timeout $(( $(left) - 10 )) $H run configs/report-table2-mpi.conf "${S[@]}" --set ranks="32" --set backend=mpi --set repeats=3 -q -o "$O/t2-none-512x384.csv" > /dev/null 2>&1 || log "t2 none rc $?"
$H table "$O/t2-none-512x384.csv" > "$O/t2-none-512x384-table.md" 2>&1; sed -n '/^| .*configuration/,/^$/p' "$O/t2-none-512x384-table.md" | head
log done
cd $O && tar czf /tmp/all.tgz . && mv /tmp/all.tgz $O/all.tgz
