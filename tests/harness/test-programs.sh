#!/bin/bash
# Command studies (docs/harness.md, "Your own program"): arguments reach the
# program verbatim with no shell, metrics and checks from stdout, stderr and
# files, failures marked with their reason, bad configs refused with
# FILE:LINE before any run (an existing CSV intact), ranges and scopes, MPI
# ranks pinned and proved, and table, plot, compare and --resume on the rows.
# usage: test-programs.sh HARNESS
set -u
. "$(dirname "$0")/common.sh"
test_setup programs "$1" "$1"
command -v python3 > /dev/null || fail "python3 missing"
command -v mpirun > /dev/null || fail "mpirun missing"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# csv FILE COLUMN...: one line per row, the columns joined by '|'
csv() { python3 -c 'import csv,sys
for r in csv.DictReader(open(sys.argv[1])): print("|".join(r[c] for c in sys.argv[2:]))' "$@"; }

echo "== 1. arguments arrive verbatim, nothing reaches a shell"
cat > args.conf <<'EOF'
command: sh -c 'printf "<%s>\n" "$@" > args.txt' sh {arg} 'x; touch PWNED_A' '$(touch PWNED_B)' '`touch PWNED_C`' "it's" 'a b'
param arg: 'semi;colon $(touch PWNED_D)'
workdir: keep
repeats: 1
pin: none
EOF
"$H" run args.conf -o args.csv -q > run.out 2>&1 || { cat run.out; fail "args study failed"; }
printf '%s\n' '<semi;colon $(touch PWNED_D)>' '<x; touch PWNED_A>' '<$(touch PWNED_B)>' '<`touch PWNED_C`>' \
    "<it's>" '<a b>' > want.txt
diff want.txt args.runs/run-0001/args.txt || fail "the arguments did not arrive verbatim"
[ -z "$(find "$T" /tmp -maxdepth 3 -name 'PWNED_*' 2> /dev/null)" ] || fail "a shell ran: $(find "$T" -name 'PWNED_*')"
[ "$(csv args.csv params)" = 'arg=semi;colon $(touch PWNED_D)' ] || fail "params column: $(csv args.csv params)"

echo "== 2. metrics from stdout, stderr and a file; checks; exit status"
cat > m.conf <<'EOF'
command: sh -c 'echo "rate: 12.5 GB/s"; echo "time=3.25" >&2; echo "gflops 7.5" > out.txt; exit {code}' sh
param code: 0 3
metric rate: 'rate: ([0-9.]+) GB/s' unit GB/s
metric t: 'time=([0-9.]+)' from stderr unit s
metric g: 'gflops ([0-9.]+)' from out.txt unit Gflop/s
check: '^rate:'
repeats: 2
pin: none
EOF
"$H" run m.conf -o m.csv -q > run.out 2>&1 && fail "a failing run should make run exit 1"
grep -q "code=3" run.out || fail "the summary does not name the failing configuration: $(cat run.out)"
got=$(csv m.csv params status extra metric_info | sort -u)
echo "$got"
echo "$got" | grep -qx 'code=0|ok|rate=12.5;t=3.25;g=7.5|rate:GB/s:higher;t:s:lower;g:Gflop/s:higher' ||
    fail "code=0 rows: metrics or their declaration wrong"
echo "$got" | grep -q '^code=3|error|' || fail "code=3 rows are not errors"
csv m.csv params status_detail | grep -q '^code=3|exit 3 (expected 0)' || fail "no exit reason: $(csv m.csv status_detail)"
printf 'command: sh -c "echo hello"\nmetric x: %s\nrepeats: 1\n' "'value=([0-9]+)' unit ms" > miss.conf
"$H" run miss.conf -o miss.csv -q > /dev/null 2>&1
[ "$(csv miss.csv status status_detail)" = "error|metric x: 'value=([0-9]+)' not found in stdout" ] ||
    fail "a missing metric: $(csv miss.csv status status_detail)"
printf 'command: sh -c "echo hello; exit 4"\ncheck: %s\nexit: 4\nrepeats: 1\n' "'goodbye'" > chk.conf
"$H" run chk.conf -o chk.csv -q > /dev/null 2>&1
[ "$(csv chk.csv status status_detail exit_code)" = "error|check failed: 'goodbye' not found in stdout|4" ] ||
    fail "a failed check: $(csv chk.csv status status_detail exit_code)"
printf 'command: sh -c "echo boom >&2; exit 2"\nrepeats: 1\n' > err.conf
"$H" run err.conf -o err.csv -q > /dev/null 2>&1
[ "$(csv err.csv status_detail)" = "exit 2 (expected 0): boom" ] || fail "the first error line: $(csv err.csv status_detail)"

echo "== 3. bad configs: one line naming FILE:LINE before any run, the CSV intact"
sum=$(md5sum m.csv)
bad() { # LINE TEXT: the config's text; the error must name bad.conf:LINE
    printf "$2" > bad.conf
    "$H" run bad.conf -o m.csv --resume > out.txt 2> err.txt && fail "accepted: $2"
    [ "$(wc -l < err.txt)" -eq 1 ] && grep -q "^bad.conf:$1: " err.txt || fail "not one line naming bad.conf:$1: $(cat err.txt)"
    echo "  $(cat err.txt)"
    [ "$(md5sum m.csv)" = "$sum" ] || fail "the CSV changed"
}
bad 2 'repeats: 1\ncommand: echo {nope}\n'
bad 2 "command: echo\nmetric x: '([0-9'\n"
bad 1 'command: no-such-program-here\n'
bad 2 "command: echo\nmetric x: 'a' unit furlongs\n"
bad 2 "command: echo\nmetric x: 'a' better sideways\n"
bad 3 'command: echo\nparam m: a b\nthreads: 1 2 when m=c\n'
bad 2 'command: echo\nscenes: demo\n'
bad 2 'command: echo\nthreads: 8..1\n'
bad 2 "command: echo\nmetric x: 'a' from ../../etc/passwd\n"

echo "== 4. ranges and scopes"
cat > sc.conf <<'EOF'
command: echo {mode} {threads} {ranks}
param mode: omp mpi
threads: 1..4 *2 when mode=omp
ranks: 1 2 when mode=mpi
param n: 10..30 +10
repeats: 1
oversubscribe: allow
EOF
"$H" run --dry-run sc.conf > plan.txt 2>&1 || { cat plan.txt; fail "dry run"; }
ids=$(grep '^\[' plan.txt | sed 's/^\[[0-9]*\] //; s/ *cores=.*//' | sort)
want=$(for n in 10 20 30; do for t in 1 2 4; do echo "threads=$t ranks=- pin=close mode=omp n=$n #r0"; done
    for p in 1 2; do echo "threads=- ranks=$p pin=close mode=mpi n=$n #r0"; done; done | sort)
[ "$ids" = "$want" ] || { diff <(echo "$want") <(echo "$ids"); fail "the plan of ranges and scopes"; }

# raytrace's keys scope the same way: OpenMP's threads, MPI's ranks
echo "# dummy" > demo.txt
printf 'scenes: demo\nscene_dir: .\nbackend: serial openmp mpi\nthreads: 1 2 when backend=openmp\nranks: 1..4 *2 when backend=mpi\nrepeats: 1\noversubscribe: allow\n' > rt.conf
"$H" run --dry-run rt.conf > plan.txt 2>&1 || { cat plan.txt; fail "raytrace dry run"; }
got=$(grep '^\[' plan.txt | sed -n 's/.*backend=\([a-z]*\) .* threads=\([-0-9]*\) ranks=\([-0-9]*\) .*/\1 \2 \3/p' | tr '\n' ',')
[ "$got" = "serial - -,openmp 1 -,openmp 2 -,mpi - 1,mpi - 2,mpi - 4," ] || fail "raytrace scopes: $got"

echo "== 5. MPI ranks through mpirun, pinned, pinning proved"
cat > mpi.conf <<'EOF'
command: awk 'BEGIN{for(i=0;i<4e6;i++)s+=i; print "sum=" s}'
ranks: 1 2
oversubscribe: allow
metric sum: 'sum=([0-9.e+]+)' unit 1 better higher
repeats: 1
EOF
"$H" run mpi.conf -o mpi.csv -q > run.out 2>&1 || { cat run.out; fail "MPI study failed"; }
csv mpi.csv ranks status cores_planned cores_actual pin_held mpi_version
ncores=$(nproc)
while IFS='|' read -r p st planned actual held mv; do
    [ "$st" = ok ] || fail "ranks=$p: $st"
    case "$mv" in *"Open MPI"*) ;; *) fail "mpi_version '$mv'" ;; esac
    if [ "$p" -le "$ncores" ]; then
        [ "$held" = yes ] && [ "$actual" = "$planned" ] || fail "ranks=$p: planned $planned, seen $actual ($held)"
    fi
