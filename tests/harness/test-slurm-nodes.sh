#!/bin/sh
# `harness slurm --submit` on a real two-node Slurm cluster on one machine.
# Each node is a network namespace with its own address on one veth pair
# between the two (10.77.0.1 and .2; the host's own network namespace is
# not touched), its own host name (a UTS namespace) and its own slurmd;
# node 1 also runs slurmctld and is the login node every client command
# runs on; one munged serves both through its socket in the test's folder.
# Open MPI's ranks talk TCP over the veth pair.
#  1. mpi and hybrid runs, a rank on each node: the images are the serial
#     renderer's, the record says nodes=2 (ranks on node 2 MPI_Put their
#     tiles into rank 0's window), each rank rendered, and each node's
#     threads hold distinct cores of that node (the harness's per-node
#     pin_held);
#  2. a run failing on two nodes is recorded as the run's own failure;
#  3. node 2 dies during a run (every process of its namespace killed): the
#     job ends, the CSV holds whole rows of ok runs only, and once its
#     slurmd is back --submit again completes the study.
# Exit 77 (skip) when not root, Slurm cannot be installed, raytrace has no
# MPI, or the kernel gives no network or UTS namespaces; no cgroups are
# needed. A missing `ip` (iproute2, scripts/install-deps.sh) fails.
# usage: test-slurm-nodes.sh HARNESS RAYTRACE
set -u
. "$(dirname "$0")/slurm-lib.sh"
H=$(abs "$1") RT=$(abs "$2")
slurm_need "$RT"
command -v ip > /dev/null || fail "ip missing (iproute2: scripts/install-deps.sh installs it)"
command -v python3 > /dev/null || fail "python3 missing (scripts/install-deps.sh installs it)"
unshare --uts true 2> /dev/null || skip "no UTS namespaces (unshare --uts failed)"

T=$(mktemp -d /tmp/hx-slurm-nodes-XXXXXX)
chmod 755 "$T"
export SLURM_CONF=$T/slurm.conf
NS=hxn$$- NET=10.77.0 # namespaces hxnPID-1 and hxnPID-2

# Runs a command on node $1: in its network namespace, under its own host
# name (Open MPI names its shared-memory segments in the one /dev/shm after
# the host: two nodes named alike open each other's and crash) and with its
# own $T/tmp (slurm.conf's TmpFS: each node's PMIx server makes a folder
# there named by job and step only), bound in the mount namespace that ip
# netns exec makes for the command.
on() {
  n=$1; shift
  ip netns exec "$NS$n" unshare --uts sh -c 'hostname "$1" && mount --bind "$2" "$3" && shift 3 && exec "$@"' \
    sh "node$n" "$T/node$n/tmp" "$T/tmp" "$@"
}
# (only processes whose network namespace is not this script's: where the
# namespaces could not be made right, nothing outside them is killed)
ns_pids() {
  own=$(readlink /proc/$$/ns/net)
  for p in $(ip netns pids "${NS}1" 2> /dev/null; ip netns pids "${NS}2" 2> /dev/null); do
    [ "$(readlink /proc/$p/ns/net 2> /dev/null)" != "$own" ] && echo "$p"
  done
}
# Stop what this test started: jobs, then the daemons and whatever else runs
# in the two namespaces (job steps, ranks, a --submit), the namespaces
# (their veths go with them), the folder.
cleanup() {
  slurm_cancel_all on 1
  slurm_kill_daemons $(ns_pids)
  for p in $(ns_pids); do kill -9 "$p" 2> /dev/null; done
  ip netns del "${NS}1" 2> /dev/null
  ip netns del "${NS}2" 2> /dev/null
  rm -rf "$T"
}
trap cleanup EXIT
trap 'exit 1' INT TERM HUP

# ---- the network: two namespaces, one veth pair between them ----
err=$(ip netns add "${NS}1" 2>&1 && ip netns add "${NS}2" 2>&1) || skip "no network namespaces: $err"
err=$(ip link add "${NS}1v" netns "${NS}1" type veth peer name "${NS}2v" netns "${NS}2" 2>&1) ||
  skip "no veth pairs: $err"
