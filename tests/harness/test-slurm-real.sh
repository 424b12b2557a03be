#!/bin/sh
# `harness slurm --submit` against a real single-node Slurm cluster started
# here: munged on its own key and socket, slurmctld and slurmd on localhost
# with the machine's own CPUs and memory (slurmd -C), every file in a temp
# folder, ports of their own (a site's Slurm is left alone). A hybrid
# MPI+OpenMP study runs through sbatch and srun (--mpi=pmix); a second one
# is cancelled half-way and --submit again continues its CSV; a failing job
# and one larger than the node each get one line and exit 1.
# Exit 77 (skip) only when Slurm cannot be started: not root, or the
# packages are missing and apt-get cannot install them. No cgroups are
# needed (slurm_conf_common in slurm-lib.sh): a daemon that does not start
# fails the test with its log.
# usage: test-slurm-real.sh HARNESS RAYTRACE
set -u
. "$(dirname "$0")/slurm-lib.sh"
H=$(abs "$1") RT=$(abs "$2")
slurm_need "$RT"

T=$(mktemp -d /tmp/hx-slurm-real-XXXXXX)
chmod 755 "$T"
export SLURM_CONF=$T/slurm.conf
# Stop what this test started, by pid: jobs first, then the daemons.
cleanup() { slurm_cancel_all; slurm_kill_daemons; rm -rf "$T"; }
trap cleanup EXIT
trap 'exit 1' INT TERM HUP

munge_start
mkdir "$T/spool"

# ---- slurm.conf: two free ports, the node as slurmd -C sees it ----
# A port is taken if any socket has it as its local port, in any state (a
# connection's or one in TIME_WAIT, not only a listener: slurmctld's bind
# fails on those too). The pairs lie below Linux's ephemeral range
# (32768-60999), so no outgoing connection takes one between the check and
# the daemons' start.
in_use() { grep -q -i "^ *[0-9]*: [0-9A-F]*:$(printf %04X "$1") " /proc/net/tcp /proc/net/tcp6 2> /dev/null; }
port=$((10000 + $$ % 10000 * 2)) # even: two tests side by side never share a pair
while in_use $port || in_use $((port + 1)); do port=$((port + 2)); done
node=$(slurmd -C | head -1 | sed 's/^NodeName=[^ ]*/NodeName=localhost/')
case $node in NodeName=localhost\ CPUs=*) ;; *) fail "unexpected slurmd -C output: $node" ;; esac
cpus=$(echo "$node" | sed 's/.* CPUs=\([0-9]*\).*/\1/')
# addresses given, not looked up: a machine without /etc/hosts (a bare
# debootstrap chroot) cannot resolve even "localhost"
{ cat <<CONF
ClusterName=raybench-test
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmdSpoolDir=$T/spool
SlurmdPidFile=$T/slurmd.pid
SlurmdLogFile=$T/log/slurmd.log
# job ids of their own, so that srun's PMIx folders (named by job and step)
# never meet those of a second cluster on the machine
FirstJobId=$((port * 10))
CONF
  slurm_conf_common
  echo "$node NodeAddr=127.0.0.1 NodeHostname=localhost State=UNKNOWN"
  echo "PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP"
} > "$SLURM_CONF"
slurmctld -f "$SLURM_CONF" -c || { slurm_logs; fail "slurmctld did not start"; }
slurmd -f "$SLURM_CONF" -N localhost || { slurm_logs; fail "slurmd did not start"; }
slurm_wait_idle localhost
srun --mpi=list 2>&1 | grep -q pmix || fail "Slurm has no mpi/pmix plugin (srun --mpi=list)"

# ---- the study: a scene written here, serial and MPI ranks x threads ----
mkdir -p "$T/repo/build/harness"
ln -s "$H" "$T/repo/build/harness/harness"
slurm_scene
# accel none at 640x480: a few tenths of a second a run, so the study lasts
# long enough to be cancelled half-way
cat > "$T/repo/real.conf" <<CONF
study: real
scene_dir: $T/scenes
scenes: balls
backend: serial mpi
accel: none
resolution: 640x480
ranks: 1 2
threads: 1 2
pin: close
repeats: 2
warmup: 0
timeout: 60
scene_cache: off
raytrace: $RT
CONF
# 2 ranks x 2 threads needs 4 cores: on a smaller node ask for what fits and
# let the harness refuse the run that does not (oversubscribe: refuse)
sizes="" refused=0
if [ "$cpus" -lt 4 ]; then sizes="--ntasks 2 --cpus-per-task 1" refused=2; fi
[ "$cpus" -ge 2 ] || skip "the node has $cpus CPU: 2 ranks need 2"
submit() { (cd "$T/repo" && timeout 400 "$H" slurm "$1" --submit $sizes --time 00:10:00 --max-wait 00:05:00); }

