#!/bin/sh
# Runner test with a fake raytrace: statuses (ok, crash with its signal,
# timeout killing the whole process group, error with the first stderr line,
# missing record, wrong-image), --resume, --dry-run, table and config errors.
# usage: test-runner.sh HARNESS FAKE_RAYTRACE
set -u
H=$1 FAKE=$2
T=$(mktemp -d /tmp/hx-runner-XXXXXX)
trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
. "$(dirname "$0")/common.sh" # need_pgrep, pids_matching
need_pgrep
export FAKE_HANG_S="31.$$" # (this test's own hang duration: common.sh, test_setup)
for s in ok crash hang fail wrong silent; do echo "# dummy" > "$T/$s.txt"; done
cat > "$T/study.conf" <<CONF
study: fake
scene_dir: $T
scenes: ok crash hang fail wrong silent
backend: serial
accel: bvh none
repeats: 2
timeout: 1
raytrace: $FAKE
CONF
start=$(date +%s)
"$H" run "$T/study.conf" -o "$T/out.csv" 2> "$T/log"
rc=$?
end=$(date +%s)
cat "$T/log"
# progress: every dimension with a value, the outcome and the time left
grep -q '^\[1/24\] scene=ok backend=serial accel=bvh pin=close r0: ok render_ms=1.250 (left ~0m[0-9][0-9]s)$' "$T/log" ||
    fail "progress line format"
# failed runs make the study's exit status 1, with one line per configuration
[ $rc -eq 1 ] || fail "run with failed runs exited $rc, want 1"
grep -q 'harness run: 9 configuration(s) had failed runs:' "$T/log" || fail "no failure summary"
grep -q '^  scene=fail backend=serial accel=bvh pin=close: error: raytrace: .*:3: bad thing' "$T/log" || fail "the summary lacks the error's message"
rows=$(($(wc -l < "$T/out.csv") - 1))
[ "$rows" -eq 24 ] || fail "expected 24 rows, got $rows"
n() { grep -c -- "$1" "$T/out.csv"; }
[ "$(n ',ok,,0,')" -eq 6 ] || fail "ok rows: $(n ',ok,,0,')"
[ "$(n ',crash,SIGSEGV,')" -eq 4 ] || fail "crash rows"
[ "$(n ',timeout,killed after 1 s')" -eq 2 ] || fail "timeout rows (killed)"
[ "$(n ',timeout,not run: an earlier repeat')" -eq 2 ] || fail "timeout rows (skipped)"
[ "$(n ',error,raytrace: .*:3: bad thing,')" -eq 2 ] || fail "error rows with stderr line"
# exit 1 is the renderer's answer to bad input: not run again for each repeat
[ "$(n ',error,"not run: an earlier repeat of this configuration exited with status 1')" -eq 2 ] || fail "a deterministic error was run again"
[ "$(n ',error,exit 0 but no record line')" -eq 4 ] || fail "no-record rows"
[ "$(n ',wrong-image,image_fnv1a 00000000000000bb != reference')" -eq 2 ] || fail "wrong-image rows"
grep -q 'newkey=1' "$T/out.csv" || fail "unknown record key not kept in extra"
# a column's values by its name in the header (the fields tested here hold no commas)
column() { awk -F, -v want="$1" 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == want) c = i; next } c { print $c }' "$T/out.csv"; }
column pin_held | grep -q '^yes$' || fail "pin_held=yes missing (cores_actual vs planned)"
# every run that ran has the harness's own measurements: CPU time and peak memory
[ "$(column maxrss_kib | grep -c '^[1-9][0-9]*$')" -ge 12 ] || fail "maxrss_kib missing: $(column maxrss_kib | tr '\n' ' ')"
[ "$(column user_ms | grep -c '^[0-9][0-9.]*$')" -ge 12 ] || fail "user_ms missing: $(column user_ms | tr '\n' ' ')"
pids_matching "^sleep $FAKE_HANG_S\$"
[ -z "$PIDS" ] || fail "a grandchild of a timed-out run survived"
[ $((end - start)) -lt 15 ] || fail "study took $((end - start)) s: timeouts not enforced"
# resume: nothing left to do; then drop 3 rows and resume runs exactly 3
"$H" run "$T/study.conf" -o "$T/out.csv" --resume -q 2> "$T/log2" || fail "resume failed"
grep -q ' 0 rows' "$T/log2" || { cat "$T/log2"; fail "resume re-ran runs"; }
head -n 22 "$T/out.csv" > "$T/cut.csv" && cp "$T/cut.csv" "$T/out.csv"
# (the rows dropped are the 'silent' scene's failing runs: exit 1 again)
"$H" run "$T/study.conf" -o "$T/out.csv" --resume -q 2> "$T/log3"
[ $? -eq 1 ] || { cat "$T/log3"; fail "resume 2: the failing runs did not give exit 1"; }
[ $(($(wc -l < "$T/out.csv") - 1)) -eq 24 ] || fail "resume did not complete the study"
# a torn last row (power loss mid-write) is dropped and its run redone,
# whether the cut leaves the field count intact or not
for cut in 20 400; do
    truncate -s -$cut "$T/out.csv"
    "$H" run "$T/study.conf" -o "$T/out.csv" --resume -q 2> "$T/log4"
    [ $? -le 1 ] || { cat "$T/log4"; fail "resume after a cut of $cut bytes failed"; }
    [ $(($(wc -l < "$T/out.csv") - 1)) -eq 24 ] || fail "resume after a cut of $cut bytes: $(($(wc -l < "$T/out.csv") - 1)) rows, want 24"
    [ "$(cut -d, -f2 "$T/out.csv" | sort | uniq -d | wc -l)" -eq 0 ] || fail "duplicate run ids after a cut of $cut bytes"
