#!/bin/sh
# Slurm support without Slurm: `run --launcher srun` command lines (dry run),
# a real study launched through a fake srun on PATH, and `harness slurm`'s
# sbatch script (#SBATCH sizing, option errors, bash -n, and the script itself
# run with a fake job environment, twice: the second continues the CSV), and
# --submit's following and reporting against a fake sbatch/squeue.
# usage: test-slurm.sh HARNESS FAKE_RAYTRACE FAKE_SRUN
set -u
abs() { (cd "$(dirname "$1")" && echo "$(pwd)/$(basename "$1")"); }
H=$(abs "$1") FAKE=$(abs "$2") SRUN=$(abs "$3")
T=$(mktemp -d /tmp/hx-slurm-XXXXXX)
trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
has() { grep -q -F -- "$2" "$1" || { cat "$1"; fail "$1: no '$2'"; }; }
echo "# dummy" > "$T/ok.txt"
mkdir "$T/bin" && ln -s "$SRUN" "$T/bin/srun"
# the harness must not rely on the caller's OpenMP/Open MPI settings
unset OMP_NUM_THREADS OMP_PLACES OMP_PROC_BIND SRUN_CPUS_PER_TASK \
      OMPI_ALLOW_RUN_AS_ROOT OMPI_ALLOW_RUN_AS_ROOT_CONFIRM SLURM_JOB_NUM_NODES

# ---- dry run: the srun command line of every MPI run ----
cat > "$T/dry.conf" <<CONF
study: dry
scene_dir: $T
scenes: ok
backend: serial mpi
ranks: 2 4 4096
threads: 1 2
pin: close none
repeats: 1
oversubscribe: allow
raytrace: $FAKE
CONF
"$H" run "$T/dry.conf" --dry-run --launcher srun > "$T/dry" 2>/dev/null || fail "dry-run failed"
has "$T/dry" "OMP_NUM_THREADS=2 OMP_PLACES=cores OMP_PROC_BIND=close SRUN_CPUS_PER_TASK=2 srun --ntasks=4 --cpus-per-task=2 --cpu-bind=cores --distribution=block:block "
has "$T/dry" "OMP_NUM_THREADS=1 OMP_PLACES=cores OMP_PROC_BIND=close SRUN_CPUS_PER_TASK=1 srun --ntasks=2 --cpus-per-task=1 --cpu-bind=cores --distribution=block:block "
has "$T/dry" "OMP_NUM_THREADS=2 SRUN_CPUS_PER_TASK=2 srun --ntasks=4 --cpus-per-task=2 --cpu-bind=none --distribution=block:block "
has "$T/dry" "srun --ntasks=4096 --cpus-per-task=1 --cpu-bind=cores --distribution=block:block --overcommit $FAKE --backend mpi --threads 1 "
[ "$(grep -c ' srun --ntasks=' "$T/dry")" -eq 12 ] || fail "expected 12 srun runs"
grep -q -E 'mpirun|OMPI_ALLOW' "$T/dry" && fail "srun dry run mentions mpirun"
grep -q -E '^    [A-Z_=0-9 ]*srun .*--backend serial' "$T/dry" && fail "serial run launched by srun"
# mpirun stays the default; the config key selects srun; the option wins
"$H" run "$T/dry.conf" --dry-run > "$T/dry-m" 2>/dev/null || fail "mpirun dry-run failed"
has "$T/dry-m" "mpirun --oversubscribe --bind-to core:overload-allowed --map-by core -np 4096 "
grep -q ' srun ' "$T/dry-m" && fail "srun used without --launcher"
printf 'launcher: srun\n' >> "$T/dry.conf"
"$H" run "$T/dry.conf" --dry-run 2>/dev/null | grep -q ' srun --ntasks=2 ' || fail "launcher: srun ignored"
"$H" run "$T/dry.conf" --dry-run --launcher mpirun 2>/dev/null | grep -q ' srun ' \
  && fail "--launcher mpirun did not override the config"
