#!/bin/bash
# `ceiling: rounds`: harness run measures one repeat of the ceiling's copies
# (and its step) before each round of an `order: rounds` study, into
# STEM-ceiling.csv beside its CSV, one row per worker count and round;
# table finds that file and pools its rounds (the median of each figure);
# --resume adds to it (a round measured before it, not again; a torn row
# dropped), a new study starts it again; a bad value, the key without
# `order: rounds`, and a machine with one allowed core are refused in one
# line before any run, and before --overwrite empties the CSV. An empty
# file of the study's own leaves table the machine's ceiling-FP.csv. With
# raytrace: each scene's rounds have copies of that scene, and table reads
# each scene against its own.
# usage: test-ceiling-rounds.sh HARNESS [RAYTRACE SOURCE_ROOT]
set -u
. "$(dirname "$0")/common.sh"
RT=${2:+$(abs "$2")} SRC=${3:+$(abs "$3")}
test_setup ceiling-rounds "$1" "$1"
command -v taskset > /dev/null || fail "taskset missing (util-linux)"
[ "$(nproc)" -ge 2 ] || { echo "SKIP: one CPU: no ceiling to measure"; exit 77; }
cat > c.conf <<'CONF'
command: awk 'BEGIN{for(i=0;i<2e6;i++)s+=i; print s}'
threads: 1 2
repeats: 3
order: rounds
ceiling: rounds
CONF
"$H" run c.conf -o study.csv > run.out 2> run.err || { cat run.err; fail "the study"; }
grep -q "ceiling: rounds: the copies before each round, into study-ceiling.csv" run.err || { cat run.err; fail "no line naming the file"; }
# each round's copies come before that round's runs
grep -E '^(ceiling: W=2|\[[0-9]/6\])' run.err | sed -E 's/^(ceiling): W=2.*/C/; s/^\[[0-9]\/6\].* r([0-9]):.*/\1/' | tr -d '\n' > order.txt
[ "$(cat order.txt)" = "C00C11C22" ] || { cat run.err; fail "copies and rounds interleaved as $(cat order.txt)"; }
python3 - <<'PY' || fail "the rounds' file"
import csv
rows = list(csv.DictReader(open("study-ceiling.csv")))
assert [(r["workers"], r["round"], r["repeats"]) for r in rows] == [("2", str(k), "1") for k in range(3)], rows
study = list(csv.DictReader(open("study.csv")))
assert all(r["fingerprint"] == study[0]["fingerprint"] for r in rows), rows
assert all(0 < float(r["step"]) <= 1.05 and float(r["together"]) > 0 for r in rows), rows
PY
"$H" table study.csv > t.md || fail "table"
tr '\n' ' ' < t.md | grep -q "the median of 3 rounds measured between the study's own" || { cat t.md; fail "rounds not named"; }
grep -qE "\| awk T=2 \| 3/3 \| .*pace [0-9.]+ of [0-9.]+\) \|" t.md || { cat t.md; fail "no pace against the rounds"; }
# pooled: the median of each figure over the rounds, not the first row;
# the pace: each run's against its own round's copies, their median. The
# 2-thread runs rewritten to 10, 40 and 20 ms by round, the copies
# together to 14, 40 and 36: paces 0.7, 0.5 and 0.9, median 0.7, where
# the pooled figures would give 36 / (2 x 20) = 0.9.
python3 - <<'PY' || fail "rewrite"
import csv
rows = list(csv.DictReader(open("study-ceiling.csv")))
for r, tog, ratio in zip(rows, (14, 40, 36), ("0.5", "0.9", "0.7")):
    r["together"], r["ratio_median"] = str(tog), ratio
w = csv.DictWriter(open("pooled.csv", "w", newline=""), fieldnames=list(rows[0]))
w.writeheader(); w.writerows(rows)
study = list(csv.DictReader(open("study.csv")))
for r in study:
    if r["threads"] == "2":
        r["wall_ms"] = str((10, 40, 20)[int(r["repeat"])])
