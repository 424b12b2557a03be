#!/usr/bin/env bash
# device-cpu-host.sh - a large CPU host (N cores: 32 on nvidia-h100-x2 or
# nvidia-h200-x2, 64 on the x4 kinds): the machine's ceiling (harness
# ceiling) at 1, 16, N/2 and N workers; the report's tables 1 and 2 there
# (BVH at 512x384 and 2048x1536, 5 repeats; brute force at 512x384, one T=1
# run); the hybrid grid P x T = N at 2048x1536; `harness ab` of the MPI
# backend at N ranks against an older commit. The code measured is .devcarry/head.tar.gz
# (git archive --prefix=head/ HEAD | gzip), the older one
# .devcarry/basempi.tar.gz (git archive --prefix=basempi/ OLD | gzip).
# Carry [".devcarry", ".devwl"] (scripts/device-ceiling.sh says what they
# hold). Everything goes to $OUT; $OUT/all.tgz holds it all.
set -u
R=$PWD; O=${OUT:-/tmp/device-cpu-host}; mkdir -p "$O"; T0=$(date +%s)
log() { echo "[$(($(date +%s) - T0))s] $*" | tee -a "$O/log.txt"; }
left() { echo $((560 - ($(date +%s) - T0))); }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
. scripts/device-debs.sh
tar xzf .devcarry/head.tar.gz -C /tmp; tar xzf .devcarry/basempi.tar.gz -C /tmp
course=$R/.devcarry/scenes/course
xx=(); [ -f /usr/include/xxhash.h ] || xx+=("-Dc_args=-I$R/.devcarry/include")
{ nproc; lscpu | grep -E 'Model name|NUMA|Socket|Thread'; mpirun --version | head -1; cd /tmp/head; git log -1 2>/dev/null; } > "$O/machine.txt" 2>&1
(cd /tmp/head && meson setup /tmp/bh -Dcuda=disabled -Dhwloc=enabled -Dcourse_dir=none "${xx[@]}" > "$O/setup.log" 2>&1 && ninja -C /tmp/bh > "$O/build.log" 2>&1) || { log "head build failed"; tail -30 "$O/build.log" "$O/setup.log"; exit 1; }
(cd /tmp/basempi && meson setup /tmp/bb -Dcuda=disabled -Dcourse_dir=none "${xx[@]}" > /dev/null 2>&1 && ninja -C /tmp/bb renderer/raytrace > "$O/base-build.log" 2>&1) || log "base build failed"
log built
N=$(nproc); W=$(echo 1 16 $((N / 2)) $N | tr ' ' '\n' | sort -nu | tr '\n' ' ')
HR=""; HT=""; for ((p = 2; p < N; p *= 2)); do HR="$HR $p"; HT="$HT $((N / p))"; done
H=/tmp/bh/harness/harness RT=/tmp/bh/renderer/raytrace
cd /tmp/head
dragon=$(find $course -name dragon.txt | head -1)
C=(--set scene_dir=$course)
for res in 512x384 2048x1536; do
  timeout 100 $H ceiling configs/openmp-scaling-bvh.conf "${C[@]}" --set resolution=$res --set threads="$W" --set schedule=tiles --repeats 5 -o "$O/ceiling-$res.csv" > "$O/ceiling-$res.log" 2>&1 || log "ceiling $res rc $?"
done
log ceilings
tab() { $H table "$O/$1.csv" --ceiling "$O/ceiling-$2.csv" > "$O/$1-table.md" 2>&1; sed -n '/^| .*configuration/,/^$/p' "$O/$1-table.md" | head -16; }
for res in 512x384 2048x1536; do
  S=("${C[@]}" --set resolution=$res --set repeats=5 --set accel=bvh)
  timeout 100 $H run configs/report-table1-openmp.conf "${S[@]}" --set threads="$W" -q -o "$O/t1-bvh-$res.csv" > /dev/null 2>&1 || log "t1 $res rc $?"
  tab t1-bvh-$res $res
  timeout 100 $H run configs/report-table2-mpi.conf "${S[@]}" --set ranks="$W" -q -o "$O/t2-bvh-$res.csv" > /dev/null 2>&1 || log "t2 $res rc $?"
  tab t2-bvh-$res $res
done
log "bvh tables"
timeout 100 $H run configs/hybrid-dragon.conf "${C[@]}" --set resolution=2048x1536 --set backend=mpi --set ranks="$HR" --set threads="$HT" --set repeats=3 -q -o "$O/hybrid-2048x1536.csv" > /dev/null 2>&1 || log "hybrid rc $?"
$H table "$O/hybrid-2048x1536.csv" > "$O/hybrid-2048x1536-table.md" 2>&1; grep -E "P=[0-9]+ T=[0-9]+" "$O/hybrid-2048x1536-table.md" | head -12
log hybrid
cat > /tmp/mN.conf <<C2
study: mpi$N
scene_dir: $course
scenes: dragon
backend: mpi
accel: bvh
mpi_schedule: dynamic
resolution: 512x384 2048x1536
ranks: $N
pin: close
repeats: 1
timeout: 60
C2
[ "$(left)" -gt 60 ] && timeout 90 $H ab --config /tmp/mN.conf /tmp/bb/renderer/raytrace $RT --rounds 5 > "$O/ab-mpi$N.txt" 2> "$O/ab-mpi$N.err"; log "ab rc $?"
grep -E '^(IMPROVEMENT|REGRESSION|INCONCLUSIVE|no change)' "$O/ab-mpi$N.txt" | cut -c1-250
for res in 2048x1536; do echo "== $res" >> "$O/keys$N.txt"
  timeout 60 mpirun --bind-to core -np $N $RT --backend mpi -q -r $res $dragon -o /tmp/k.png 2>&1 | tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|rank_claims|rank_work_ms|rank_end_ms)=' >> "$O/keys$N.txt"; done
log "brute force"
S=("${C[@]}" --set resolution=512x384 --set accel=none)
[ "$(left)" -gt 100 ] && timeout $(( $(left) - 50 )) $H run configs/report-table1-openmp.conf "${S[@]}" --set threads="1 $N" --set backend=openmp --set schedule="tiles pixels" --set repeats=1 -q -o "$O/t1-none-512x384.csv" > /dev/null 2>&1 || log "t1 none rc $?"
tab t1-none-512x384 512x384
[ "$(left)" -gt 40 ] && timeout $(( $(left) - 10 )) $H run configs/report-table2-mpi.conf "${S[@]}" --set ranks="$N" --set backend=mpi --set repeats=3 -q -o "$O/t2-none-512x384.csv" > /dev/null 2>&1 || log "t2 none rc $?"
$H table "$O/t2-none-512x384.csv" > "$O/t2-none-512x384-table.md" 2>&1; sed -n '/^| .*configuration/,/^$/p' "$O/t2-none-512x384-table.md" | head
log done
cd $O && tar czf /tmp/all.tgz . && mv /tmp/all.tgz $O/all.tgz
