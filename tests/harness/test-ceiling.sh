#!/bin/bash
# harness ceiling: one-worker copies of a study's workload at once, one per
# core where the study pins its workers, against one alone; the file it
# writes, table's efficiency against it, and a machine (or a run) with one
# allowed core, or a study with no parallel run, refused in one line.
# usage: test-ceiling.sh HARNESS
set -u
. "$(dirname "$0")/common.sh"
test_setup ceiling "$1" "$1"
command -v taskset > /dev/null || fail "taskset missing (util-linux)"
[ "$(nproc)" -ge 2 ] || { echo "SKIP: one CPU: no ceiling to measure"; exit 77; }
cat > c.conf <<'CONF'
command: awk 'BEGIN{for(i=0;i<3e6;i++)s+=i; print s}'
threads: 1 2
repeats: 3
CONF
"$H" ceiling c.conf -o ceil.csv --repeats 2 > ceil.out 2> ceil.err || { cat ceil.out ceil.err; fail "ceiling failed"; }
cat ceil.out ceil.err
grep -q '^W=2: each copy at [0-9.]* of a copy alone (median of 4, ' ceil.out || fail "no W=2 line"
python3 - <<'PY' || fail "the ceiling file"
import csv
rows = list(csv.DictReader(open("ceil.csv")))
assert [r["workers"] for r in rows] == ["2"], rows
r = rows[0]
assert 0.1 < float(r["ratio_median"]) < 1.5 and r["repeats"] == "2" and len(r["fingerprint"]) == 16, r
assert float(r["ratio_min"]) <= float(r["ratio_median"]) <= float(r["ratio_max"]), r
PY
"$H" run c.conf -o study.csv -q > /dev/null 2>&1 || fail "the study"
fp=$(python3 -c 'import csv; print(next(csv.DictReader(open("study.csv")))["fingerprint"])')
cp ceil.csv "ceiling-$fp.csv"   # found beside the CSV without --ceiling
"$H" table study.csv > t.md || fail "table"
grep -q "| awk T=2 | 3/3 | .* | [0-9.]* ([0-9.]* of [0-9.]*) |" t.md || { cat t.md; fail "no efficiency against the ceiling"; }
"$H" table study.csv --format json | python3 -c 'import json,sys; d=json.load(sys.stdin); assert any(c["ceiling"] for c in d["configurations"] if c.get("ceiling"))' ||
    fail "json: no ceiling"
taskset -c 0 "$H" ceiling c.conf -o one.csv > one.out 2> one.err && fail "one allowed core accepted"
[ "$(wc -l < one.err)" -eq 1 ] && grep -q "only one core is allowed here" one.err || fail "one core: $(cat one.err)"
printf 'command: true\nrepeats: 1\n' > serial.conf
"$H" ceiling serial.conf > /dev/null 2> s.err && fail "a study without parallel runs accepted"
grep -q "plans no pinned run of 2 to" s.err || fail "serial: $(cat s.err)"
echo "ok"