w = csv.DictWriter(open("paired.csv", "w", newline=""), fieldnames=list(study[0]))
w.writeheader(); w.writerows(study)
PY
"$H" table paired.csv --ceiling pooled.csv --format json > p.json || fail "table --ceiling"
python3 - <<'PY' || { cat p.json; fail "the rounds pooled"; }
import json
c = [c for c in json.load(open("p.json"))["configurations"] if c["workers"] == 2][0]
assert abs(c["ceiling"] - 0.7) < 1e-9, c
assert abs(c["ceiling_pace"] - 0.7) < 1e-9, c
PY
"$H" table paired.csv --ceiling pooled.csv > p.md || fail "table --ceiling (md)"
tr '\n' ' ' < p.md | grep -q "a pace is the median of each run's against the copies of its own round" ||
  { cat p.md; fail "the paired pace unsaid"; }
# --resume with a fourth round adds its row; a new study starts the file again
"$H" run c.conf -o study.csv --resume --set repeats=4 -q > /dev/null 2> resume.err || { cat resume.err; fail "--resume"; }
[ "$(grep -c '^[0-9a-f]*,.*,2,1,' study-ceiling.csv)" -eq 4 ] && tail -1 study-ceiling.csv | grep -q ',3,-$' ||
  { cat study-ceiling.csv; fail "--resume: the fourth round's row"; }
# a round whose copies ran but not all its runs (stopped there): --resume
# runs the rest and keeps that round's row, one; a torn row is dropped
head -n -1 study.csv > cut.csv && mv cut.csv study.csv
cp study-ceiling.csv whole.csv
printf 'torn,row' >> study-ceiling.csv
"$H" run c.conf -o study.csv --resume --set repeats=4 -q > /dev/null 2> again.err || { cat again.err; fail "--resume again"; }
grep -q "ceiling: rounds: study-ceiling.csv: dropping a torn last row" again.err || { cat again.err; fail "torn row unsaid"; }
cmp -s whole.csv study-ceiling.csv || { diff whole.csv study-ceiling.csv; fail "--resume: the rounds file changed"; }
[ "$(wc -l < study.csv)" -eq 9 ] || fail "--resume: the round's last run not run"
# a worker count the study grew by gets its row in a round that has the
# others' (here round 3's W=2 row made another W's, as if W=2 were new)
sed -i '$ s/^\([0-9a-f]*,[^,]*\),2,/\1,3,/' study-ceiling.csv
head -n -1 study.csv > cut.csv && mv cut.csv study.csv
"$H" run c.conf -o study.csv --resume --set repeats=4 -q > /dev/null 2> grew.err || { cat grew.err; fail "--resume (grown)"; }
python3 - <<'PY' || { cat study-ceiling.csv; fail "--resume: the new worker count not measured"; }
import csv
rows = list(csv.DictReader(open("study-ceiling.csv")))
assert [(r["round"], r["workers"]) for r in rows] == [("0", "2"), ("1", "2"), ("2", "2"), ("3", "3"), ("3", "2")], rows
PY
sed -i '5 s/^\([0-9a-f]*,[^,]*\),3,/\1,2,/; $d' study-ceiling.csv
# a rounds file that is not a file is refused before --overwrite empties the study
mkdir dir-ceiling.csv
cp study.csv dir.csv
"$H" run c.conf -o dir.csv --overwrite -q > /dev/null 2> dir.err && fail "a folder as the rounds file accepted"
[ "$(wc -l < dir.err)" -eq 1 ] && grep -q "dir-ceiling.csv: not a regular file" dir.err || fail "folder: $(cat dir.err)"
cmp -s study.csv dir.csv || fail "a refused rounds file: --overwrite emptied the study"
# ... and a folder that cannot take a new one (as another user: root may write anywhere)
if [ "$(id -u)" -ne 0 ]; then echo "not root: a folder another user cannot write not checked"; else
  command -v setpriv > /dev/null || fail "setpriv missing (util-linux)"
  ro=$(mktemp -d /tmp/hx-ceiling-ro-XXXXXX) && chmod 755 "$ro"
  # the harness copied there: the build may be in a folder only root can enter
  cp "$H" "$ro/harness" && cp c.conf study.csv "$ro"/ && chmod 755 "$ro/harness" && chmod 644 "$ro/c.conf" && chmod 666 "$ro/study.csv"
  (cd "$ro" && setpriv --reuid=65534 --regid=65534 --clear-groups ./harness run c.conf -o study.csv --overwrite -q) \
    > /dev/null 2> ro.err && { rm -rf "$ro"; fail "a rounds file its folder cannot take accepted"; }
  cmp -s study.csv "$ro/study.csv"; same=$?
  rm -rf "$ro"
  grep -q "cannot create study-ceiling.csv there: Permission denied" ro.err || fail "unwritable folder: $(cat ro.err)"
  [ $same -eq 0 ] || fail "an unwritable folder: --overwrite emptied the study"