done < <(csv mpi.csv ranks status cores_planned cores_actual pin_held mpi_version)

echo "== 6. table, plot and compare use the metric's direction"
printf 'command: sh -c %s\nenv RATE: 12.5\nthreads: 1 2\nmetric rate: %s unit GB/s\nrepeats: 5\npin: none\n' \
    "'echo \"rate: \$RATE GB/s\"'" "'rate: ([0-9.]+)'" > r.conf
"$H" run r.conf -o base.csv -q > /dev/null 2>&1 || fail "rate study"
"$H" table base.csv > table.txt || fail "table"
grep -q "metric rate, higher is better" table.txt && grep -q "median GB/s" table.txt || { cat table.txt; fail "table header"; }
"$H" table base.csv --format json | python3 -c 'import json,sys; json.load(sys.stdin)' || fail "table json"
"$H" plot base.csv -o plot > /dev/null 2>&1 || fail "plot"
[ -s plot-speedup.png ] || fail "no speedup plot"
"$H" run r.conf -o slow.csv -q --set 'env RATE=6.25' > /dev/null 2>&1 || fail "slower study"
"$H" compare slow.csv base.csv > cmp.txt && { cat cmp.txt; fail "a halved rate is no regression"; }
grep -q "^REGRESSION" cmp.txt || { cat cmp.txt; fail "compare"; }
"$H" compare base.csv slow.csv > cmp2.txt || { cat cmp2.txt; fail "an improvement made compare exit 1"; }
grep -q "^IMPROVEMENT" cmp2.txt || { cat cmp2.txt; fail "a doubled rate is no improvement"; }