# named veth0 on both nodes (a name inside each namespace), so that one
# setting in the job names each node's end
# (a chroot without its own /run or sysfs can make the pair and not set it
# up: a machine that cannot, not a failure of the harness)
for n in 1 2; do
  err=$({ ip -n "$NS$n" link set "$NS${n}v" name veth0 && ip -n "$NS$n" addr add "$NET.$n/24" dev veth0 &&
    ip -n "$NS$n" link set lo up && ip -n "$NS$n" link set veth0 up; } 2>&1) ||
    skip "the namespaces' veth pair cannot be set up here: $(echo "$err" | head -1)"
done

# ---- Slurm: slurmctld and slurmd on node 1, slurmd on node 2 ----
munge_start
mkdir -p "$T/spool" "$T/node1/tmp" "$T/node2/tmp" "$T/jobtmp" "$T/repo/build/harness"
node=$(slurmd -C | head -1 | sed 's/^NodeName=[^ ]* //')
case $node in CPUs=*) ;; *) fail "unexpected slurmd -C output: $node" ;; esac
cpus=$(echo "$node" | sed 's/^CPUs=\([0-9]*\).*/\1/')
[ "$cpus" -ge 2 ] || skip "the machine has $cpus CPU: a rank of 2 threads needs 2"
{ cat <<CONF
ClusterName=raybench-nodes
SlurmctldHost=node1($NET.1)
# the namespaces' own ports: nothing else listens there
SlurmctldPort=6817
SlurmdPort=6818
SlurmdSpoolDir=$T/spool/%n
SlurmdPidFile=$T/slurmd-%n.pid
SlurmdLogFile=$T/log/slurmd-%n.log
# a dead node noticed in seconds, and its job ended (NODE_FAIL) rather
# than requeued: the test resubmits as a user would
SlurmdTimeout=5
JobRequeue=0
# job ids of its own: Open MPI names its shared-memory segments after the
# host and the job, and a second copy of this test has hosts named alike
FirstJobId=$((1000000 + $$ % 60000 * 1000))
CONF
  slurm_conf_common
  # both nodes are this machine: its CPUs and memory each
  for n in 1 2; do echo "NodeName=node$n NodeAddr=$NET.$n NodeHostname=node$n $node State=UNKNOWN"; done
  echo "PartitionName=test Nodes=node1,node2 Default=YES MaxTime=INFINITE State=UP"
} > "$SLURM_CONF"
on 1 slurmctld -f "$SLURM_CONF" -c || { slurm_logs; fail "slurmctld did not start"; }
slurmd_start() { on "$1" slurmd -f "$SLURM_CONF" -N "node$1" || { slurm_logs; fail "slurmd of node$1 did not start"; }; }
slurmd_start 1
slurmd_start 2
slurm_wait_idle node1 on 1
slurm_wait_idle node2 on 1