out=$("$H" run "$T/dry.conf" --dry-run --launcher pbs 2>&1) && fail "--launcher pbs accepted"
echo "$out" | grep -q "^harness run: --launcher: expected mpirun|srun, got 'pbs'$" || fail "bad --launcher error: $out"
printf 'scenes: ok\nscene_dir: %s\nlauncher: slurm\n' "$T" > "$T/badl.conf"
out=$("$H" run "$T/badl.conf" --dry-run 2>&1) && fail "launcher: slurm accepted"
echo "$out" | grep -q "badl.conf:3: launcher: expected mpirun|srun, got 'slurm'" || fail "bad launcher key error: $out"

# ---- a real study through the fake srun ----
cat > "$T/run.conf" <<CONF
study: viasrun
scene_dir: $T
scenes: ok
backend: serial mpi
ranks: 1
threads: 1
pin: close none
repeats: 2
raytrace: $FAKE
CONF
FAKE_SRUN_LOG=$T/srun.log PATH="$T/bin:$PATH" "$H" run "$T/run.conf" --launcher srun \
  -o "$T/run.csv" 2> "$T/runlog" || { cat "$T/runlog"; fail "run through srun failed"; }
[ "$(grep -c ',ok,,0,' "$T/run.csv")" -eq 8 ] || { cat "$T/runlog"; fail "expected 8 ok rows"; }
[ "$(grep -c '^args: ' "$T/srun.log")" -eq 4 ] || { cat "$T/srun.log"; fail "srun not called for the 4 MPI runs"; }
has "$T/srun.log" "args: --ntasks=1 --cpus-per-task=1 --cpu-bind=cores --distribution=block:block $FAKE --backend mpi --threads 1 -o "
has "$T/srun.log" "args: --ntasks=1 --cpus-per-task=1 --cpu-bind=none --distribution=block:block $FAKE --backend mpi"
has "$T/srun.log" "env: OMP_NUM_THREADS=1 OMP_PLACES=cores OMP_PROC_BIND=close SRUN_CPUS_PER_TASK=1 OMPI_ALLOW_RUN_AS_ROOT=unset"
has "$T/srun.log" "env: OMP_NUM_THREADS=1 OMP_PLACES=unset OMP_PROC_BIND=unset SRUN_CPUS_PER_TASK=1"
grep -q ',mpi,.*,ok,' "$T/run.csv" || fail "no ok mpi row"

# ---- harness slurm: the sbatch script ----
cat > "$T/hyb.conf" <<CONF
study: hyb
scene_dir: $T
scenes: ok
backend: serial openmp mpi
ranks: 1 2 4
threads: 1 2
repeats: 1
raytrace: $FAKE
CONF
"$H" slurm "$T/hyb.conf" > "$T/job.sh" || fail "harness slurm failed"
for l in '#!/bin/bash' '#SBATCH --job-name=hyb' '#SBATCH --nodes=1' '#SBATCH --ntasks=4' \
         '#SBATCH --cpus-per-task=2' '#SBATCH --exclusive' '#SBATCH --hint=nomultithread' \
         '#SBATCH --time=01:00:00' '#SBATCH --output=slurm-%j.out' 'cd "$SLURM_SUBMIT_DIR"' \
         "build/harness/harness run $T/hyb.conf --launcher srun -o results/hyb-slurm.csv --resume" \
         'build/harness/harness table results/hyb-slurm.csv' 'export SLURM_MPI_TYPE=pmix'; do
  grep -q -x -F -- "$l" "$T/job.sh" || grep -q -F -- "$l " "$T/job.sh" || { cat "$T/job.sh"; fail "script lacks: $l"; }
done
[ "$(grep -c '^#SBATCH' "$T/job.sh")" -eq 8 ] || fail "expected 8 #SBATCH lines"
grep -q -- '--partition\|--account' "$T/job.sh" && fail "partition/account without the options"
bash -n "$T/job.sh" || fail "bash -n rejects the script"
# sbatch reads #SBATCH only before the first command: all of them come first
awk '/^#SBATCH/ && cmd { exit 1 } /^[^#]/ { cmd = 1 }' "$T/job.sh" || fail "#SBATCH after a command"
"$H" slurm "$T/hyb.conf" -o "$T/job2.sh" --nodes 2 --time 02:30:00 --partition short \
  --account proj-1 --job-name scan.1 2> "$T/slog" || fail "harness slurm -o failed"