echo "== 7. --resume grows a command study"
"$H" run r.conf -o base.csv --resume --set threads='1 2 4' --set repeats=5 -q > run.out 2>&1 || { cat run.out; fail "resume"; }
[ "$(csv base.csv threads | sort | uniq -c | awk '{print $1 "x" $2}' | tr '\n' ' ')" = "5x1 5x2 5x4 " ] ||
    fail "after --resume: $(csv base.csv threads | sort | uniq -c)"
echo "== 8. history across commits: a rate that drops is a slowdown"
command -v git > /dev/null || fail "git missing"
# the "code" is the checkout's rate.txt; the config stays the same
printf 'command: sh -c %s\ninput rate.txt: rate.txt\nmetric rate: %s unit GB/s\nrepeats: 5\npin: none\n' \
    "'echo \"rate: \$(cat rate.txt) GB/s\"'" "'rate: ([0-9.]+)'" > h.conf
mkdir repo && cd repo || exit 1
git init -q . && git config user.email t@example.org && git config user.name t
for i in 1 2 3; do
    rate=12.5
    [ "$i" -lt 3 ] || rate=6.25
    echo "$rate" > rate.txt && echo "$i" > f && git add rate.txt f || fail "git add"
    GIT_AUTHOR_DATE="2026-01-0$i 12:00:00 +0000" GIT_COMMITTER_DATE="2026-01-0$i 12:00:00 +0000" \
        git commit -qm "c$i" || fail "git commit"
    "$H" run ../h.conf -o "../h$i.csv" -q > /dev/null 2>&1 || fail "study at c$i"
    "$H" history add "../h$i.csv" --db ../h.db > /dev/null || fail "history add c$i"
done
cd .. || exit 1
[ "$(csv h3.csv git_commit | sort -u)" = "$(git -C repo rev-parse --short HEAD)" ] || fail "git_commit of the checkout"
"$H" history check --metric rate --db h.db --window 2 > hc.txt && { cat hc.txt; fail "history check missed the drop"; }
grep -q "^STEP .*program=sh.* rate at commit $(git -C repo rev-parse --short HEAD) .*-50.0%" hc.txt ||
    { cat hc.txt; fail "no step at the third commit"; }

