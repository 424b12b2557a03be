#!/bin/bash
# The third-party workloads shipped as configs, run as they are (their CI
# sizes): configs/hpcc.conf (HPC Challenge over 1 and 2 MPI ranks) and
# configs/xz.conf (xz over 1 and 2 threads). Every row ok with its metrics,
# ranks and threads pinned as planned, and the table of each.
# usage: test-workloads.sh HARNESS SRCDIR
set -u
. "$(dirname "$0")/common.sh"
test_setup workloads "$1" "$1"
src=$2
for p in hpcc xz mpirun python3; do
    command -v "$p" > /dev/null || fail "$p missing (scripts/install-deps.sh installs it)"
done
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
csv() { python3 -c 'import csv,sys
for r in csv.DictReader(open(sys.argv[1])): print("|".join(r[c] for c in sys.argv[2:]))' "$@"; }
ncores=$(nproc)
for s in hpcc xz; do
    echo "== $s"
    # oversubscribe: a 1-core machine still runs the 2-worker configuration
    "$H" run "$src/configs/$s.conf" -o "$s.csv" --set oversubscribe=allow > "$s.out" 2>&1 ||
        { cat "$s.out"; fail "$s study failed"; }
    tail -2 "$s.out"
    [ "$(csv "$s.csv" status | sort | uniq -c | awk '{print $1 $2}')" = 6ok ] || fail "$s: not 6 ok rows"
    # a thread seen on another thread's core counts as held only in part;
    # where other work took a core (noise: busy) that is the machine, and
    # the row says so, else it is a pinning fault
    while IFS='|' read -r w planned actual held noise; do
        [ "$w" -gt "$ncores" ] || [ "$held" = yes ] || { [ "$held" = partial ] && [[ "$noise" == *busy* ]]; } ||
            fail "$s: workers=$w planned $planned, ran on $actual ($held, noise '$noise')"
    done < <(csv "$s.csv" workers cores_planned cores_actual pin_held noise)
    "$H" table "$s.csv" > "$s-table.md" || fail "$s: table"
    cat "$s-table.md"
done
csv hpcc.csv extra | grep -q '^hpl_gflops=[0-9.]*;hpl_tflops=.*;triad_gbs=[0-9.]*;' || fail "hpcc's metrics"
[ "$(csv hpcc.csv program_version | sort -u)" = "hpcc 1.5.0-3" ] || echo "note: hpcc version $(csv hpcc.csv program_version | sort -u)"
grep -q "metric hpl_gflops, higher is better" hpcc-table.md && grep -q "| hpcc P=2 |" hpcc-table.md ||
    fail "hpcc's table"
grep -q "metric wall_ms" xz-table.md && grep -q "| xz T=2 |" xz-table.md || fail "xz's table"
[ "$(csv xz.csv maxrss_kib | awk '$1 > 10000' | wc -l)" -eq 6 ] || fail "xz's peak memory"
"$H" table hpcc.csv --metric triad_gbs | grep -q "median GB/s" || fail "hpcc's STREAM table"
echo "ok"