for l in '#SBATCH --nodes=2' '#SBATCH --time=02:30:00' '#SBATCH --partition=short' \
         '#SBATCH --account=proj-1' '#SBATCH --job-name=scan.1'; do
  grep -q -x -F -- "$l" "$T/job2.sh" || { cat "$T/job2.sh"; fail "script lacks: $l"; }
done
bash -n "$T/job2.sh" || fail "bash -n rejects the -o script"
has "$T/slog" "sbatch $T/job2.sh"
# -o writes its own script over, never another file (a results CSV)
"$H" slurm "$T/hyb.conf" -o "$T/job2.sh" 2> /dev/null || fail "slurm -o over its own script"
printf 'study,run_id\nx,1\n' > "$T/rows.csv"
"$H" slurm "$T/hyb.conf" -o "$T/rows.csv" 2> "$T/rows.err" && fail "slurm -o wrote over a CSV"
[ "$(cat "$T/rows.csv")" = "$(printf 'study,run_id\nx,1')" ] || fail "slurm -o changed the CSV"
[ "$(wc -l < "$T/rows.err")" -eq 1 ] && grep -q "rows.csv: holds something else" "$T/rows.err" || fail "-o refusal: $(cat "$T/rows.err")"
# no MPI in the study: one task
printf 'scenes: ok\nscene_dir: %s\nbackend: openmp\nthreads: 1 8\n' "$T" > "$T/omp.conf"
"$H" slurm "$T/omp.conf" > "$T/omp.sh" || fail "slurm on an OpenMP study"
grep -q -x -- '#SBATCH --ntasks=1' "$T/omp.sh" && grep -q -x -- '#SBATCH --cpus-per-task=8' "$T/omp.sh" \
  || fail "OpenMP-only sizing"
# a GPU per rank: the script asks Slurm for one per task, srun binds it
printf 'study: gpus\nscenes: ok\nscene_dir: %s\nbackend: mpi-cuda\nranks: 1 2\nraytrace: %s\n' "$T" "$FAKE" > "$T/gpu.conf"
"$H" slurm "$T/gpu.conf" > "$T/gpu.sh" || fail "slurm on an mpi-cuda study"
for l in '#SBATCH --gpus-per-task=1' '#SBATCH --gpu-bind=closest' '#SBATCH --ntasks=2'; do
  grep -q -x -F -- "$l" "$T/gpu.sh" || { cat "$T/gpu.sh"; fail "mpi-cuda script lacks: $l"; }
done
bash -n "$T/gpu.sh" || fail "bash -n rejects the mpi-cuda script"
"$H" run "$T/gpu.conf" --dry-run --launcher srun > "$T/dry-g" 2>/dev/null || fail "mpi-cuda dry-run failed"
has "$T/dry-g" "CUDA_DEVICE_ORDER=PCI_BUS_ID srun --ntasks=2 --cpus-per-task=1 --cpu-bind=cores --distribution=block:block --gpus-per-task=1 --gpu-bind=closest $FAKE --backend mpi-cuda "
# bad options: one line naming the option, exit 1
bad() {
  want=$1; shift
  out=$("$H" slurm "$@" 2>&1) && fail "accepted: slurm $*"
  [ "$(printf '%s\n' "$out" | wc -l)" -eq 1 ] || fail "not one line: $out"
  echo "$out" | grep -q -F -- "$want" || fail "wanted '$want', got: $out"
}
bad "harness slurm: --nodes: expected an integer >= 1, got '0'" "$T/hyb.conf" --nodes 0
bad "harness slurm: --nodes: 8 nodes but the largest run has 4 rank(s)" "$T/hyb.conf" --nodes 8
bad "harness slurm: --time: expected HH:MM:SS" "$T/hyb.conf" --time 1h
bad "harness slurm: --time: expected HH:MM:SS" "$T/hyb.conf" --time 01:60:00
bad "harness slurm: --partition: expected a name" "$T/hyb.conf" --partition 'a b'
bad "harness slurm: --account: expected a name" "$T/hyb.conf" --account ''
bad "harness slurm: --job-name: expected a name" "$T/hyb.conf" --job-name 'x;y'
bad "harness slurm: expected one CONFIG argument" 
bad "badl.conf:3: launcher" "$T/badl.conf"
bad "harness slurm: $T/nodir/x.sh: cannot write" "$T/hyb.conf" -o "$T/nodir/x.sh"
"$H" slurm --help > /dev/null || fail "slurm --help"
"$H" --help | grep -q 'slurm CONFIG' || fail "slurm missing from harness --help"

