#!/bin/bash
# harness ceiling: one-worker copies of a study's workload at once, one per
# core where the study pins its workers, against one alone, each measured by
# the metric table reads the study by; the file it writes, table's
# efficiency against it (and not against a ceiling of another metric), and
# a machine (or a run) with one allowed core, or a study with no parallel
# run, refused in one line. The step: W pinned threads doing their share
# of the copies' work at once, released together; beside two busy
# neighbours on one of the cores they keep well under 0.6 of it.
# usage: test-ceiling.sh HARNESS [RAYTRACE SOURCE_ROOT]
set -u
. "$(dirname "$0")/common.sh"
RT=${2:+$(abs "$2")} SRC=${3:+$(abs "$3")}
test_setup ceiling "$1" "$1"
command -v taskset > /dev/null || fail "taskset missing (util-linux)"
command -v stress-ng > /dev/null || fail "stress-ng missing (scripts/install-deps.sh)"
[ "$(nproc)" -ge 2 ] || { echo "SKIP: one CPU: no ceiling to measure"; exit 77; }
cat > c.conf <<'CONF'
command: awk 'BEGIN{for(i=0;i<3e6;i++)s+=i; print s}'
threads: 1 2
repeats: 3
CONF
"$H" ceiling c.conf -o ceil.csv --repeats 2 > ceil.out 2> ceil.err || { cat ceil.out ceil.err; fail "ceiling failed"; }
cat ceil.out ceil.err
# -o replaces a ceiling file, never another (a results CSV), and says so
# before the copies run
printf 'study,run_id\nx,1\n' > rows.csv
"$H" ceiling c.conf -o rows.csv --repeats 2 > rows.out 2> rows.err && fail "ceiling -o wrote over a CSV"
[ "$(cat rows.csv)" = "$(printf 'study,run_id\nx,1')" ] && [ ! -s rows.out ] || fail "ceiling -o changed the CSV"
[ "$(wc -l < rows.err)" -eq 1 ] && grep -q "rows.csv: holds something else" rows.err || fail "-o refusal: $(cat rows.err)"
grep -q '^W=2: each copy.s wall_ms at [0-9.]* of a copy alone (median of 4, [0-9.]* to [0-9.]*; alone [0-9.]*, together [0-9.]*;' ceil.out ||
  fail "no W=2 line"
grep -q '; a step of [0-9.]* ms on 2 cores at once keeps [0-9.]* (CPU steal [0-9.]*%))$' ceil.out || fail "no step on the W=2 line"
python3 - <<'PY' || fail "the ceiling file"
import csv
rows = list(csv.DictReader(open("ceil.csv")))
assert [r["workers"] for r in rows] == ["2"], rows
r = rows[0]
assert 0.1 < float(r["ratio_median"]) < 1.5 and r["repeats"] == "2" and len(r["fingerprint"]) == 16, r
assert float(r["ratio_min"]) <= float(r["ratio_median"]) <= float(r["ratio_max"]), r
assert r["metric"] == "wall_ms", r
assert 0 <= float(r["steal_pct"]) <= 100, r
assert float(r["together"]) > 0, r
# each of 2 workers does half the copies' work, their wall time over 2 (a
# repeat's, where together is the median of all)
assert 0.1 * float(r["together"]) < float(r["step_ms"]) < float(r["together"]), r
assert 0 < float(r["step"]) <= 1.05, r
PY
# beside two busy neighbours on the second core, a step waits for that
# core's turn: its worker gets a third of it (the scheduler's slices are
# shorter than the step), the first core's all of its own or, on a machine
# busy elsewhere too, a share like the copies'
stress-ng --cpu 2 --taskset 1 --timeout 60s > /dev/null 2>&1 &
sp=$!
"$H" ceiling c.conf -o busy.csv --repeats 2 > busy.out 2> busy.err || { kill $sp; cat busy.out busy.err; fail "ceiling beside a busy core"; }
kill $sp; wait $sp 2> /dev/null
python3 - <<'PY' || { cat ceil.out busy.out; fail "the step beside a busy core"; }
import csv
quiet, busy = (float(next(csv.DictReader(open(f)))["step"]) for f in ("ceil.csv", "busy.csv"))
assert busy < 0.6, (quiet, busy)
PY
"$H" run c.conf -o study.csv -q > /dev/null 2>&1 || fail "the study"
fp=$(python3 -c 'import csv; print(next(csv.DictReader(open("study.csv")))["fingerprint"])')
cp ceil.csv "ceiling-$fp.csv"   # found beside the CSV without --ceiling
"$H" table study.csv > t.md || fail "table"
# E(a) whole, or its pace where the other cells leave the table too narrow
# for it (a wider median or notes column: a slower, busier machine)
grep -qE "\| awk T=2 \| 3/3 \| .* \| [0-9.]+ \(([0-9.]+ of [0-9.]+, )?pace [0-9.]+ of [0-9.]+\) \|" t.md ||
  { cat t.md; fail "no efficiency against the ceiling"; }