# ---- the studies: --submit from node 1 over both nodes ----
ln -s "$H" "$T/repo/build/harness/harness"
slurm_scene
# accel none at 640x480: a tenth of a second or more, so that every rank,
# on either node, claims tiles before rank 0 has rendered them all
study() { # NAME, then extra config lines
  name=$1; shift
  { printf 'study: %s\nscene_dir: %s\nscenes: balls\naccel: none\nresolution: 640x480\n' "$name" "$T/scenes"
    printf 'pin: close\nwarmup: 0\ntimeout: 120\nscene_cache: off\nraytrace: %s\n' "$RT"
    printf '%s\n' "$@"; } > "$T/repo/$name.conf"
}
study nodes 'backend: serial mpi' 'ranks: 2' 'threads: 1 2' 'repeats: 2'
study bad 'backend: mpi' 'ranks: 2' 'threads: 1' 'repeats: 2' 'extra_args: --mpi-scene bogus'
study lost 'backend: serial mpi' 'ranks: 2' 'threads: 1 2' 'repeats: 2'
# The job's environment (sbatch passes the submitter's on to the job and
# srun to the ranks): Open MPI's TCP on the veth only; osc/pt2pt, the
# one-sided component that works over TCP, which Debian's
# /etc/openmpi/openmpi-mca-params.conf turns off (osc = ^ucx,pt2pt): without
# it MPI_Win_allocate fails across nodes (MPI_ERR_WIN); temporary files in $T.
jobenv="OMPI_MCA_btl_tcp_if_include=veth0 OMPI_MCA_osc=sm,pt2pt TMPDIR=$T/jobtmp"
# One rank per node: with two per node, that is 4 processes on 2 cores
# here, Open MPI 4.1's btl/tcp crashes about one MPI_Init in a hundred (a
# message from a rank that has left MPI_Init reaches one that has not yet
# registered its handler: a call through NULL). --nodes 2 and the plan's
# sizes (2 tasks x 2 CPUs) fit two nodes of 2 CPUs.
submit() {
  (cd "$T/repo" && on 1 env $jobenv timeout 300 build/harness/harness slurm "$1" --submit --nodes 2 \
    --time 00:10:00 --max-wait 00:04:00)
}
ref=$("$RT" --backend serial --accel none --resolution 640x480 -q -o "$T/ref.ppm" "$T/scenes/balls.txt" |
  sed -n 's/.* image_fnv1a=\([0-9a-f]*\).*/\1/p')
[ -n "$ref" ] || fail "no image_fnv1a from the serial renderer"