# ---- the generated script, run as Slurm would (fake job env, fake srun) ----
mkdir -p "$T/repo/build/harness" && ln -s "$H" "$T/repo/build/harness/harness"
sed 's/^threads: 1 2/threads: 1/; s/^ranks: 1 2 4/ranks: 1/' "$T/hyb.conf" > "$T/repo/small.conf"
(cd "$T/repo" && "$H" slurm small.conf -o job.sh) 2>/dev/null || fail "slurm for the job run"
(cd / && SLURM_SUBMIT_DIR=$T/repo SLURM_JOB_ID=42 SLURM_JOB_NUM_NODES=1 SLURM_JOB_NODELIST=node1 \
  FAKE_SRUN_LOG=$T/job-srun.log PATH="$T/bin:$PATH" bash "$T/repo/job.sh") > "$T/joblog" 2>&1 \
  || { cat "$T/joblog"; fail "the generated script failed"; }
[ "$(grep -c ',ok,,0,' "$T/repo/results/hyb-slurm.csv")" -eq 3 ] || { cat "$T/joblog"; fail "job CSV"; }
grep -q -- '--launcher srun' "$T/job-srun.log" && fail "harness options leaked to srun"
grep -q '^args: --ntasks=1 ' "$T/job-srun.log" || fail "job did not launch MPI through srun"
has "$T/joblog" "### Per configuration"
# a resubmission (another job id) continues the same CSV: nothing runs twice
(cd / && SLURM_SUBMIT_DIR=$T/repo SLURM_JOB_ID=43 SLURM_JOB_NUM_NODES=1 SLURM_JOB_NODELIST=node1 \
  FAKE_SRUN_LOG=$T/job-srun.log PATH="$T/bin:$PATH" bash "$T/repo/job.sh") > "$T/joblog2" 2>&1 \
  || { cat "$T/joblog2"; fail "the resubmitted script failed"; }
[ "$(grep -c ',ok,,0,' "$T/repo/results/hyb-slurm.csv")" -eq 3 ] || fail "the resubmission added rows"
has "$T/joblog2" "3 skipped (resume)"

# ---- sizes and the MPI plugin from the options ----
"$H" slurm "$T/hyb.conf" --ntasks 2 --cpus-per-task 1 --mpi site > "$T/job3.sh" || fail "sizes from options"
grep -q -x -- '#SBATCH --ntasks=2' "$T/job3.sh" && grep -q -x -- '#SBATCH --cpus-per-task=1' "$T/job3.sh" \
  || fail "--ntasks/--cpus-per-task ignored"
grep -q SLURM_MPI_TYPE "$T/job3.sh" && fail "--mpi site still sets SLURM_MPI_TYPE"
"$H" slurm "$T/hyb.conf" --mpi pmi2 | grep -q -x 'export SLURM_MPI_TYPE=pmi2' || fail "--mpi pmi2"
bad "harness slurm: --mpi: expected a name" "$T/hyb.conf" --mpi 'pmix;id'
bad "harness slurm: --ntasks: expected an integer >= 1, got 'x'" "$T/hyb.conf" --ntasks x
bad "harness slurm: --cpus-per-task: expected an integer >= 1" "$T/hyb.conf" --cpus-per-task 0
bad "harness slurm: --max-wait: expected HH:MM:SS" "$T/hyb.conf" --max-wait 5