"$H" table study.csv --wide > tw.md || fail "table --wide"
grep -q "| awk T=2 | 2 | 3/3 | .* | [0-9.]* ([0-9.]* of [0-9.]*, pace [0-9.]* of [0-9.]*) |" tw.md ||
  { cat tw.md; fail "--wide: no efficiency against the ceiling"; }
tr '\n' ' ' < t.md | grep -q '"pace 0.74 of 0.83": W workers that each did their share' || { cat t.md; fail "the step not explained"; }
tr '\n' ' ' < t.md | grep -q "Its copies ran with CPU steal of [0-9.]*% at 2 workers" || { cat t.md; fail "no steal of the ceiling's copies"; }
"$H" table study.csv --format json | python3 -c 'import json,sys; d=json.load(sys.stdin); assert any(c["ceiling"] and c["ceiling_pace"] > 0 and 0 < c["ceiling_step"] <= 1.05 for c in d["configurations"] if c.get("ceiling"))' ||
    fail "json: no ceiling"
# A metric of the copies' own: n, how many copies were running at once
# (each leaves a file while it runs), better higher. Alone 1, together 2:
# the ceiling is exactly 2, where the copies' wall times could give any
# ratio near 1.
mkdir running
cat > n.conf <<CONF
command: sh -c 'touch $PWD/running/\$\$; sleep 0.4; n=\$(ls $PWD/running | wc -l); sleep 0.3; rm $PWD/running/\$\$; echo n=\$n'
metric n: 'n=([0-9]+)' unit 1 better higher
threads: 1 2
repeats: 1
CONF
"$H" ceiling n.conf -o n.csv --repeats 2 > n.out 2> n.err || { cat n.out n.err; fail "ceiling of a metric failed"; }
grep -q '^W=2: each copy.s n at 2.000 of a copy alone (median of 4, 2.000 to 2.000; alone 1, together 2; CPU steal [0-9.]*%; a step of ' n.out ||
  { cat n.out n.err; fail "the copies were not measured by their metric n"; }
python3 -c 'import csv; r = next(csv.DictReader(open("n.csv"))); assert r["metric"] == "n" and r["ratio_median"] == "2.0000", r' ||
  fail "n.csv: $(cat n.csv)"
# ... and a ceiling of wall_ms is not the ceiling of a table that reads n
"$H" run n.conf -o nstudy.csv -q > /dev/null 2>&1 || fail "the n study"
"$H" table nstudy.csv --ceiling ceil.csv > nt.md 2> nt.err || { cat nt.err; fail "table of n"; }
grep -q "ceil.csv measures wall_ms, this table reads n: not used" nt.err || { cat nt.err; fail "a wall_ms ceiling used for n"; }
grep -q " of [0-9.]*) |" nt.md && { cat nt.md; fail "efficiency of n against a wall_ms ceiling"; }
grep -q "against this machine's ceiling" nt.md && { cat nt.md; fail "a ceiling named that gave nothing"; }
# a file from before the metric column: the copies' wall time, said so
cut -d, -f1-9 ceil.csv > old.csv
"$H" table nstudy.csv --ceiling old.csv > ot.md 2> ot.err || fail "table with an old ceiling file"
grep -q " of [0-9.]*) |" ot.md || { cat ot.md; fail "no efficiency against an old ceiling file"; }
grep -q "pace" ot.md && { cat ot.md; fail "a pace without the copies' own values"; }
# a file from before the step: the pace alone
cut -d, -f1-13 ceil.csv > nostep.csv
"$H" table study.csv --ceiling nostep.csv --wide > ns.md 2> /dev/null || fail "table with a ceiling file without step"
grep -q "| awk T=2 | 2 | 3/3 | .* | [0-9.]* ([0-9.]* of [0-9.]*, pace [0-9.]*) |" ns.md || { cat ns.md; fail "no pace without the step"; }
grep -q "pace 0.74 of" ns.md && { cat ns.md; fail "a step explained that the file has not"; }
grep -q "old.csv has no metric column: a ceiling of the copies' wall time, read against n" ot.err ||
  { cat ot.err; fail "an old ceiling file used without a word"; }
