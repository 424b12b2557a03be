#!/usr/bin/env bash
# device-cpu-stalls.sh - a large CPU host (64 cores on the nvidia-h100-x4 and
# nvidia-h200-x4 kinds): how its stalls reach the OpenMP and MPI frames.
# STEPS (default "ab ceil tables keys"), each into $OUT:
#   ab      `harness ab` of OpenMP and MPI (AB_BACKENDS) at N workers (ABW),
#           512x384 and 2048x1536, the older build against this one
#           (ROUNDS, default 7)
#   ceil    `harness ceiling` at 1, N/2 and N copies (WORKERS), both
#           resolutions
#   ceilprev the same with the older build's harness (its ceiling's own
#           measure: before e.g. render_ms, the copies' wall time)
#   tables  the report's tables 1 and 2 (BVH, tiles, dynamic) at 1, N/2 and
#           N workers (WORKERS), TREP repeats (default 5), `order: rounds`; tables against
#           the ceiling
#   keys    5 unpinned runs of each at N workers (or at each of
#           KEYS_WORKERS), their timing keys
#   diag    6 rounds of OpenMP (pinned, this build and the older one) and MPI
#           at N workers: fork_ms, thread_start_ms, backups, rank_work_ms
#   none    brute force at N workers, 3 repeats each
#   bruteceil brute force against its own ceiling: `harness ceiling` of
#           brute-force copies at N (RES, default 512x384; 1 repeat, CEIL_S
#           default 100 s), then table 1's OpenMP tiles with brute force at 1
#           and N threads, 2 repeats, `order: rounds`, and its table against
#           that ceiling
#   brute2k brute force at 2048x1536: table 1's OpenMP tiles at N threads,
#           REP2K repeats (default 3); its pace comes from bruteceil's
#           512x384 copies, scaled by the two frames' prim_tests (one
#           thread's 2048x1536 frame outlasts a device call)
#   paired  ROUNDS rounds (default 12), each `harness ceiling` (1 repeat) at N
#           and tables 1 and 2 (BVH) at 1 and N workers, 1 repeat, RES
#           (default 512x384), into paired/: each round's pace against the
#           ceiling measured beside it, so a drift of the host between the
#           ceiling and the tables stays out of the ratio
#   rounds  tables 2 and 1 (BVH) at 1 and N workers (WORKERS) with `ceiling:
#           rounds`: the ceiling's copies before each of TREP rounds
#           (default 9), RES (default 512x384), each table against its own
#           rounds (t2-rounds-RES-ceiling.csv beside t2-rounds-RES.csv)
#   one     serial, OpenMP at one thread and MPI at one rank, interleaved
#           (`order: rounds`, 10 repeats), both resolutions: the baselines
#           of tables 1 and 2 on the same core at the same time
#   lean    MPI at N ranks, the older build and this one interleaved,
#           512x384 and 2048x1536, ROUNDS rounds (default 20): every
#           per-rank key, to see where one's frames differ from the other's
#   warm    in-process warm-up frames: MPI at N ranks and OpenMP at N
#           threads with --warmup 0 --runs 1 (the tables' runs) and with
#           --warmup 3 --runs 9, and one rank with --warmup 1 --runs 3,
#           both resolutions, interleaved, ROUNDS rounds (default 8)
#   build   the BVH build, the older build and this one interleaved, ROUNDS
#           rounds (default 7): build_ms and build_threads of the demo scene
#           (7 primitives), the dragon and a 1M-triangle sphere field on the
#           default threads, idle and beside one busy core; then every rank
#           parsing and building at N ranks (--mpi-scene every), the same
#           two scenes, beside one busy core
#   idle    whether idle cores cost the first frame: MPI at N ranks and
#           OpenMP at N threads, cold (--warmup 0 --runs 1), cold with a
#           SCHED_IDLE spinner on every core (so no core idles, while any
#           other thread preempts it), and warm (--warmup 3 --runs 9),
#           interleaved, RES, ROUNDS rounds (default 8): each run's keys and
#           the host's steal over it (steal_pct, % of all CPU time).
#           IDLE_MODES picks the modes (default "cold spun warm"); "active"
#           is cold with OMP_WAIT_POLICY=active for OpenMP (its threads spin
#           between regions instead of sleeping)
#   pixcost where a rank's pixels cost more than a thread's: warm frames
#           (--warmup 3 --runs 9) of OpenMP at N threads, MPI at N ranks
#           dynamic (the shared image, board and counter) and with block
#           rows (each rank its own image, no claims), and one rank of N
#           threads with block rows, of the dragon and of scenes/glass.txt
#           (a few primitives: no memory but the image), interleaved, RES
#           (default 512x384 2048x1536), ROUNDS rounds (default 4); each
#           worker's own time (thread_work_ms, rank_work_ms), whose sum is
#           the frame's CPU time in pixels
#   cache   whether the scene cache moves a frame: `harness ab` of MPI at N
#           ranks, and of OpenMP at N threads, with the scene loaded from
#           the cache (A) and built in the process (B), RES (default
#           512x384), ROUNDS rounds (default 16)
#   order   MPI at N ranks, the scene from the scene cache or built in
#           every rank, each alone or right after a one-rank run (as
#           `order: rounds` runs a table), interleaved, RES (default
#           512x384), ROUNDS rounds (default 12): render_ms, each rank's
#           work and the host's steal over the run
#   bigbuild the BVH build of a 3.6M-triangle sphere field (large-4m) on
#           16, N/2 and N threads (BUILD_THREADS), the older build and this
#           one interleaved, ROUNDS rounds (default 3)
#   share   MPI at N ranks (or at each of WORKERS), the older build, the
#           middle one (.devcarry/mid.tar.gz, git archive --prefix=mid/,
#           where carried) and this one, and OpenMP at as many threads,
#           interleaved, RES, ROUNDS rounds (default 10): render_ms,
#           scene_copies and the starts
#   hybrid  the hybrid table (configs/hybrid-dragon.conf): every P x T <= N
#           of powers of two, both resolutions, 3 repeats, `order: rounds`,
#           against the ceiling (run ceil first), HYB_S seconds each (default 200)
#   layouts OpenMP at N threads and every P ranks x N/P threads (powers of
#           two), cold (--warmup 0 --runs 1) and warm (--warmup 3 --runs 9),
#           interleaved, RES (default 512x384), ROUNDS rounds (default 5):
#           the backup, per-rank and per-thread keys
#   gap     where a rank's frame differs from a thread's: warm frames
#           (--warmup 3 --runs 9) of OpenMP at N threads, MPI at N ranks
#           from the node's one copy of the scene (the older build, the
#           build of .devcarry/mid.tar.gz where carried, and this one), MPI
#           at N ranks from a
#           copy each (raytrace-testhooks, RT_MPI_TEST_SHM_FAIL=0: rank 0
#           makes no shared copy, so every rank keeps its own), and MPI at
#           one rank of N threads and two of N/2 by the older build and this
#           one, interleaved, RES, ROUNDS rounds (default 8); with the
#           backup and claim keys
# RES limits ceil, tables and warm to one resolution; EXTRA gives their runs
# raytrace arguments (extra_args), e.g. EXTRA="--warmup 3 --runs 9".
# CEIL_S bounds each ceiling (default 100 s; 2048x1536 with that EXTRA
# needs about 300).
# The code measured is .devcarry/head.tar.gz (git archive --prefix=head/ HEAD
# | gzip), the older one .devcarry/prev.tar.gz (git archive --prefix=prev/
# OLD | gzip). Carry [".devcarry", ".devwl"] (scripts/device-ceiling.sh says
# what they hold).
set -u
R=$PWD; O=${OUT:-/tmp/device-cpu-stalls}; mkdir -p "$O"; T0=$(date +%s)
log() { echo "[$(($(date +%s) - T0))s] $*" | tee -a "$O/log.txt"; }
left() { echo $((${LIMIT:-570} - ($(date +%s) - T0))); }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
. scripts/device-debs.sh
course=$R/.devcarry/scenes/course
xx=(); [ -f /usr/include/xxhash.h ] || xx+=("-Dc_args=-I$R/.devcarry/include")
if [ ! -x /tmp/bh/harness/harness ]; then
  tar xzf .devcarry/head.tar.gz -C /tmp; tar xzf .devcarry/prev.tar.gz -C /tmp
  { nproc; lscpu | grep -E 'Model name|NUMA|Socket|Thread'; mpirun --version | head -1; } > "$O/machine.txt" 2>&1
  (cd /tmp/head && meson setup /tmp/bh -Dcuda=disabled -Dhwloc=enabled -Dcourse_dir=none "${xx[@]}" > "$O/setup.log" 2>&1 && ninja -C /tmp/bh harness/harness renderer/raytrace > "$O/build.log" 2>&1) &
  (cd /tmp/prev && meson setup /tmp/bp -Dcuda=disabled -Dhwloc=enabled -Dcourse_dir=none "${xx[@]}" > /dev/null 2>&1 && ninja -C /tmp/bp renderer/raytrace harness/harness > "$O/prev-build.log" 2>&1) &
  if [ -f .devcarry/mid.tar.gz ]; then
    tar xzf .devcarry/mid.tar.gz -C /tmp
    (cd /tmp/mid && meson setup /tmp/bm -Dcuda=disabled -Dcourse_dir=none "${xx[@]}" > /dev/null 2>&1 && ninja -C /tmp/bm renderer/raytrace > "$O/mid-build.log" 2>&1) &
  fi
  wait