echo "== 9. a size (peak memory) is shown against 1 worker: no speedup, no Amdahl fit"
# 16 MiB more per thread: as a "time", T=2 would read as slower than 1 worker
printf 'command: python3 -c %s {threads}\nthreads: 1 2\nrepeats: 3\npin: none\n' \
    "'import sys; b = b\"x\" * (int(sys.argv[1]) << 24); print(len(b))'" > mem.conf
"$H" run mem.conf -o mem.csv -q > run.out 2>&1 || { cat run.out; fail "memory study"; }
"$H" table mem.csv --metric maxrss_kib > size.md || fail "table --metric maxrss_kib"
grep -q 'metric maxrss_kib (KiB), a size' size.md && grep -q '| x 1 worker |' size.md &&
    grep -q '^No Amdahl fit' size.md &&
    ! grep -q 'slower than 1 worker\|speedup (a)\|Amdahl fit T' size.md || { cat size.md; fail "a size read as a time"; }
r=$(grep '| python3 T=2 |' size.md | awk -F'|' '{print $6}')
awk -v r="$r" 'BEGIN { exit !(r > 1.2 && r < 3) }' || { cat size.md; fail "T=2 against 1 worker: '$r'"; }
"$H" table mem.csv --metric maxrss_kib --format json | python3 -c 'import json,sys
c = json.load(sys.stdin)["configurations"]
assert all("ratio_to_one_worker" in x and "speedup_a" not in x for x in c), c' || fail "table json of a size"
# a metric that is no decimal number, or a time below zero, is a misread: error
for v in -3 0x10 $(printf '1%.0s' $(seq 70)); do
    printf "study: m\ncommand: echo t=%s\nmetric t: 't=([-0-9a-fx.]+)' unit ms\nrepeats: 1\npin: none\n" "$v" > misread.conf
    "$H" run misread.conf -o misread.csv --overwrite -q > /dev/null 2>&1 && fail "metric t=$v read as ok"
    grep -q ",error,metric t: .*\(is negative\|is not a decimal number\)," misread.csv || fail "metric t=$v: $(tail -n 1 misread.csv)"
done
printf 'study: b\ncommand: echo {n}\nparam n: 1 2\nrepeats: 1\npin: none\n' > pset.conf
# --resume with a param's value dropped names that value
"$H" run pset.conf -o pres.csv -q 2> /dev/null || fail "the study to resume"
"$H" run pset.conf -o pres.csv --resume --set 'n=2 3' -q 2> pres.err && fail "a resume that drops n=1 went on"
grep -q "the config's param n no longer has '1'; write to another file or use --overwrite$" pres.err ||
    fail "resume without n=1: $(cat pres.err)"
# --set 'param NAME=...' overrides a param of the config, never adds one
"$H" run pset.conf --dry-run --set 'param n=3' > pset.out 2>&1 && grep -q "override: --set 'param n=3'" pset.out ||
    fail "--set 'param n=3': $(cat pset.out)"
"$H" run pset.conf --dry-run --set 'param w=1' > /dev/null 2> pset.err && fail "--set 'param w=1' added a param"
[ "$(cat pset.err)" = "harness: option --set 'param w=1': 'param w': the config has no param of that name" ] ||
    fail "--set 'param w=1': $(cat pset.err)"
# compare: one metric in one unit on both sides (0.3 s is 300 ms, no slowdown)
printf "study: u\ncommand: echo t=0.3\nmetric t: 't=([0-9.]+)' unit s\nrepeats: 4\npin: none\n" > unit-s.conf
printf "study: u\ncommand: echo t=300\nmetric t: 't=([0-9.]+)' unit ms\nrepeats: 4\npin: none\n" > unit-ms.conf
"$H" run unit-s.conf -o unit-s.csv -q 2> /dev/null && "$H" run unit-ms.conf -o unit-ms.csv -q 2> /dev/null || fail "unit studies"
"$H" compare unit-ms.csv unit-s.csv > unit.out 2> unit.err && fail "compare across units passed"
[ ! -s unit.out ] && [ "$(wc -l < unit.err)" -eq 1 ] && grep -q "NEW's metric t \[ms, lower is better\] and BASE's t \[s, lower\] differ" unit.err ||
    fail "compare across units: $(cat unit.out unit.err)"