fi
# a rounds file of another shape is not appended to
printf 'a,b\n1,2\n' > other-ceiling.csv
cp study.csv other.csv
"$H" run c.conf -o other.csv --resume --set repeats=4 -q > /dev/null 2> other.err && fail "a foreign rounds file appended to"
[ "$(wc -l < other.err)" -eq 1 ] && grep -q "other-ceiling.csv: its header is not this harness's" other.err ||
  fail "foreign file: $(cat other.err)"
[ "$(cat other-ceiling.csv)" = "$(printf 'a,b\n1,2')" ] || fail "the foreign file changed"
"$H" run c.conf -o study.csv --overwrite -q > /dev/null 2>&1 || fail "--overwrite"
[ "$(grep -c ',2,1,' study-ceiling.csv)" -eq 3 ] || { cat study-ceiling.csv; fail "a new study kept the old rounds"; }
# an own file with no row of this machine leaves the machine's file its turn
fp=$(python3 -c 'import csv; print(next(csv.DictReader(open("study.csv")))["fingerprint"])')
cp pooled.csv "ceiling-$fp.csv"
cp study-ceiling.csv kept-ceiling.csv
head -1 kept-ceiling.csv > study-ceiling.csv
"$H" table study.csv > e.md 2> e.err || { cat e.err; fail "table with an empty rounds file"; }
grep -q "ceiling from ceiling-$fp.csv" e.md || { cat e.md; fail "an empty rounds file hid ceiling-$fp.csv"; }
mv kept-ceiling.csv study-ceiling.csv
# a ceiling of another scene is no ceiling of this one: said, not named
sed 's/,-$/,other/' study-ceiling.csv > other-scene.csv
"$H" table study.csv --ceiling other-scene.csv > os.md 2> os.err || { cat os.err; fail "table, another scene's ceiling"; }
grep -q "other-scene.csv has no row of this study's machine, metric and scenes: not used" os.err ||
  { cat os.err; fail "another scene's ceiling unsaid"; }
grep -q "against this machine's ceiling" os.md && { cat os.md; fail "another scene's ceiling named"; }
# bad input: one line naming the file and line, nothing run
printf 'command: true\nthreads: 1 2\norder: rounds\nceiling: sometimes\n' > bad.conf
"$H" run bad.conf -o bad.csv > /dev/null 2> bad.err && fail "ceiling: sometimes accepted"
[ "$(wc -l < bad.err)" -eq 1 ] && grep -q "bad.conf:4: ceiling: expected off|rounds, got 'sometimes'" bad.err ||
  fail "bad value: $(cat bad.err)"