done
# without --resume an existing CSV is refused
"$H" run "$T/study.conf" -o "$T/out.csv" -q 2>/dev/null && fail "existing CSV overwritten silently"
# dry run lists runs with planned cores, runs nothing
"$H" run "$T/study.conf" --dry-run > "$T/dry" || fail "dry-run failed"
grep -q 'cores=0' "$T/dry" || fail "dry-run shows no planned cores"
# only the CPUs the process may use are planned (taskset, a Slurm allocation)
command -v taskset > /dev/null || fail "taskset missing (util-linux)"
if [ "$(nproc --all)" -ge 2 ]; then
    taskset -c 1 "$H" run "$T/study.conf" --dry-run > "$T/dry1" || fail "dry-run under taskset failed"
    grep -q 'cores=0' "$T/dry1" && fail "under taskset -c 1 a run was planned on core 0"
    grep -q 'cores=1' "$T/dry1" || fail "under taskset -c 1 no run was planned on core 1"
fi
# table: TLE in the cross table, wrong-image warning
"$H" table "$T/out.csv" > "$T/table" 2> "$T/tlog" || fail "table failed"
grep -q 'TLE' "$T/table" || fail "no TLE in the cross table"
grep -q 'wrong-image' "$T/tlog" || fail "no wrong-image warning"
"$H" table "$T/out.csv" --format csv | grep -q '^scene,configuration' || fail "table csv"
# config errors: file:line, exit 1
printf 'scenes: ok\nthreads: many\n' > "$T/bad.conf"
out=$("$H" run "$T/bad.conf" 2>&1) && fail "bad config accepted"
echo "$out" | grep -q "bad.conf:2: threads" || fail "error without file:line: $out"
"$H" run 2>/dev/null && fail "run without CONFIG accepted"
"$H" table /nonexistent.csv 2>/dev/null && fail "missing CSV accepted"
"$H" bogus 2>/dev/null && fail "unknown command accepted"
for c in run table plot compare topo; do "$H" $c --help > /dev/null || fail "$c --help"; done
echo "runner test passed"