# Checks a CSV ($1) holding $2 rows (0: any number) that are whole, each
# an ok run rendering the serial renderer's image; MPI rows spread over both
# nodes, every rank rendering on as many cores as it has threads, no core
# of a node shared, the harness's per-node plan held (pin_held yes).
check_csv() {
  python3 - "$1" "$2" "$ref" <<'PY' || fail "CSV check of $1"
import csv, sys
path, want_rows, ref = sys.argv[1], int(sys.argv[2]), sys.argv[3]
def bad(msg):
    print(msg); sys.exit(1)
text = open(path).read()
if not text.endswith("\n"): bad("the last row is not whole")
lines = list(csv.reader(text.splitlines()))
if any(len(l) != len(lines[0]) for l in lines): bad("a row is not whole")
rows = list(csv.DictReader(text.splitlines()))
if want_rows and len(rows) != want_rows: bad("%d rows, expected %d" % (len(rows), want_rows))
if len({r["run_id"] for r in rows}) != len(rows): bad("duplicated run ids")
for r in rows:
    if r["status"] != "ok": bad("%s: status %s: %s" % (r["run_id"], r["status"], r["status_detail"]))
    if r["image_fnv1a"] != ref: bad("%s: image %s, the serial renderer's %s" % (r["run_id"], r["image_fnv1a"], ref))
    if r["backend"] != "mpi":
        continue
    P, T = int(r["ranks"]), int(r["threads"])
    ex = dict(kv.split("=", 1) for kv in r["extra"].split(";") if "=" in kv)
    if (r["rec_ranks"], r["rec_threads"]) != (str(P), str(T)): bad("%s: the record's ranks x threads" % r["run_id"])
    if ex.get("nodes") != "2": bad("%s: nodes=%s, expected 2" % (r["run_id"], ex.get("nodes")))
    node = ex.get("rank_node", "").split("/")
    if node != [str(k * 2 // P) for k in range(P)]: bad("%s: rank_node=%s" % (r["run_id"], ex.get("rank_node")))
    cores = [set(c.split(",")) if c else set() for c in ex.get("rank_cores", "").split("/")]
    if len(cores) != P or any(len(c) != T for c in cores):
        bad("%s: rank_cores=%s: a rank rendered nothing or not on %d cores" % (r["run_id"], ex.get("rank_cores"), T))
    for n in "01":
        mine = [c for c, k in zip(cores, node) if k == n]
        if len(set().union(*mine)) != sum(len(c) for c in mine):
            bad("%s: two ranks of node %s share a core: rank_cores=%s" % (r["run_id"], n, ex.get("rank_cores")))
    per_node = lambda s: [set(x.split(",")) for x in s.split("|")]
    if r["pin_held"] != "yes" or per_node(r["cores_actual"]) != per_node(r["cores_planned"]) or \
            len(per_node(r["cores_planned"])) != 2:
        bad("%s: per node: planned %s, used %s, pin_held %s" % (r["run_id"], r["cores_planned"],
                                                               r["cores_actual"], r["pin_held"]))
PY
}

# ---- 1: mpi and hybrid runs over both nodes ----
submit nodes.conf > "$T/sub1.out" 2> "$T/sub1.err" || { cat "$T/sub1.err"; slurm_logs; fail "--submit failed"; }
cat "$T/sub1.err"
grep -q '^harness slurm: job [0-9]* COMPLETED: 6/6 rows in results/nodes-slurm.csv' "$T/sub1.err" ||
  fail "no COMPLETED line"
check_csv "$T/repo/results/nodes-slurm.csv" 6
job=$(submitted_job "$T/sub1.err")
grep -q "^job $job: 2 node(s): node\[1-2\]" "$T/repo/slurm-$job.out" || { cat "$T/repo/slurm-$job.out"; fail "job log"; }

# ---- 2: a run that fails on two nodes is its own failure, not a node's ----
submit bad.conf > /dev/null 2> "$T/sub2.err" && fail "--submit of a failing study exited 0"
grep -q '^harness slurm: job [0-9]* ended FAILED' "$T/sub2.err" || { cat "$T/sub2.err"; fail "no FAILED line"; }
job=$(submitted_job "$T/sub2.err")
grep -q 'Slurm job cannot run on its nodes' "$T/repo/slurm-$job.out" && fail "a failing run was taken for a lost node"
python3 - "$T/repo/results/bad-slurm.csv" <<'PY' || fail "failing study's CSV"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert [r["status"] for r in rows] == ["error", "error"], [(r["status"], r["status_detail"]) for r in rows]
PY

# ---- 3: node 2 dies during a run; --submit again once it is back ----
csv=$T/repo/results/lost-slurm.csv
submit lost.conf > /dev/null 2> "$T/sub3.err" &
sub=$!
# once the serial rows and one MPI row are in, and a rank runs on node 2
i=0
on2_renders() { p=$(ip netns pids "${NS}2" | paste -sd, -); [ -n "$p" ] && ps -o comm= -p "$p" | grep -q '^raytrace$'; }
until [ "$(($(cat "$csv" 2> /dev/null | wc -l) - 1))" -ge 3 ] && on2_renders; do
  i=$((i + 1)); [ $i -le 1200 ] || { cat "$T/sub3.err"; fail "no MPI run on node 2 in 120 s"; }
  sleep 0.1
done
for p in $(ip netns pids "${NS}2"); do kill -9 "$p"; done
wait $sub && fail "--submit of a job that lost a node exited 0"
cat "$T/sub3.err"
grep -Eq '^harness slurm: job [0-9]* ended (NODE_FAIL|FAILED)' "$T/sub3.err" || fail "no NODE_FAIL or FAILED line"
done1=$(($(wc -l < "$csv") - 1))
[ "$done1" -ge 3 ] && [ "$done1" -lt 6 ] || fail "the job ended with $done1 of 6 rows"
check_csv "$csv" 0
cp "$csv" "$T/before.csv"
slurmd_start 2
slurm_wait_idle node2 on 1
submit lost.conf > /dev/null 2> "$T/sub4.err" || { cat "$T/sub4.err"; slurm_logs; fail "the resubmission failed"; }
job=$(submitted_job "$T/sub4.err")
grep -q "$done1 skipped (resume)" "$T/repo/slurm-$job.out" || { cat "$T/repo/slurm-$job.out"; fail "no resume"; }
head -n $((done1 + 1)) "$csv" | cmp -s - "$T/before.csv" || fail "the resubmission changed the first rows"
check_csv "$csv" 6
echo "slurm two-node test passed ($cpus CPUs a node; node 2 lost at $done1/6 rows, job $job completed the study)"
