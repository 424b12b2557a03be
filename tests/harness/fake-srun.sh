#!/bin/sh
# A stand-in for Slurm's srun (not installed here): appends its arguments and
# the OpenMP/srun environment the harness gave it to $FAKE_SRUN_LOG, drops its
# own --options and runs the rest (the fake raytrace), which prints the record
# line, so the harness's row proves the run really went through srun.
{
  echo "args: $*"
  echo "env: OMP_NUM_THREADS=${OMP_NUM_THREADS:-unset} OMP_PLACES=${OMP_PLACES:-unset}" \
       "OMP_PROC_BIND=${OMP_PROC_BIND:-unset} SRUN_CPUS_PER_TASK=${SRUN_CPUS_PER_TASK:-unset}" \
       "OMPI_ALLOW_RUN_AS_ROOT=${OMPI_ALLOW_RUN_AS_ROOT:-unset}"
} >> "${FAKE_SRUN_LOG:?FAKE_SRUN_LOG not set}"
while [ $# -gt 0 ]; do
  case "$1" in
    --*) shift ;;
    *) break ;;
  esac
done
[ $# -gt 0 ] || { echo "srun: no program to run" >&2; exit 2; }
exec "$@"
