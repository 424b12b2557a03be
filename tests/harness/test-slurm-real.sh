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
# needed (slurm.conf and cgroup.conf below): a daemon that does not start
# fails the test with its log.
# usage: test-slurm-real.sh HARNESS RAYTRACE
set -u
abs() { (cd "$(dirname "$1")" && echo "$(pwd)/$(basename "$1")"); }
H=$(abs "$1") RT=$(abs "$2")
skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }

[ "$(id -u)" -eq 0 ] || skip "not root: slurmd must run as root to start jobs"
need="slurmctld slurmd sbatch squeue scancel sinfo srun munged munge"
missing() { for c in $need; do command -v "$c" > /dev/null || return 0; done; return 1; }
if missing; then
  # the packages of scripts/install-deps.sh; no daemon is started by them here
  export DEBIAN_FRONTEND=noninteractive
  { timeout 600 apt-get install -y -qq --no-install-recommends slurm-wlm slurm-client munge ||
    { timeout 300 apt-get update -qq && timeout 600 apt-get install -y -qq --no-install-recommends \
        slurm-wlm slurm-client munge; }; } > /dev/null 2>&1
  missing && skip "slurm-wlm/munge not installed and apt-get could not install them"
fi
"$RT" -V | grep -q 'mpi(not built)' && skip "raytrace was built without MPI"

T=$(mktemp -d /tmp/hx-slurm-real-XXXXXX)
chmod 755 "$T"
export SLURM_CONF=$T/slurm.conf
# Stop what this test started, by pid: jobs first (their steps would outlive
# slurmd), then the daemons.
cleanup() {
  if [ -f "$T/slurmctld.pid" ]; then
    scancel --quiet --user=root > /dev/null 2>&1
    i=0; while [ $i -lt 20 ] && [ -n "$(squeue -h -o %i 2> /dev/null)" ]; do sleep 0.5; i=$((i + 1)); done
  fi
  pids=""
  for p in slurmd.pid slurmctld.pid munge/munged.pid; do
    [ -f "$T/$p" ] && pid=$(cat "$T/$p") && kill "$pid" 2> /dev/null && pids="$pids $pid"
  done
  # they save state on the way out: remove the folder once they are gone
  i=0
  while [ $i -lt 40 ]; do
    alive=0; for pid in $pids; do kill -0 "$pid" 2> /dev/null && alive=1; done
    [ $alive -eq 0 ] && break
    sleep 0.25; i=$((i + 1))
  done
  rm -rf "$T"
}
trap cleanup EXIT
trap 'exit 1' INT TERM HUP
logs() { for f in "$T"/log/*.log "$T"/munge/munged.log; do echo "--- $f"; tail -20 "$f"; done 2> /dev/null; }

# ---- munge: a key of our own and its own socket ----
mkdir -m 700 "$T/munge" && mkdir "$T/state" "$T/spool" "$T/log" "$T/tmp"
dd if=/dev/urandom of="$T/munge/munge.key" bs=1024 count=1 2> /dev/null && chmod 400 "$T/munge/munge.key"
munged -f --socket="$T/munge/sock" --key-file="$T/munge/munge.key" --pid-file="$T/munge/munged.pid" \
  --log-file="$T/munge/munged.log" --seed-file="$T/munge/seed" || { logs; fail "munged did not start"; }
munge -S "$T/munge/sock" -n | unmunge -S "$T/munge/sock" > /dev/null || { logs; fail "munge does not work"; }

# ---- slurm.conf: two free ports, the node as slurmd -C sees it ----
listening() { grep -q -i ":$(printf %04X "$1") [0-9A-F:]* 0A " /proc/net/tcp /proc/net/tcp6 2> /dev/null; }
port=$((20000 + $$ % 10000 * 2)) # even: two tests side by side never share a pair
while listening $port || listening $((port + 1)); do port=$((port + 2)); done
node=$(slurmd -C | head -1 | sed 's/^NodeName=[^ ]*/NodeName=localhost/')
case $node in NodeName=localhost\ CPUs=*) ;; *) fail "unexpected slurmd -C output: $node" ;; esac
cpus=$(echo "$node" | sed 's/.* CPUs=\([0-9]*\).*/\1/')
# addresses given, not looked up: a machine without /etc/hosts (a bare
# debootstrap chroot) cannot resolve even "localhost"
cat > "$SLURM_CONF" <<CONF
ClusterName=raybench-test
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$T/munge/sock
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd.pid
SlurmctldLogFile=$T/log/slurmctld.log
SlurmdLogFile=$T/log/slurmd.log
# no cgroups (a container or chroot may not mount /sys/fs/cgroup): processes
# tracked through /proc, tasks bound with sched_setaffinity (task/none
# would ignore srun --cpu-bind, and the pinning checks below need it), no
# accounting sampler
ProctrackType=proctrack/linuxproc
TaskPlugin=task/affinity
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
# none, as at many sites: the harness's script must ask for pmix itself
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
ReturnToService=2
# job ids and srun's PMIx folders (TmpFS/spmix_appdir_UID_JOB.STEP) of their
# own, so that a second cluster on the machine never meets this one's
FirstJobId=$((port * 10))
TmpFS=$T/tmp
KillWait=5
MinJobAge=300
$node NodeAddr=127.0.0.1 NodeHostname=localhost State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
# Slurm 22.05's slurmd loads a cgroup plugin whatever the other plugins
# are, and the default (autodetect) fails where /sys/fs/cgroup is not
# mounted (a container, a chroot). Naming cgroup/v1 skips that probe; none
# of the plugins above uses cgroups, so nothing is mounted or created.
printf 'CgroupPlugin=cgroup/v1\nCgroupAutomount=no\n' > "$T/cgroup.conf"
slurmctld -f "$SLURM_CONF" -c || { logs; fail "slurmctld did not start"; }
slurmd -f "$SLURM_CONF" -N localhost || { logs; fail "slurmd did not start"; }
i=0
until [ "$(sinfo -h -n localhost -o %t 2> /dev/null)" = idle ]; do
  i=$((i + 1)); [ $i -le 60 ] || { sinfo; logs; fail "the node did not come up idle in 30 s"; }
  sleep 0.5