# checks the CSV of a finished study; $1 the CSV
check_csv() {
  python3 - "$1" "$refused" <<'PY' || fail "CSV check of $1"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
refused = int(sys.argv[2])
def bad(msg):
    print(msg); sys.exit(1)
if len(rows) != 10: bad("%d rows, expected 10" % len(rows))
if len({r["run_id"] for r in rows}) != 10: bad("duplicated run ids")
got = sorted((r["backend"], r["ranks"], r["threads"]) for r in rows)
want = sorted([("serial", "-", "-")] * 2 + [("mpi", p, t) for p in "12" for t in "12"] * 2)
if got != want: bad("runs %s, expected %s" % (got, want))
for r in rows:
    hybrid = r["backend"] == "mpi" and r["ranks"] == "2" and r["threads"] == "2"
    if hybrid and refused:
        if r["status"] != "refused": bad("2x2 on a small node: status %s" % r["status"])
        continue
    if r["status"] != "ok" or r["exit_code"] != "0": bad("%s: status %s" % (r["run_id"], r["status"]))
    # srun's binding inside the allocation is the harness's plan
    if r["pin"] != "close" or r["cores_planned"] in ("", "-") or r["pin_held"] != "yes":
        bad("%s: pinning not held (%s %s %s)" % (r["run_id"], r["pin"], r["cores_planned"], r["pin_held"]))
    if r["ranks"] == "2" and "rank_cores=0/1" not in r["extra"]:
        bad("%s: the two ranks did not get a core each: %s" % (r["run_id"], r["extra"]))
    if r["backend"] == "mpi" and (r["rec_ranks"] != r["ranks"] or r["rec_threads"] != r["threads"]):
        bad("%s: the record says ranks=%s threads=%s" % (r["run_id"], r["rec_ranks"], r["rec_threads"]))
if sum(r["status"] == "refused" for r in rows) != refused: bad("refused rows")
if len({r["image_fnv1a"] for r in rows if r["status"] == "ok"}) != 1: bad("images differ")
PY
}

# ---- 1: the whole study through sbatch and srun ----
submit real.conf > "$T/sub1.out" 2> "$T/sub1.err" || { cat "$T/sub1.err"; slurm_logs; fail "--submit failed"; }
cat "$T/sub1.err"
grep -q '^harness slurm: job [0-9]* COMPLETED: 10/10 rows in results/real-slurm.csv' "$T/sub1.err" ||
  fail "no COMPLETED line"
grep -q '### Per configuration' "$T/sub1.out" || fail "--submit printed no table"
check_csv "$T/repo/results/real-slurm.csv"
job=$(submitted_job "$T/sub1.err")
log=$T/repo/slurm-$job.out
grep -q 'export SLURM_MPI_TYPE=pmix' "$T/repo/results/real-slurm.sbatch" || fail "no SLURM_MPI_TYPE in the script"
grep -q "^job $job: 1 node(s): localhost" "$log" || { cat "$log"; fail "job log"; }
grep -q 'mpirun' "$log" && fail "the job log mentions mpirun"

# ---- 2: cancelled half-way, then continued by --submit again ----
sed 's/^study: real$/study: cut/' "$T/repo/real.conf" > "$T/repo/cut.conf"
csv=$T/repo/results/cut-slurm.csv
submit cut.conf > /dev/null 2> "$T/sub2.err" &
sub=$!
# An MPI run in progress (a rank of a step of this job, a task of
# slurmstepd, not of the harness): its tasks are killed with the job and the
# run can end before the harness's own SIGTERM comes. The harness must see
# the job ending, not a failed run, and write no row for it.
mpi_running() {
  for p in $(pgrep -x raytrace); do
    pp=$(ps -o ppid= -p "$p" | tr -d ' ')
    [ "$(ps -o comm= -p "$pp" 2> /dev/null)" = slurmstepd ] &&
      tr '\0' '\n' < "/proc/$p/environ" 2> /dev/null | grep -qx "SLURM_JOB_ID=$1" && return 0
  done
  return 1
}
i=0 job=""
until [ "$(($(cat "$csv" 2> /dev/null | wc -l) - 1))" -ge 2 ] && [ -n "$job" ] && mpi_running "$job"; do
  i=$((i + 1)); [ $i -le 2400 ] || { cat "$T/sub2.err"; fail "no MPI run after 2 rows in 120 s"; }
  job=$(submitted_job "$T/sub2.err")
  sleep 0.05
done
scancel "$job" || fail "scancel $job"
wait $sub && fail "--submit of a cancelled job exited 0"
cat "$T/sub2.err"
grep -q "^harness slurm: job $job ended CANCELLED: [0-9]*/10 rows in results/cut-slurm.csv" "$T/sub2.err" ||
  fail "no CANCELLED line"