# ---- --submit against fake sbatch/squeue (the real cluster: test-slurm-real.sh) ----
mkdir "$T/sbin" "$T/nosb"
printf '#!/bin/sh\necho "$*" >> "$FAKE_SLURM/sbatch.args"\n[ -f "$FAKE_SLURM/sbatch-fails" ] && { echo "sbatch: error: Batch job submission failed" >&2; exit 1; }\necho "4242;cluster"\n' > "$T/sbin/sbatch"
printf '#!/bin/sh\ncat "$FAKE_SLURM/state"\n' > "$T/sbin/squeue"
printf '#!/bin/sh\nexit 1\n' > "$T/sbin/sacct"
printf '#!/bin/sh\nexit 1\n' > "$T/sbin/scontrol"
chmod +x "$T/sbin/"*
sub() { (cd "$T/repo" && FAKE_SLURM=$T PATH="$T/sbin:$PATH" timeout 30 "$H" slurm small.conf --submit "$@"); }
# no sbatch at all: one line, exit 1
out=$(cd "$T/nosb" && PATH=$T/nosb "$H" slurm "$T/repo/small.conf" --submit 2>&1) && fail "--submit without sbatch"
[ "$(printf '%s\n' "$out" | wc -l)" -eq 1 ] && echo "$out" | grep -q "cannot run sbatch" || fail "no-sbatch error: $out"
touch "$T/sbatch-fails"
out=$(sub 2>&1) && fail "a failing sbatch was not an error"
echo "$out" | grep -q "^harness slurm: --submit: sbatch results/hyb-slurm.sbatch failed (exit 1)$" || fail "sbatch failure: $out"
rm "$T/sbatch-fails"
has "$T/sbatch.args" "--parsable results/hyb-slurm.sbatch"
cmp -s "$T/repo/results/hyb-slurm.sbatch" "$T/repo/job.sh" || fail "--submit wrote another script than -o"
echo 'COMPLETED|None|0:05|node1' > "$T/state"
sub > "$T/sub.out" 2> "$T/sub.err" || { cat "$T/sub.err"; fail "--submit of a completed job"; }
has "$T/sub.err" "harness slurm: submitted results/hyb-slurm.sbatch as job 4242 "
has "$T/sub.err" "harness slurm: job 4242 COMPLETED: 3/3 rows in results/hyb-slurm.csv, log slurm-4242.out"
has "$T/sub.out" "### Per configuration"
echo 'FAILED|NonZeroExitCode|0:03|node1' > "$T/state"
printf 'job 4242: 1 node(s): node1\nharness run: --resume: boom\n' > "$T/repo/slurm-4242.out"
sub -o job4.sh > /dev/null 2> "$T/sub.err" && fail "a failed job exited 0"
has "$T/sub.err" "harness slurm: job 4242 ended FAILED: 3/3 rows in results/hyb-slurm.csv; log slurm-4242.out ends: 'harness run: --resume: boom'; once fixed, --submit again continues the CSV"
has "$T/sbatch.args" "--parsable job4.sh"
# a job that can never start: said at once, not after --max-wait
printf 'PENDING|PartitionConfig|0:00|\n' > "$T/state"
sub > /dev/null 2> "$T/sub.err" && fail "a job that cannot start exited 0"
has "$T/sub.err" "harness slurm: job 4242 cannot start as submitted (PENDING: PartitionConfig)"
# a job that never ends: --max-wait stops following (the job is left alone)
printf 'PENDING|Priority|0:00|\n' > "$T/state"
start=$(date +%s)
sub --max-wait 00:00:02 > /dev/null 2> "$T/sub.err" && fail "--max-wait did not fail"
[ $(( $(date +%s) - start )) -le 6 ] || fail "--max-wait 2 s took longer than 6 s"
has "$T/sub.err" "harness slurm: job 4242 PENDING (Priority)"
has "$T/sub.err" "harness slurm: stopped following job 4242 after 2 s (--max-wait)"
echo "slurm test passed"