done
srun --mpi=list 2>&1 | grep -q pmix || fail "Slurm has no mpi/pmix plugin (srun --mpi=list)"

# ---- the study: a scene written here, serial and MPI ranks x threads ----
mkdir -p "$T/repo/build/harness" "$T/scenes"
ln -s "$H" "$T/repo/build/harness/harness"
{ printf 'film_resolution: 200 150\ncamera_pos: 0 1.5 8\ncamera_fwd: 0 0.1 1\ncamera_up: 0 1 0\n'
  printf 'camera_fov_ha: 30\nbackground: .3 .5 .8\nambient_light: .1 .1 .1\nmax_depth: 6\n'
  printf 'point_light: 5 8 5  1 1 1\nmaterial: .2 .2 .2 .5 .5 .5 .3 .3 .3 20 0 0 0 1\nsphere: 0 -1000 0 999\n'
  for x in -3 -2 -1 0 1 2 3; do for z in -2 -1 0 1 2; do
    printf 'material: .1 .1 .1 .4 .3 .2 .5 .5 .5 40 0 0 0 1\nsphere: %s 0.5 %s 0.45\n' $x $z
  done; done; } > "$T/scenes/balls.txt"
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
submit real.conf > "$T/sub1.out" 2> "$T/sub1.err" || { cat "$T/sub1.err"; logs; fail "--submit failed"; }
cat "$T/sub1.err"
grep -q '^harness slurm: job [0-9]* COMPLETED: 10/10 rows in results/real-slurm.csv' "$T/sub1.err" ||
  fail "no COMPLETED line"
grep -q '### Per configuration' "$T/sub1.out" || fail "--submit printed no table"
check_csv "$T/repo/results/real-slurm.csv"
job=$(sed -n 's/^harness slurm: submitted .* as job \([0-9]*\) .*/\1/p' "$T/sub1.err")
log=$T/repo/slurm-$job.out
grep -q 'export SLURM_MPI_TYPE=pmix' "$T/repo/results/real-slurm.sbatch" || fail "no SLURM_MPI_TYPE in the script"
grep -q "^job $job: 1 node(s): localhost" "$log" || { cat "$log"; fail "job log"; }
grep -q 'mpirun' "$log" && fail "the job log mentions mpirun"

# ---- 2: cancelled half-way, then continued by --submit again ----
sed 's/^study: real$/study: cut/' "$T/repo/real.conf" > "$T/repo/cut.conf"
csv=$T/repo/results/cut-slurm.csv
submit cut.conf > /dev/null 2> "$T/sub2.err" &
sub=$!
i=0
while [ "$(($(cat "$csv" 2> /dev/null | wc -l) - 1))" -lt 2 ]; do
  i=$((i + 1)); [ $i -le 600 ] || { cat "$T/sub2.err"; fail "the study wrote no rows in 120 s"; }
  sleep 0.2
done
job=$(sed -n 's/^harness slurm: submitted .* as job \([0-9]*\) .*/\1/p' "$T/sub2.err")
[ -n "$job" ] || fail "no job id in: $(cat "$T/sub2.err")"
scancel "$job" || fail "scancel $job"
wait $sub && fail "--submit of a cancelled job exited 0"
cat "$T/sub2.err"
grep -q "^harness slurm: job $job ended CANCELLED: [0-9]*/10 rows in results/cut-slurm.csv" "$T/sub2.err" ||
  fail "no CANCELLED line"
done1=$(($(wc -l < "$csv") - 1))
[ "$done1" -ge 2 ] && [ "$done1" -lt 10 ] || fail "cancelled with $done1 rows: not half-way"
head -n $((done1 + 1)) "$csv" > "$T/before.csv"
submit cut.conf > "$T/sub3.out" 2> "$T/sub3.err" || { cat "$T/sub3.err"; fail "the resubmission failed"; }
job2=$(sed -n 's/^harness slurm: submitted .* as job \([0-9]*\) .*/\1/p' "$T/sub3.err")
grep -q "$done1 skipped (resume)" "$T/repo/slurm-$job2.out" || { cat "$T/repo/slurm-$job2.out"; fail "no resume"; }
head -n $((done1 + 1)) "$csv" | cmp -s - "$T/before.csv" || fail "the resubmission changed the first rows"
check_csv "$csv"

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
submit cmd.conf > "$T/sub5.out" 2> "$T/sub5.err" || { cat "$T/sub5.err"; logs; fail "command study: --submit failed"; }
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