done1=$(($(wc -l < "$csv") - 1))
[ "$done1" -ge 2 ] && [ "$done1" -lt 10 ] || fail "cancelled with $done1 rows: not half-way"
head -n $((done1 + 1)) "$csv" > "$T/before.csv"
submit cut.conf > "$T/sub3.out" 2> "$T/sub3.err" || { cat "$T/sub3.err"; fail "the resubmission failed"; }
job2=$(submitted_job "$T/sub3.err")
grep -q "$done1 skipped (resume)" "$T/repo/slurm-$job2.out" || { cat "$T/repo/slurm-$job2.out"; fail "no resume"; }
head -n $((done1 + 1)) "$csv" | cmp -s - "$T/before.csv" || fail "the resubmission changed the first rows"
check_csv "$csv"

# ---- 2b: the job cancelled by its own third run, which then fails at once ----
# The run ends before the harness's SIGTERM arrives (scancel, slurmctld,
# slurmd, slurmstepd: milliseconds); its failure is the job ending, not the
# run's own, so it gets no row.
cat > "$T/repo/self.conf" <<CONF
study: self
command: sh -c 'n=\$(cat $T/count 2> /dev/null || echo 0); echo \$((n + 1)) > $T/count; [ "\$n" -lt 2 ] || { scancel "\$SLURM_JOB_ID"; exit 1; }; echo v=1'
metric v: 'v=([0-9]+)' unit 1 better higher
repeats: 6
timeout: 60
CONF
submit self.conf > /dev/null 2> "$T/sub2b.err" && fail "--submit of a job cancelled by its run exited 0"
grep -q "^harness slurm: job [0-9]* ended CANCELLED: 2/6 rows in results/self-slurm.csv" "$T/sub2b.err" ||
  { cat "$T/sub2b.err"; fail "self-cancelled job: not 2 rows, CANCELLED"; }
python3 - "$T/repo/results/self-slurm.csv" <<'PY' || fail "self-cancelled job's CSV"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert [r["status"] for r in rows] == ["ok", "ok"], [(r["status"], r["status_detail"]) for r in rows]
PY

# ---- 3: a job that fails, and one that can never start: one line, exit 1 ----
sed 's|^raytrace: .*|raytrace: /nonexistent/raytrace|; s/^study: real$/study: broken/' \
  "$T/repo/real.conf" > "$T/repo/broken.conf"
submit broken.conf > /dev/null 2> "$T/sub4.err" && fail "--submit of a failing job exited 0"
grep -q "^harness slurm: job [0-9]* ended FAILED: 0/10 rows .*raytrace not executable at '/nonexistent/raytrace'" \
  "$T/sub4.err" || { cat "$T/sub4.err"; fail "no FAILED line"; }
sed 's/^study: real$/study: huge/' "$T/repo/real.conf" > "$T/repo/huge.conf"
out=$(cd "$T/repo" && timeout 60 "$H" slurm huge.conf --submit --cpus-per-task $((cpus * 8)) 2>&1) &&
  fail "--submit of a job larger than the node exited 0"
echo "$out" | grep -q "^harness slurm: job [0-9]* cannot start as submitted (PENDING: PartitionConfig)" ||
  fail "no 'cannot start' line: $out"
# ---- 6: a command study's ranks through srun, their pinning proved ----
cat > "$T/repo/cmd.conf" <<'CONF'
study: cmd
command: awk 'BEGIN{for(i=0;i<3e6;i++)s+=i; print "sum=" s}'
ranks: 1 2
metric sum: 'sum=([0-9.e+]+)' unit 1 better higher
repeats: 2
timeout: 60
CONF
submit cmd.conf > "$T/sub5.out" 2> "$T/sub5.err" || { cat "$T/sub5.err"; slurm_logs; fail "command study: --submit failed"; }
grep -q '^harness slurm: job [0-9]* COMPLETED: 4/4 rows in results/cmd-slurm.csv' "$T/sub5.err" ||
  { cat "$T/sub5.err"; fail "command study: no COMPLETED line"; }
python3 - "$T/repo/results/cmd-slurm.csv" <<'PY' || fail "command study's CSV"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert sorted(r["ranks"] for r in rows) == ["1", "1", "2", "2"], [r["ranks"] for r in rows]
for r in rows:
    assert r["status"] == "ok" and r["program"] == "awk" and "sum=" in r["extra"], r
    # the tasks are slurmstepd's, not srun's: seen by the harness anyway
    assert r["pin_held"] == "yes" and r["cores_actual"] == r["cores_planned"], (r["run_id"], r["cores_planned"], r["cores_actual"], r["pin_held"])
PY
echo "slurm real-cluster test passed ($cpus CPUs; job $job cancelled at $done1/10 rows, job $job2 resumed it)"