# a setup that fails stops the study before --overwrite empties its CSV
printf 'study: s\ncommand: true\nrepeats: 2\npin: none\n' > keep.conf
"$H" run keep.conf -o keep.csv -q 2> /dev/null || fail "the study to keep"
cp keep.csv keep.bak
printf 'study: s\ncommand: true\nsetup: false\nrepeats: 2\npin: none\n' > badsetup.conf
"$H" run badsetup.conf -o keep.csv --overwrite -q 2> setup.err && fail "a failed setup ran the study"
grep -q "badsetup.conf:3: setup: exited with status 1" setup.err || fail "setup: $(cat setup.err)"
cmp -s keep.csv keep.bak || fail "a failed setup emptied the CSV"
# a setup or a version that never ends is ended at the study's timeout
printf 'study: s\ncommand: true\nsetup: sleep 1000\ntimeout: 1\nrepeats: 1\npin: none\n' > hang.conf
timeout 30 "$H" run hang.conf -o hang.csv -q 2> hang.err; rc=$?
[ "$rc" -eq 1 ] && grep -q "hang.conf:3: setup: still running after the study's timeout (1 s); ended" hang.err ||
    fail "a setup that never ends (rc $rc): $(cat hang.err)"
printf 'study: s\ncommand: true\nversion: sleep 1000\ntimeout: 1\nrepeats: 1\npin: none\n' > vhang.conf
timeout 30 "$H" run vhang.conf -o vhang.csv -q 2> vhang.err || fail "a version that never ends hung or failed the study"
grep -q "^harness: warning: vhang.conf:3: version: still running at the study's timeout, ended; program_version is '-'$" vhang.err ||
    fail "a version that never ends: $(cat vhang.err)"
printf 'study: s\ncommand: true\nversion: false\nrepeats: 1\npin: none\n' > vfail.conf
"$H" run vfail.conf -o vfail.csv -q 2> vfail.err || fail "a failing version failed the study"
grep -q "^harness: warning: vfail.conf:3: version: failed; program_version is '-'$" vfail.err || fail "version: false: $(cat vfail.err)"
# inputs that are no text file: one line naming them, no hang, no memory eaten
printf 'study: n\ncommand: true\0junk\n' > nul.conf
"$H" run nul.conf --dry-run > /dev/null 2> nul.err && fail "a NUL byte in a config accepted"
[ "$(cat nul.err)" = "nul.conf:2: control character 0x00 in the line" ] || fail "NUL config: $(cat nul.err)"
mkdir -p adir.conf
"$H" run adir.conf --dry-run 2> adir.err && fail "a folder as a config accepted"
[ "$(cat adir.err)" = "adir.conf: cannot read config: Is a directory" ] || fail "folder config: $(cat adir.err)"
printf 'study: z\ncommand: cat t\ntemplate t: /dev/zero\nrepeats: 1\npin: none\n' > zero.conf
(ulimit -v 4000000; timeout 30 "$H" run zero.conf --dry-run > /dev/null 2> zero.err) && fail "/dev/zero as a template accepted"
[ "$(cat zero.err)" = "zero.conf:3: template t: /dev/zero: not a regular file (a device?)" ] || fail "/dev/zero: $(cat zero.err)"
printf 'A\0B{n}\n' > tnul.txt
printf 'study: z\ncommand: cat t\ntemplate t: tnul.txt\nrepeats: 1\npin: none\n' > tnul.conf
"$H" run tnul.conf --dry-run > /dev/null 2> tnul.err && fail "a template with a NUL byte accepted"
grep -q "^tnul.conf:3: template t: tnul.txt holds a NUL byte" tnul.err || fail "NUL template: $(cat tnul.err)"
printf "study: f\ncommand: mkfifo out.txt\nmetric t: 't=([0-9]+)' from out.txt unit ms\nrepeats: 1\npin: none\n" > fifo.conf
timeout 30 "$H" run fifo.conf -o fifo.csv -q > /dev/null 2>&1; rc=$?
[ "$rc" -eq 1 ] && grep -q ",error,out.txt: not a regular file," fifo.csv || fail "a FIFO as the metric's file (rc $rc)"
echo "ok"
