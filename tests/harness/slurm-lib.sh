# slurm-lib.sh - sourced by the tests that start a real Slurm cluster
# (test-slurm-real.sh: one node; test-slurm-nodes.sh: two nodes in network
# namespaces): the packages, munged on a key and socket of its own, the
# slurm.conf lines both clusters share, waiting for a node, stopping what a
# test started, the scene, the CSV checks. Everything lives in the test's
# temp folder $T, which the caller sets before using anything but
# slurm_need and skip.
#   . "$(dirname "$0")/slurm-lib.sh"
. "$(dirname "$0")/common.sh"
skip() { echo "SKIP: $*"; exit 77; }

# Root, Slurm and munge (installed as scripts/install-deps.sh does when
# missing), and a raytrace ($1) built with MPI; else skip.
slurm_need() {
  [ "$(id -u)" -eq 0 ] || skip "not root: slurmd must run as root to start jobs"
  need="slurmctld slurmd sbatch squeue scancel sinfo srun munged munge"
  if slurm_missing; then
    # the packages of scripts/install-deps.sh; no daemon is started by them here
    export DEBIAN_FRONTEND=noninteractive
    { timeout 600 apt-get install -y -qq --no-install-recommends slurm-wlm slurm-client munge ||
      { timeout 300 apt-get update -qq && timeout 600 apt-get install -y -qq --no-install-recommends \
          slurm-wlm slurm-client munge; }; } > /dev/null 2>&1
    slurm_missing && skip "slurm-wlm/munge not installed and apt-get could not install them"
  fi
  "$1" -V | grep -q 'mpi(not built)' && skip "raytrace was built without MPI"
}
slurm_missing() { for c in $need; do command -v "$c" > /dev/null || return 0; done; return 1; }

# The daemons' logs, for a failure's message.
slurm_logs() { for f in "$T"/log/*.log "$T"/munge/munged.log; do echo "--- $f"; tail -20 "$f"; done 2> /dev/null; }

# munged with a fresh key, listening on $T/munge/sock (slurm.conf's AuthInfo):
# a site's munged and key are left alone.
munge_start() {
  mkdir -m 700 "$T/munge" && mkdir -p "$T/state" "$T/log" "$T/tmp" || fail "cannot make folders in $T"
  dd if=/dev/urandom of="$T/munge/munge.key" bs=1024 count=1 2> /dev/null && chmod 400 "$T/munge/munge.key"
  munged -f --socket="$T/munge/sock" --key-file="$T/munge/munge.key" --pid-file="$T/munge/munged.pid" \
    --log-file="$T/munge/munged.log" --seed-file="$T/munge/seed" || { slurm_logs; fail "munged did not start"; }
  munge -S "$T/munge/sock" -n | unmunge -S "$T/munge/sock" > /dev/null || { slurm_logs; fail "munge does not work"; }
}

# The slurm.conf lines both test clusters share (the caller adds its hosts,
# ports, daemon files, nodes and partition), and cgroup.conf.
slurm_conf_common() {
  cat <<CONF
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$T/munge/sock
StateSaveLocation=$T/state
SlurmctldPidFile=$T/slurmctld.pid
SlurmctldLogFile=$T/log/slurmctld.log
# no cgroups (a container or chroot may not mount /sys/fs/cgroup): processes
# tracked through /proc, tasks bound with sched_setaffinity (task/none
# would ignore srun --cpu-bind, and the pinning checks need it), no
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
# srun's PMIx folders (TmpFS/spmix_appdir_UID_JOB.STEP) in the test's folder
TmpFS=$T/tmp
KillWait=5
MinJobAge=300
CONF
  # Slurm 22.05's slurmd loads a cgroup plugin whatever the other plugins
  # are, and the default (autodetect) fails where /sys/fs/cgroup is not
  # mounted (a container, a chroot). Naming cgroup/v1 skips that probe; none
  # of the plugins above uses cgroups, so nothing is mounted or created.
  printf 'CgroupPlugin=cgroup/v1\nCgroupAutomount=no\n' > "$T/cgroup.conf"
}

# Waits up to 30 s for node $1 to be idle; the rest of the arguments run
# sinfo (e.g. a namespace's prefix), none: sinfo here.
slurm_wait_idle() {
  node=$1; shift
  i=0
  until [ "$("$@" sinfo -h -n "$node" -o %t 2> /dev/null)" = idle ]; do
    i=$((i + 1)); [ $i -le 60 ] || { "$@" sinfo; slurm_logs; fail "node $node did not come up idle in 30 s"; }
    sleep 0.5
  done
}

# Cancels every job of the cluster and waits (10 s at most) until the
# controller lists none: their steps would outlive slurmd. The arguments
# run the client commands, as for slurm_wait_idle.
slurm_cancel_all() {
  [ -f "$T/slurmctld.pid" ] || return 0
  "$@" scancel --quiet --user=root > /dev/null 2>&1
  i=0; while [ $i -lt 20 ] && [ -n "$("$@" squeue -h -o %i 2> /dev/null)" ]; do sleep 0.5; i=$((i + 1)); done
}

# Stops the daemons of the pid files in $T (slurmd, slurmctld, munged) and
# the processes given as arguments, and waits (10 s at most) for them to
# exit: they save state on the way out, so $T goes only after them.
slurm_kill_daemons() {
  pids=""
  for p in "$T"/slurmd*.pid "$T/slurmctld.pid" "$T/munge/munged.pid" $*; do
    case $p in /*) [ -f "$p" ] && pid=$(cat "$p") || continue ;; *) pid=$p ;; esac
    kill "$pid" 2> /dev/null && pids="$pids $pid"
  done
  i=0
  while [ $i -lt 40 ]; do
    alive=0; for pid in $pids; do kill -0 "$pid" 2> /dev/null && alive=1; done
    [ $alive -eq 0 ] && break
    sleep 0.25; i=$((i + 1))
  done
}

# $T/scenes/balls.txt: 35 balls on a floor, a few tenths of a second at
# 640x480 without a BVH.
slurm_scene() {
  mkdir -p "$T/scenes"
  { printf 'film_resolution: 200 150\ncamera_pos: 0 1.5 8\ncamera_fwd: 0 0.1 1\ncamera_up: 0 1 0\n'
    printf 'camera_fov_ha: 30\nbackground: .3 .5 .8\nambient_light: .1 .1 .1\nmax_depth: 6\n'
    printf 'point_light: 5 8 5  1 1 1\nmaterial: .2 .2 .2 .5 .5 .5 .3 .3 .3 20 0 0 0 1\nsphere: 0 -1000 0 999\n'
    for x in -3 -2 -1 0 1 2 3; do for z in -2 -1 0 1 2; do
      printf 'material: .1 .1 .1 .4 .3 .2 .5 .5 .5 40 0 0 0 1\nsphere: %s 0.5 %s 0.45\n' $x $z
    done; done; } > "$T/scenes/balls.txt"
}

# The job id in --submit's stderr ($1: the file).
submitted_job() { sed -n 's/^harness slurm: submitted .* as job \([0-9]*\) .*/\1/p' "$1"; }
