#!/usr/bin/env bash
# Installs what raybench needs from Debian's packages (run as root, or with sudo).
# Idempotent: packages already present are skipped, so a second run is quick.
# The CUDA toolkit is not in Debian 12's main archive under the same version on
# every machine; when nvcc is missing the CUDA backend is simply not built.
# slurm-wlm, slurm-client and munge are for tests/harness/test-slurm-real.sh,
# which starts its own single-node cluster, and test-slurm-nodes.sh, whose
# two nodes are network namespaces joined by a veth pair (iproute2's ip);
# installing them starts no daemon that the tests use. libpmix2 is the PMIx
# that srun --mpi=pmix starts Open MPI's ranks with. libsqlite3-dev is the
# harness's history database; valgrind (cachegrind) counts the instructions
# of the CI performance check.
# The tools the tests run that a minbase Debian 12 lacks (it has only the
# Essential packages: coreutils, util-linux, diffutils, grep, sed, mawk, ...):
# procps (pgrep, ps: the leftover-process checks), python3 (JSON and CSV
# checks), git (provenance, `harness history`), time (/usr/bin/time: peak
# memory) and binutils (strings).
# hpcc (HPC Challenge) and xz-utils are the third-party workloads of the
# command studies configs/hpcc.conf and configs/xz.conf; stress-ng is the
# noisy neighbour of the noise tests; chromium opens `harness report`'s
# pages in the report test, headless.
set -euo pipefail
# Open MPI's launcher and ranks look up this host's own name: where neither
# /etc/hosts nor a quick DNS server has it (a bare chroot has no /etc/hosts),
# every mpirun waits seconds on the resolver, and the MPI tests run out of
# time. Said once here rather than found in a test's timeout.
host=$(uname -n)
if ! getent -s files hosts "$host" > /dev/null 2>&1; then
  echo "install-deps: warning: this host's name ($host) is not in /etc/hosts; each mpirun may wait on DNS" \
       "for it (a line such as '127.0.1.1 $host' in /etc/hosts avoids that)" >&2
fi
pkgs=(meson ninja-build gcc pkg-config libpng-dev libhwloc-dev hwloc
      libopenmpi-dev openmpi-bin gnuplot-nox libxxhash-dev libassimp-dev assimp-testmodels
      libembree-dev slurm-wlm slurm-client munge libpmix2 libsqlite3-dev valgrind
      procps python3 git time binutils iproute2
      hpcc xz-utils stress-ng chromium)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all packages present"
  exit 0
fi
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done"