fi
[ -x /tmp/bh/renderer/raytrace ] && [ -x /tmp/bp/renderer/raytrace ] || { log "build failed"; tail -20 "$O"/*.log; exit 1; }
log built
H=/tmp/bh/harness/harness RT=/tmp/bh/renderer/raytrace PR=/tmp/bp/renderer/raytrace MID=/tmp/bm/renderer/raytrace
# the builds compared by share and gap (mid only where carried), and each one's renderer
VERS=(prev head); [ -x $MID ] && VERS=(prev mid head)
bin() { case $1 in prev) echo $PR ;; mid) echo $MID ;; *) echo $RT ;; esac; }
# mpirun's placement for P ranks of N/P threads: a rank's threads on its own cores
layout() { if [ $1 -gt 1 ]; then echo --map-by slot:PE=$((N / $1)) --bind-to core; else echo --bind-to none; fi; }
N=$(nproc)
X=(); [ -n "${EXTRA:-}" ] && X=(--set "extra_args=$EXTRA")
dragon=$(find $course -name dragon.txt | head -1)
cd /tmp/head
for step in ${STEPS:-ab ceil tables keys}; do case $step in
ab)
  for b in ${AB_BACKENDS:-openmp mpi}; do
    k=threads; [ $b = mpi ] && k=ranks
    printf 'study: %s%s\nscene_dir: %s\nscenes: dragon\nbackend: %s\naccel: bvh\nresolution: 512x384 2048x1536\n%s: %s\npin: close\nrepeats: 1\ntimeout: 60\n' $b $N $course $b $k "${ABW:-$N}" > /tmp/ab-$b.conf
    timeout $(( $(left) - 20 )) $H ab --config /tmp/ab-$b.conf $PR $RT --rounds ${ROUNDS:-7} > "$O/ab-$b.txt" 2> "$O/ab-$b.err"; log "ab $b rc $?"
    grep -E '^(IMPROVEMENT|REGRESSION|INCONCLUSIVE|no change)' "$O/ab-$b.txt" | cut -c1-250
  done ;;
ceil)
  W=${WORKERS:-1 $((N / 2)) $N}
  for res in ${RES:-512x384 2048x1536}; do
    timeout ${CEIL_S:-100} $H ceiling configs/openmp-scaling-bvh.conf --set scene_dir=$course --set resolution=$res --set threads="$W" --set schedule=tiles --repeats 5 "${X[@]}" -o "$O/ceiling-$res.csv" > "$O/ceiling-$res.log" 2>&1 || log "ceiling $res rc $?"
    tail -5 "$O/ceiling-$res.log"
  done; log ceilings ;;
ceilprev)
  W=${WORKERS:-1 $((N / 2)) $N}
  for res in ${RES:-512x384 2048x1536}; do
    timeout ${CEIL_S:-100} /tmp/bp/harness/harness ceiling configs/openmp-scaling-bvh.conf --set scene_dir=$course --set resolution=$res --set threads="$W" --set schedule=tiles --repeats 5 "${X[@]}" -o "$O/ceilprev-$res.csv" > "$O/ceilprev-$res.log" 2>&1 || log "ceilprev $res rc $?"
  done; log ceilprev ;;
tables)
  W=${WORKERS:-1 $((N / 2)) $N}
  for res in ${RES:-512x384 2048x1536}; do
    S=(--set scene_dir=$course --set resolution=$res --set repeats=${TREP:-5} --set accel=bvh "${X[@]}")
    timeout 120 $H run configs/report-table1-openmp.conf "${S[@]}" --set order=rounds --set threads="$W" --set backend=openmp --set schedule=tiles -q -o "$O/t1-bvh-$res.csv" > /dev/null 2>&1 || log "t1 $res rc $?"
    $H table "$O/t1-bvh-$res.csv" --ceiling "$O/ceiling-$res.csv" > "$O/t1-bvh-$res-table.md" 2>&1
    timeout 120 $H run configs/report-table2-mpi.conf "${S[@]}" --set order=rounds --set ranks="$W" --set backend=mpi --set mpi_schedule=dynamic -q -o "$O/t2-bvh-$res.csv" > /dev/null 2>&1 || log "t2 $res rc $?"
    $H table "$O/t2-bvh-$res.csv" --ceiling "$O/ceiling-$res.csv" > "$O/t2-bvh-$res-table.md" 2>&1
    log "tables $res"
  done ;;
keys)
  f() { tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|join_ms|backups|backups_won|rank_claims|rank_start_ms|rank_work_ms|rank_end_ms|rank_faults)=' | tr '\n' ' '; echo; }
  for i in 1 2 3 4 5; do
    for w in ${KEYS_WORKERS:-$N}; do
      echo "== omp $w 512x384"; $RT -q -b openmp -t $w -r 512x384 $dragon -o /tmp/k.png | f
      echo "== mpi $w 512x384"; mpirun --bind-to core -np $w $RT -b mpi -q -r 512x384 $dragon -o /tmp/k.png | f
    done
  done > "$O/keys.txt" 2>&1; log keys ;;
none)
  S=(--set scene_dir=$course --set resolution=512x384 --set accel=none --set repeats=3)
  timeout $(( $(left) - 10 )) $H run configs/report-table1-openmp.conf "${S[@]}" --set threads="$N" --set backend=openmp --set schedule=tiles -q -o "$O/t1-none-512x384.csv" > /dev/null 2>&1 || log "none rc $?"
  timeout $(( $(left) - 10 )) $H run configs/report-table2-mpi.conf "${S[@]}" --set ranks="$N" --set backend=mpi --set mpi_schedule=dynamic -q -o "$O/t2-none-512x384.csv" > /dev/null 2>&1 || log "none mpi rc $?"
  log none ;;
bruteceil)
  res=${RES:-512x384}
  timeout ${CEIL_S:-100} $H ceiling configs/openmp-scaling-bvh.conf --set scene_dir=$course --set resolution=$res --set accel=none --set threads=$N --set schedule=tiles --repeats 1 -o "$O/ceiling-none-$res.csv" > "$O/ceiling-none-$res.log" 2>&1 || log "ceiling none rc $?"
  tail -3 "$O/ceiling-none-$res.log"
  timeout $(( $(left) - 10 )) $H run configs/report-table1-openmp.conf --set scene_dir=$course --set resolution=$res --set accel=none --set repeats=2 --set order=rounds --set threads="1 $N" --set backend=openmp --set schedule=tiles -q -o "$O/t1-none-$res.csv" > /dev/null 2>&1 || log "t1 none rc $?"
  $H table "$O/t1-none-$res.csv" --ceiling "$O/ceiling-none-$res.csv" > "$O/t1-none-$res-table.md" 2>&1
  log bruteceil ;;
brute2k)
  timeout $(( $(left) - 10 )) $H run configs/report-table1-openmp.conf --set scene_dir=$course --set resolution=2048x1536 --set accel=none --set repeats=${REP2K:-3} --set threads=$N --set backend=openmp --set schedule=tiles -q -o "$O/t1-none-2048x1536.csv" > /dev/null 2>&1 || log "brute2k rc $?"
  log brute2k ;;
paired)
  mkdir -p "$O/paired"; res=${RES:-512x384}
  S=(--set scene_dir=$course --set resolution=$res --set repeats=1 --set accel=bvh)
  for i in $(seq ${ROUNDS:-12}); do
    [ "$(left)" -lt 30 ] && break
    timeout 60 $H ceiling configs/openmp-scaling-bvh.conf --set scene_dir=$course --set resolution=$res --set threads=$N --set schedule=tiles --repeats 1 -o "$O/paired/ceil-$i.csv" > "$O/paired/ceil-$i.log" 2>&1 || log "paired ceiling $i rc $?"
    timeout 60 $H run configs/report-table2-mpi.conf "${S[@]}" --set ranks="1 $N" --set backend=mpi --set mpi_schedule=dynamic -q -o "$O/paired/t2-$i.csv" > /dev/null 2>&1 || log "paired t2 $i rc $?"
    timeout 60 $H run configs/report-table1-openmp.conf "${S[@]}" --set threads="1 $N" --set backend=openmp --set schedule=tiles -q -o "$O/paired/t1-$i.csv" > /dev/null 2>&1 || log "paired t1 $i rc $?"
    for t in t1 t2; do $H table "$O/paired/$t-$i.csv" --ceiling "$O/paired/ceil-$i.csv" --format json > "$O/paired/$t-$i.json" 2>&1; done
  done; log paired ;;
rounds)
  W=${WORKERS:-1 $N}
  for res in ${RES:-512x384}; do
    S=(--set scene_dir=$course --set resolution=$res --set repeats=${TREP:-9} --set accel=bvh --set order=rounds --set ceiling=rounds "${X[@]}")
    timeout $(( $(left) - 10 )) $H run configs/report-table2-mpi.conf "${S[@]}" --set ranks="$W" --set backend=mpi --set mpi_schedule=dynamic -q -o "$O/t2-rounds-$res.csv" > "$O/t2-rounds-$res.log" 2>&1 || log "t2 rounds $res rc $?"
    $H table "$O/t2-rounds-$res.csv" > "$O/t2-rounds-$res-table.md" 2>&1
    timeout $(( $(left) - 10 )) $H run configs/report-table1-openmp.conf "${S[@]}" --set threads="$W" --set backend=openmp --set schedule=tiles -q -o "$O/t1-rounds-$res.csv" > "$O/t1-rounds-$res.log" 2>&1 || log "t1 rounds $res rc $?"
    $H table "$O/t1-rounds-$res.csv" > "$O/t1-rounds-$res-table.md" 2>&1
    log "rounds $res"
  done ;;
one)
  for res in 512x384 2048x1536; do
    printf 'study: one-worker\nscene_dir: %s\nscenes: dragon\nbackend: serial openmp mpi\naccel: bvh\nresolution: %s\nschedule: tiles\nmpi_schedule: dynamic\nthreads: 1\nranks: 1\npin: close\norder: rounds\nrepeats: 10\ntimeout: 60\n' $course $res > /tmp/one.conf
    timeout 150 $H run /tmp/one.conf -q -o "$O/one-$res.csv" > /dev/null 2>&1 || log "one $res rc $?"
    $H table "$O/one-$res.csv" > "$O/one-$res-table.md" 2>&1
  done; log one ;;
hybrid)
  P=""; for ((p = 1; p <= N; p *= 2)); do P="$P $p"; done
  for res in 512x384 2048x1536; do
    timeout ${HYB_S:-200} $H run configs/hybrid-dragon.conf --set scene_dir=$course --set resolution=$res --set ranks="$P" --set threads="$P" --set repeats=3 --set order=rounds -q -o "$O/hybrid-$res.csv" > /dev/null 2>&1 || log "hybrid $res rc $?"
    $H table "$O/hybrid-$res.csv" --ceiling "$O/ceiling-$res.csv" > "$O/hybrid-$res-table.md" 2>&1
  done; log hybrid ;;
diag)
  g() { tr ' ' '\n' | grep -E '^(render_ms|fork_ms|join_ms|backups|backups_won|thread_start_ms|thread_work_ms|rank_work_ms|rank_end_ms|render_ms_min)=' | tr '\n' ' '; echo; }
  export OMP_PLACES=cores OMP_PROC_BIND=close
  for i in 1 2 3 4 5 6; do
    echo "== omp $N pinned"; OMP_NUM_THREADS=$N $RT -q -b openmp -t $N -r 512x384 --cache /tmp/cc $dragon -o /tmp/k.png | g

    echo "== omp $N pinned prev"; OMP_NUM_THREADS=$N $PR -q -b openmp -t $N -r 512x384 --cache /tmp/cc $dragon -o /tmp/k.png | g
    echo "== mpi $N"; mpirun --bind-to core -np $N $RT -b mpi -q -r 512x384 --cache /tmp/cc $dragon -o /tmp/k.png | g
  done > "$O/diag.txt" 2>&1
  unset OMP_PLACES OMP_PROC_BIND; log diag ;;
lean)
  g() { tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|backups|backups_won|strips_per_claim|tiles_per_claim|rank_claims|rank_claim_ms|rank_start_ms|rank_work_ms|rank_end_ms|rank_faults)=' | tr '\n' ' '; echo; }
  mkdir -m 700 -p /tmp/cc-prev /tmp/cc-head
  for i in $(seq ${ROUNDS:-20}); do
    for res in 512x384 2048x1536; do for v in prev head; do
      x=$(bin $v)
      echo -n "round=$i version=$v res=$res "
      mpirun --bind-to core -np $N $x -b mpi -q -r $res --cache /tmp/cc-$v $dragon -o /tmp/k.png | g
    done; done
  done > "$O/lean.txt" 2>&1; log lean ;;
warm)
  g() { tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|runs|warmups|fork_ms|join_ms|thread_start_ms|thread_work_ms|rank_start_ms|rank_work_ms)=' | tr '\n' ' '; echo; }
  mkdir -m 700 -p /tmp/cc-head
  for i in $(seq ${ROUNDS:-8}); do
    for res in ${RES:-512x384 2048x1536}; do
      for w in "0 1" "3 9"; do
        set -- $w
        echo -n "round=$i res=$res backend=mpi workers=$N warmup=$1 "
        mpirun --bind-to core -np $N $RT -b mpi -q -r $res --warmup $1 --runs $2 --cache /tmp/cc-head $dragon -o /tmp/k.png | g
        echo -n "round=$i res=$res backend=openmp workers=$N warmup=$1 "
        OMP_PLACES=cores OMP_PROC_BIND=close $RT -b openmp -t $N -q -r $res --warmup $1 --runs $2 --cache /tmp/cc-head \
          $dragon -o /tmp/k.png | g
      done
      echo -n "round=$i res=$res backend=mpi workers=1 warmup=1 "
      mpirun --bind-to core -np 1 $RT -b mpi -q -r $res --warmup 1 --runs 3 --cache /tmp/cc-head $dragon -o /tmp/k.png | g
    done
  done > "$O/warm.txt" 2>&1; log warm ;;
build)
  g() { tr ' ' '\n' | grep -E '^(parse_ms|build_ms|build_threads|sah_cost)=' | tr '\n' ' '; echo; }
  ninja -C /tmp/bh renderer/scenegen > /dev/null 2>&1
  big=/tmp/large-1m.txt
  [ -s $big ] || /tmp/bh/renderer/scenegen --kind spheres --triangles 1000000 --seed 3 --resolution 800x600 -o $big
  spin() { taskset -c 0 sh -c 'while :; do :; done' > /dev/null 2>&1 & echo $!; }
  for i in $(seq ${ROUNDS:-7}); do for busy in 0 1; do
    bp=; [ $busy = 1 ] && bp=$(spin)
    for sc in scenes/demo.txt $dragon $big; do for v in prev head; do
      x=$(bin $v)
      echo -n "round=$i busy=$busy version=$v scene=$(basename $sc .txt) "
      $x -q -b serial -r 8x8 $sc -o /tmp/k.png | g
    done; done
    [ -n "$bp" ] && kill $bp
  done; done > "$O/build.txt" 2>&1; log build
  bp=$(spin)
  for i in $(seq 3); do for sc in scenes/demo.txt $dragon; do for v in prev head; do
    x=$(bin $v)
    echo -n "round=$i ranks=$N version=$v scene=$(basename $sc .txt) "
    timeout 60 mpirun --bind-to core -np $N $x -b mpi -q -r 64x48 --mpi-scene every $sc -o /tmp/k.png | g
  done; done; done > "$O/build-mpi.txt" 2>&1
  kill $bp; log build-mpi ;;
idle)
  g() { tr ' ' '\n' | grep -E '^(render_ms|fork_ms|join_ms|thread_start_ms|rank_start_ms|rank_work_ms)=' | tr '\n' ' '; echo; }
  mkdir -m 700 -p /tmp/cc-head
  spinners() { for c in $(seq 0 $((N - 1))); do chrt --idle 0 taskset -c $c sh -c 'while :; do :; done' > /dev/null 2>&1 & done; }
  # the run's keys, then the host's steal over it in % of all CPU time (/proc/stat)
  ticks() { awk '/^cpu /{t = 0; for (i = 2; i <= 9; i++) t += $i; print $9, t}' /proc/stat; }
  stolen() {
    local a b; a=$(ticks); "$@" | g | tr -d '\n'; b=$(ticks)
    echo "$a $b" | awk '{printf " steal_pct=%.2f\n", 100 * ($3 - $1) / ($4 - $2 + 1)}'
  }
  for i in $(seq ${ROUNDS:-8}); do
    for res in ${RES:-512x384 2048x1536}; do
      for mode in ${IDLE_MODES:-cold spun warm}; do
        w="0 1"; [ $mode = warm ] && w="3 9"
        set -- $w
        pol=(); [ $mode = active ] && pol=(OMP_WAIT_POLICY=active)
        [ $mode = spun ] && { spinners; sleep 0.5; }
        echo -n "round=$i res=$res backend=mpi workers=$N mode=$mode "
        stolen mpirun --bind-to core -np $N $RT -b mpi -q -r $res --warmup $1 --runs $2 --cache /tmp/cc-head $dragon \
          -o /tmp/k.png
        echo -n "round=$i res=$res backend=openmp workers=$N mode=$mode "
        stolen env "${pol[@]}" OMP_PLACES=cores OMP_PROC_BIND=close $RT -b openmp -t $N -q -r $res --warmup $1 --runs $2 \
          --cache /tmp/cc-head $dragon -o /tmp/k.png
        [ $mode = spun ] && { pkill -f 'while :; do :; done'; sleep 0.5; }
      done
    done
    [ "$(left)" -lt 40 ] && break
  done > "$O/idle.txt" 2>&1; log idle ;;
share)
  g() { tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|scene_copies|fork_ms|thread_start_ms|rank_claims|rank_start_ms|rank_work_ms)=' | tr '\n' ' '; echo; }
  mkdir -m 700 -p /tmp/cc-head
  for i in $(seq ${ROUNDS:-10}); do
    for res in ${RES:-512x384 2048x1536}; do for w in ${WORKERS:-$N}; do
      for v in "${VERS[@]}"; do
        x=$(bin $v)
        echo -n "round=$i res=$res backend=mpi workers=$w version=$v "
        timeout 60 mpirun --bind-to core -np $w $x -b mpi -q -r $res --cache /tmp/cc-head $dragon -o /tmp/k.png | g
      done
      echo -n "round=$i res=$res backend=openmp workers=$w version=head "
      OMP_PLACES=cores OMP_PROC_BIND=close $RT -b openmp -t $w -q -r $res --cache /tmp/cc-head $dragon -o /tmp/k.png | g
    done; done
    [ "$(left)" -lt 60 ] && break
  done > "$O/share.txt" 2>&1; log share ;;
layouts)
  g() { tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|backups|backups_won|fork_ms|rank_fork_ms|thread_start_ms|rank_work_ms|rank_faults)=' | tr '\n' ' '; echo; }
  mkdir -m 700 -p /tmp/cc-head
  for i in $(seq ${ROUNDS:-5}); do for w in "0 1" "3 9"; do
    set -- $w
    echo -n "round=$i warmup=$1 run=openmp-$N "
    OMP_PLACES=cores OMP_PROC_BIND=close $RT -b openmp -t $N -q -r ${RES:-512x384} --warmup $1 --runs $2 \
      --cache /tmp/cc-head $dragon -o /tmp/k.png | g
    for ((p = 1; p <= N; p *= 2)); do
      echo -n "round=$i warmup=$1 run=mpi-${p}x$((N / p)) "
      mpirun $(layout $p) -np $p -x OMP_PLACES=cores -x OMP_PROC_BIND=close $RT -b mpi -t $((N / p)) -q -r ${RES:-512x384} \
        --warmup $1 --runs $2 --cache /tmp/cc-head $dragon -o /tmp/k.png | g
    done
  done; [ "$(left)" -lt 40 ] && break; done > "$O/layouts.txt" 2>&1; log layouts ;;
gap)
  g() { tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|scene_copies|rank_work_ms|thread_work_ms|backups|backups_won|rank_claims|fork_ms)=' | tr '\n' ' '; echo; }
  ninja -C /tmp/bh tests/cpu/raytrace-testhooks > /dev/null 2>&1
  TH=/tmp/bh/tests/cpu/raytrace-testhooks
  mkdir -m 700 -p /tmp/cc-head
  W=(--warmup 3 --runs 9 -q --cache /tmp/cc-head)
  for i in $(seq ${ROUNDS:-8}); do for res in ${RES:-512x384}; do
    echo -n "round=$i res=$res run=openmp "
    OMP_PLACES=cores OMP_PROC_BIND=close $RT -b openmp -t $N -r $res "${W[@]}" $dragon -o /tmp/k.png | g
    for v in "${VERS[@]}"; do
      x=$(bin $v)
      echo -n "round=$i res=$res run=mpi-shared version=$v "
      mpirun --bind-to core -np $N $x -b mpi -r $res "${W[@]}" $dragon -o /tmp/k.png | g
    done
    echo -n "round=$i res=$res run=mpi-private "
    mpirun --bind-to core -np $N -x RT_MPI_TEST_SHM_FAIL=0 $TH -b mpi -r $res "${W[@]}" $dragon -o /tmp/k.png | g
    for v in prev head; do for p in 1 2; do
      x=$(bin $v)
      echo -n "round=$i res=$res run=mpi-${p}x$((N / p)) version=$v "
      mpirun $(layout $p) -np $p -x OMP_PLACES=cores -x OMP_PROC_BIND=close $x -b mpi -t $((N / p)) -r $res \
        "${W[@]}" $dragon -o /tmp/k.png | g
    done; done
  done; [ "$(left)" -lt 40 ] && break; done > "$O/gap.txt" 2>&1; log gap ;;
pixcost)
  g() { tr ' ' '\n' | grep -E '^(render_ms|render_ms_min|thread_work_ms|rank_work_ms)=' | tr '\n' ' '; echo; }
  mkdir -m 700 -p /tmp/cc-head
  W=(--warmup 3 --runs 9 -q --cache /tmp/cc-head)
  for i in $(seq ${ROUNDS:-4}); do for sc in dragon glass; do for res in ${RES:-512x384 2048x1536}; do
    f=$dragon; [ $sc = glass ] && f=$R/scenes/glass.txt
    p="round=$i scene=$sc res=$res"
    echo -n "$p run=openmp "; OMP_PLACES=cores OMP_PROC_BIND=close $RT -b openmp -t $N -r $res "${W[@]}" $f -o /tmp/k.png | g
    for m in dynamic rows; do
      echo -n "$p run=mpi-$m "; mpirun --bind-to core -np $N $RT -b mpi --mpi-schedule $m -r $res "${W[@]}" $f -o /tmp/k.png | g
    done
    echo -n "$p run=mpi-1x$N-rows "; mpirun --bind-to none -np 1 -x OMP_PLACES=cores -x OMP_PROC_BIND=close $RT -b mpi \
      --mpi-schedule rows -t $N -r $res "${W[@]}" $f -o /tmp/k.png | g
  done; done; [ "$(left)" -lt 40 ] && break; done > "$O/pixcost.txt" 2>&1; log pixcost ;;
cache)
  mkdir -m 700 -p /tmp/cc-head
  res=${RES:-512x384}
  $RT -q -b serial -r 8x8 --cache /tmp/cc-head $dragon -o /tmp/k.png > /dev/null
  M="mpirun --bind-to core -np $N $RT -b mpi -q -r $res" P="env OMP_PLACES=cores OMP_PROC_BIND=close $RT -b openmp -t $N -q -r $res"
  for run in "$M" "$P"; do
    timeout 200 $H ab "$run --cache /tmp/cc-head -o /tmp/a.png $dragon" "$run -o /tmp/b.png $dragon" \
      --metric 'render_ms=([0-9.]+)' --rounds ${ROUNDS:-16} >> "$O/cache.txt" 2>&1
  done; log cache ;;
order)
  g() { tr ' ' '\n' | grep -E '^(render_ms|parse_ms|build_ms|rank_work_ms)=' | tr '\n' ' '; }
  ticks() { awk '/^cpu /{t = 0; for (i = 2; i <= 9; i++) t += $i; print $9, t}' /proc/stat; }
  mkdir -m 700 -p /tmp/cc-head
  res=${RES:-512x384}
  $RT -q -b serial -r 8x8 --cache /tmp/cc-head $dragon -o /tmp/k.png > /dev/null
  for i in $(seq ${ROUNDS:-12}); do for v in cached built cached-after-one built-after-one; do
    c=(); [ ${v%%-*} = cached ] && c=(--cache /tmp/cc-head)
    [ $v != ${v%-after-one} ] && mpirun --bind-to core -np 1 $RT -b mpi -q -r $res "${c[@]}" $dragon -o /tmp/k.png > /dev/null
    a=$(ticks); echo -n "round=$i run=$v "
    mpirun --bind-to core -np $N $RT -b mpi -q -r $res "${c[@]}" $dragon -o /tmp/k.png | g
    b=$(ticks); echo "$a $b" | awk '{printf "steal_pct=%.2f\n", 100 * ($3 - $1) / ($4 - $2 + 1)}'
  done; [ "$(left)" -lt 40 ] && break; done > "$O/order.txt" 2>&1; log order ;;
bigbuild)
  g() { tr ' ' '\n' | grep -E '^(parse_ms|build_ms|build_threads|sah_cost|huge_pages)=' | tr '\n' ' '; echo; }
  ninja -C /tmp/bh renderer/scenegen > /dev/null 2>&1
  big=/tmp/large-4m.txt
  [ -s $big ] || /tmp/bh/renderer/scenegen --kind spheres --triangles 4000000 --seed 1 --resolution 1920x1080 -o $big
  for i in $(seq ${ROUNDS:-3}); do for t in ${BUILD_THREADS:-16 $((N / 2)) $N}; do for v in prev head; do
    x=$(bin $v)
    echo -n "round=$i threads=$t version=$v "
    $x -q -b serial -r 8x8 --build-threads $t $big -o /tmp/k.png | g
  done; done; done > "$O/bigbuild.txt" 2>&1; log bigbuild ;;
esac; done
log done