printf 'command: true\nthreads: 1 2\nceiling: rounds\n' > nested.conf
"$H" run nested.conf -o nested.csv > /dev/null 2> nested.err && fail "ceiling: rounds without order: rounds accepted"
[ "$(wc -l < nested.err)" -eq 1 ] && grep -q "nested.conf:3: ceiling: rounds .* it needs order: rounds" nested.err ||
  fail "nested: $(cat nested.err)"
taskset -c 0 "$H" run c.conf -o one.csv > /dev/null 2> one.err && fail "one allowed core accepted"
grep -q "ceiling: rounds: only one core is allowed here" one.err || fail "one core: $(cat one.err)"
[ ! -s one.csv ] || [ "$(wc -l < one.csv)" -le 1 ] || fail "one core: runs were recorded"
# ... before --overwrite empties the study, and in a dry run
cp study.csv before.csv
taskset -c 0 "$H" run c.conf -o study.csv --overwrite > /dev/null 2> ow.err && fail "one core: --overwrite accepted"
[ "$(wc -l < ow.err)" -eq 1 ] && grep -q "only one core is allowed here" ow.err || fail "one core, --overwrite: $(cat ow.err)"
cmp -s before.csv study.csv || fail "a refused --overwrite emptied the study"
taskset -c 0 "$H" run c.conf --dry-run > /dev/null 2> dry.err && fail "one core: --dry-run accepted"
grep -q "only one core is allowed here" dry.err || fail "one core, --dry-run: $(cat dry.err)"
# raytrace: each scene's rounds, with copies of that scene
if [ -z "$RT" ]; then echo "raytrace not built here: scenes not checked"; else
cat > rt.conf <<CONF
scene_dir: $SRC/scenes
scenes: demo glass
backend: serial openmp
threads: 1 2
resolution: 160x120
repeats: 2
order: rounds
ceiling: rounds
CONF
"$H" run rt.conf -o rt.csv --raytrace "$RT" > /dev/null 2> rt.err || { cat rt.err; fail "the raytrace study"; }
grep -q "^ceiling: W=2 of glass: each copy's render_ms" rt.err || { cat rt.err; fail "no scene on the W= line"; }
python3 - <<'PY' || { cat rt-ceiling.csv; fail "the scenes' rounds"; }
import csv
rows = list(csv.DictReader(open("rt-ceiling.csv")))
assert [(r["scene"], r["round"]) for r in rows] == [("demo", "0"), ("demo", "1"), ("glass", "0"), ("glass", "1")], rows
# glass's copies render glass: more work than demo's at this size
demo, glass = (sorted(float(r["alone"]) for r in rows if r["scene"] == s) for s in ("demo", "glass"))
assert glass[0] > 1.5 * demo[-1], (demo, glass)
for r, tog in zip(rows, (10, 30, 40, 60)):
    r["together"] = str(tog)
w = csv.DictWriter(open("rt-pooled.csv", "w", newline=""), fieldnames=list(rows[0]))
w.writeheader(); w.writerows([rows[0], rows[2], rows[1], rows[3]])  # the scenes interleaved
PY
"$H" table rt.csv --ceiling rt-pooled.csv --format json > rt.json || fail "table of the scenes"
python3 - <<'PY' || { cat rt.json; fail "a scene read against another's ceiling"; }
import json
import csv, json, statistics
tog = {"demo": (10, 30), "glass": (40, 60)}  # each scene's rounds
runs = [r for r in csv.DictReader(open("rt.csv")) if r["threads"] == "2" and r["status"] == "ok"]
cs = [c for c in json.load(open("rt.json"))["configurations"] if c["workers"] == 2]
assert sorted(c["scene"] for c in cs) == ["demo", "glass"], cs
for c in cs:
    want = statistics.median(tog[c["scene"]][int(r["repeat"])] / (2 * float(r["render_ms"]))
                             for r in runs if r["scene"] == c["scene"])
    assert abs(c["ceiling_pace"] - want) < 1e-3 * want, (c, want)
PY
fi
echo "PASS: ceiling rounds"