"$H" table nstudy.csv --ceiling n.csv > nt2.md 2> /dev/null || fail "table of n with its ceiling"
# the study's runs count themselves alone (n 1, at 1 and 2 threads): efficiency
# 0.5, a quarter of the ceiling 2; and against the copies' own n together (2),
# 1 / (2 x 2): the pace 0.25
grep -q "| 0.500 (0.25 of 2.00, pace 0.25 of [0-9.]*) |" nt2.md || { cat nt2.md; fail "no efficiency of n against its own ceiling"; }
# raytrace's copies: by render_ms, with how much their renders overlapped
if [ -z "$RT" ]; then echo "raytrace not built here: its copies not checked"; else
cat > rt.conf <<CONF
scene_dir: $SRC/scenes
scenes: demo glass
backend: serial openmp
threads: 1 2
resolution: 160x120
repeats: 1
CONF
"$H" ceiling rt.conf -o rt.csv --repeats 2 --raytrace "$RT" > rt.out 2> rt.err || { cat rt.out rt.err; fail "raytrace ceiling failed"; }
grep -q "^W=2 of demo: each copy's render_ms at [0-9.]* of a copy alone (.*; renders overlapping [0-9.]*; a step of [0-9.]* ms on 2 cores at once keeps [0-9.]* (CPU steal [0-9.]*%))$" rt.out ||
  { cat rt.out rt.err; fail "raytrace ceiling: no render_ms or overlap"; }
grep -q "^W=2 of glass: " rt.out || { cat rt.out; fail "raytrace ceiling: the second scene not measured"; }
python3 - <<'PY' || fail "rt.csv: $(cat rt.csv)"
import csv
rows = list(csv.DictReader(open("rt.csv")))
assert [r["scene"] for r in rows] == ["demo", "glass"], rows
assert all(r["metric"] == "render_ms" and 0 <= float(r["overlap"]) <= 1 for r in rows), rows
# each scene's copies render that scene: glass is more work than demo
assert float(rows[1]["alone"]) > 1.5 * float(rows[0]["alone"]), rows
PY
fi
# a table too narrow for E(a)'s whole cell keeps its pace, and says what
# it left out (a study of the 16-core host in results/)
if [ -n "$SRC" ]; then
  "$H" table "$SRC/results/stalls-AL-t1-bvh-2048x1536.csv" --ceiling "$SRC/results/stalls-AL-ceiling-2048x1536.csv" \
    > al.md 2> /dev/null || fail "table of results/stalls-AL-t1-bvh-2048x1536.csv"
  grep -q "| 12.63 | 0.789 (pace 1.03 of 0.97) |" al.md || { cat al.md; fail "the narrow E(a) without its pace"; }
  tr '\n' ' ' < al.md | grep -q "E(a)'s share of the ceiling)" || { cat al.md; fail "the share left out unsaid"; }
fi
# SIGTERM (a job's time limit, `timeout`) ends the copies with the harness:
# none is left to load the machine, and no ceiling is written
printf 'command: sleep 37.5\nthreads: 1 2\nrepeats: 1\n' > slow.conf
"$H" ceiling slow.conf -o slow.csv > /dev/null 2> slow.err &
hp=$!
i=0
until [ "$(pgrep -fc '^sleep 37.5$')" -ge 1 ]; do i=$((i + 1)); [ $i -le 100 ] || fail "no copy started"; sleep 0.1; done
kill -TERM $hp
wait $hp; rc=$?
[ $rc -eq 143 ] || fail "SIGTERM: exit $rc, not 143"
grep -qx "harness ceiling: stopped by SIGTERM: its copies ended, no ceiling written" slow.err || fail "SIGTERM: $(cat slow.err)"
sleep 0.2
pgrep -f '^sleep 37.5$' > /dev/null && fail "a copy outlived the harness"
[ -e slow.csv ] && fail "a ceiling written after SIGTERM"
taskset -c 0 "$H" ceiling c.conf -o one.csv > one.out 2> one.err && fail "one allowed core accepted"
[ "$(wc -l < one.err)" -eq 1 ] && grep -q "only one core is allowed here" one.err || fail "one core: $(cat one.err)"
printf 'command: true\nrepeats: 1\n' > serial.conf
"$H" ceiling serial.conf > /dev/null 2> s.err && fail "a study without parallel runs accepted"
grep -q "plans no pinned run of 2 to" s.err || fail "serial: $(cat s.err)"
echo "ok"
