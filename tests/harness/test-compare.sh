#!/bin/bash
# harness compare as a user meets it:
#   - an option left unset and the same option set to the renderer's default
#     are one configuration (accel unset against accel: bvh);
#   - a change to half the time is reported as an IMPROVEMENT and passes;
#     to twice the time, a REGRESSION that fails.
# usage: test-compare.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup compare "$1" "$2"
echo "# dummy" > ok.txt
printf 'study: c\nscene_dir: .\nscenes: ok\nrepeats: 5\npin: none\nraytrace: %s\n' "$FAKE" > unset.conf
printf 'study: c\nscene_dir: .\nscenes: ok\naccel: bvh\nrepeats: 5\npin: none\nraytrace: %s\n' "$FAKE" > set.conf
"$H" run unset.conf -o unset.csv -q 2> /dev/null || fail "unset study"
"$H" run set.conf -o set.csv -q 2> /dev/null || fail "set study"
"$H" compare set.csv unset.csv > c1.out || { cat c1.out; fail "accel: bvh against accel unset flagged"; }
grep -q "^NOTE times are not calibrated" c1.out || fail "no note on uncalibrated times"
grep -q "compare: 1 configuration(s) compared, 0 regression(s)" c1.out || { cat c1.out; fail "not compared as one configuration"; }
# the same rows with render_ms scaled (the fake renders in 1.250 ms)
scale() { # IN OUT FACTOR
    awk -F, -v OFS=, -v f="$3" 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "render_ms") c = i; print; next }
                                { $c = $c * f; print }' "$1" > "$2"
}
scale set.csv fast.csv 0.5
scale set.csv slow.csv 2
"$H" compare fast.csv unset.csv > c2.out || { cat c2.out; fail "an improvement failed the check"; }
grep -q "^IMPROVEMENT ok " c2.out || { cat c2.out; fail "the improvement is not reported"; }
grep -q "0 regression(s), 1 improvement(s)" c2.out || { cat c2.out; fail "improvement count"; }
"$H" compare slow.csv unset.csv > c3.out && { cat c3.out; fail "a 2x slowdown passed"; }
grep -q "^REGRESSION ok " c3.out || { cat c3.out; fail "the regression is not reported"; }
"$H" compare --format json slow.csv unset.csv > c4.json && fail "json: a 2x slowdown passed"
command -v python3 > /dev/null || fail "python3 missing (it reads the JSON; scripts/install-deps.sh)"
python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); assert d["schema"]=="raybench-compare/1"; assert d["regressions"]==1; v=d["verdicts"][0]; assert v["verdict"]=="REGRESSION" and abs(v["ratio"]-2)<1e-9' c4.json ||
    fail "compare JSON: $(cat c4.json)"
# per row: render_ms and calib_ms set from two lists (python3 rewrites the CSV)
setrows() { # IN OUT "r1 r2 ..." ["c1 c2 ..."]
    python3 - "$@" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
ms = sys.argv[3].split()
cal = sys.argv[4].split() if len(sys.argv) > 4 else None
for i, r in enumerate(rows):
    r["render_ms"] = ms[i % len(ms)]
    if cal:
        r["extra"] = ";".join([kv for kv in r["extra"].split(";") if kv and not kv.startswith("calib_ms=")] +
                              ["calib_ms=" + cal[i % len(cal)]])
w = csv.DictWriter(open(sys.argv[2], "w", newline=""), fieldnames=list(rows[0].keys()), lineterminator="\n")
w.writeheader()
w.writerows(rows)
PY
}
# samples that cannot tell: never "no change", the detectable change said
setrows set.csv noisy.csv "1.25 1.3 5 6 1.2"
"$H" compare noisy.csv unset.csv > c6.out || { cat c6.out; fail "inconclusive data made compare fail"; }
grep -q "^INCONCLUSIVE ok .*only changes beyond x[0-9.]* are detectable, about [0-9]* repeats a side" c6.out ||
    { cat c6.out; fail "noisy samples not inconclusive"; }
grep -q "0 regression(s), 0 improvement(s), 1 inconclusive" c6.out || { cat c6.out; fail "inconclusive count"; }
# a calibration that varies more than the change: /calib refused, the plain
# time finds the 2.5x slowdown it would hide
setrows set.csv cbase.csv "1.0 1.1 1.2 1.05 1.15" "6.6 106.8 20 50 9"
setrows set.csv cslow.csv "2.5 2.75 3.0 2.625 2.875" "106.8 6.6 90 12 40"
"$H" compare cslow.csv cbase.csv > c7.out && { cat c7.out; fail "a 2.5x slowdown under a noisy calibration passed"; }
grep -q "^NOTE render_ms/calib not used: the calibration varies x16.2" c7.out && grep -q "^REGRESSION ok " c7.out ||
    { cat c7.out; fail "noisy calibration"; }
"$H" compare --metric render_ms/calib cslow.csv cbase.csv > c8.out 2> c8.err && fail "--metric X/calib accepted"
[ "$(wc -l < c8.err)" -eq 1 ] && grep -q "refused: the calibration varies x16.2" c8.err || fail "refusal: $(cat c8.err)"
cat c6.out c7.out c8.err
# a configuration whose first repeat crashed is still the same configuration
awk -F, -v OFS=, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; print; next }
                  NR == 2 { $c["status"] = "crash"; $c["render_ms"] = ""; $c["rec_accel"] = ""; $c["width"] = "" }
                  { print }' unset.csv > crash1.csv
# (and the crash, which BASE never had, is a regression of its own)
"$H" compare crash1.csv set.csv > c5.out && { cat c5.out; fail "a crash in NEW passed"; }
grep -q "1 configuration(s) compared, 1 regression(s)" c5.out &&
    grep -q "^REGRESSION ok .*: 1 of 5 runs in NEW did not end ok (crash 1), 0 of 5 in BASE$" c5.out &&
    grep -q "^no change ok " c5.out || { cat c5.out; fail "crash1 not compared as one configuration"; }
# runs that timed out are slow runs, not missing ones: half of NEW's hit the
# timeout while its ok runs kept BASE's time
python3 - set.csv timeout-new.csv <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
out = [dict(r) for r in rows]
for i, r in enumerate(rows):
    t = dict(r, status="timeout", render_ms="", run_id=r["run_id"] + "-t%d" % i)
    out.append(t)
w = csv.DictWriter(open(sys.argv[2], "w", newline=""), fieldnames=list(rows[0].keys()), lineterminator="\n")
w.writeheader()
w.writerows(out)
PY
"$H" compare timeout-new.csv set.csv > c9.out && { cat c9.out; fail "half the runs timing out passed"; }
grep -q "^REGRESSION ok .*: 5 of 10 runs in NEW did not end ok (timeout 5), 0 of 5 in BASE$" c9.out ||
    { cat c9.out; fail "timeouts not reported"; }
# every run of NEW timed out: no time on that side, still the same metric,
# and a REGRESSION that says why
python3 - set.csv allto.csv <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
for r in rows:
    r["status"], r["render_ms"] = "timeout", ""
w = csv.DictWriter(open(sys.argv[2], "w", newline=""), fieldnames=list(rows[0].keys()), lineterminator="\n")
w.writeheader()
w.writerows(rows)
PY
"$H" compare allto.csv set.csv > c12.out 2> c12.err && { cat c12.out c12.err; fail "every run timing out passed"; }
grep -q "^REGRESSION ok .*: no ok run in NEW (timeout 5" c12.out || { cat c12.out c12.err; fail "all timed out: not said"; }
# one run as fast as BASE's among nine five times slower: the interval,
# wholly past the factor, decides where the minimum alone would not
setrows set.csv ten-base.csv "1.25 1.26 1.24 1.25 1.27"
python3 - ten-base.csv ten-base2.csv ten-slow.csv ten-tail.csv <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
def write(path, ms):
    out = []
    for i, v in enumerate(ms):
        r = dict(rows[i % len(rows)], render_ms=str(v), repeat=str(i))
        r["run_id"] = r["run_id"] + "-%d" % i
        out.append(r)
    w = csv.DictWriter(open(path, "w", newline=""), fieldnames=list(rows[0].keys()), lineterminator="\n")
    w.writeheader()
    w.writerows(out)
base = [1.25 + 0.001 * i for i in range(20)]
write(sys.argv[2], base)
write(sys.argv[3], [1.25] + [6.25 + 0.01 * i for i in range(9)])
# a tenth of the runs ten times slower: the medians agree, the tail does not
write(sys.argv[4], [1.25 + 0.001 * i for i in range(17)] + [12.5, 12.6, 12.7])
PY
"$H" compare ten-slow.csv ten-base2.csv > c10.out && { cat c10.out; fail "a 5x slowdown in 9 of 10 runs passed"; }
grep -q "^REGRESSION ok .*min ratio 1.00, n=10/20" c10.out || { cat c10.out; fail "one fast run held the verdict"; }
"$H" compare ten-tail.csv ten-base2.csv > c11.out || { cat c11.out; fail "a slow tail failed the check"; }
grep -q "^INCONCLUSIVE ok .*; the medians agree, but the slowest tenth of NEW is x[0-9.]* BASE's$" c11.out ||
    { cat c11.out; fail "a tenth of the runs 10x slower called no change"; }
# --format md, the pull-request summary. many: a study of N scenes s00..
# made from IN's rows, its commit and CPU set, and per scene a change:
# "s17=2" scales render_ms, "s05=1.25,1.3,5,6,1.2" sets the samples
many() { # IN OUT N COMMIT CPU "SCENE=CHANGE ..."
    python3 - "$@" <<'PY'
import csv, sys
src, out, n, commit, cpu = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]
plan = dict(p.split("=", 1) for p in sys.argv[6].split()) if len(sys.argv) > 6 else {}
rows = list(csv.DictReader(open(src)))
res = []
for k in range(n):
    name = "s%02d" % k
    for i, r in enumerate(rows):
        r = dict(r, scene=name, git_commit=commit, cpu_model=cpu)
        r["run_id"] = r["run_id"].replace("scene=ok", "scene=" + name)
        vals = plan.get(name, "1").split(",")
        r["render_ms"] = str(float(r["render_ms"]) * float(vals[0])) if len(vals) == 1 else vals[i % len(vals)]
        res.append(r)
w = csv.DictWriter(open(out, "w", newline=""), fieldnames=list(rows[0].keys()), lineterminator="\n")
w.writeheader()
w.writerows(res)
PY
}
# table rows of a summary: lines starting with "| " after the separator
md_rows() { awk '/^\|---/ { t = 1; next } t && /^\| / { print } t && !/^\|/ { t = 0 }' "$1"; }
many set.csv m-base.csv 40 def5678 "Test CPU 9000"
many set.csv m-new.csv 40 abc1234 "Test CPU 9000" "s17=2 s05=1.25,1.3,5,6,1.2 s30=0.5"
"$H" compare --format md m-new.csv m-base.csv > md1.out && { cat md1.out; fail "md: a 2x slowdown passed"; }
# the verdict first: counts, metric, factor, both commits, the CPU in words
head -n 1 md1.out | grep -q '^\*\*FAIL\*\*: \*\*1 regression\*\*, 1 improvement, 37 no change, 1 inconclusive in render\\_ms at factor 1\.80 (alpha 0\.05); new: study c, commit abc1234; base: study c, commit def5678; machine: Test CPU 9000$' ||
    { cat md1.out; fail "md: verdict line"; }
# regressions, then inconclusive, then improvements; "no change" in one line
md_rows md1.out > md1.rows
[ "$(wc -l < md1.rows)" -eq 3 ] || { cat md1.out; fail "md: 3 rows expected"; }
awk 'NR == 1 && /^\| \*\*REGRESSION\*\* \| s17 \| .* \| 2\.00 \[2\.00, 2\.00\] \| 0\.[0-9]+ \|/ { a++ }
     NR == 2 && /^\| INCONCLUSIVE \| s05 \| .* \| x[0-9.]+ \| [0-9]+ \|/ { a++ }
     NR == 3 && /^\| IMPROVEMENT \| s30 \|/ { a++ } END { exit a != 3 }' md1.rows || { cat md1.out; fail "md: row order"; }
grep -q '^_Not shown (37): 37 no change; ' md1.out || { cat md1.out; fail "md: no change not collapsed"; }
# the inconclusive row carries the values the text line says, computed once
"$H" compare m-new.csv m-base.csv > md1.txt
mde=$(sed -n 's/^INCONCLUSIVE s05 .*changes beyond \(x[0-9.]*\) are detectable, about \([0-9]*\) repeats.*/\1 | \2/p' md1.txt)
[ -n "$mde" ] && grep -qF "| $mde |" md1.rows || { cat md1.txt md1.rows; fail "md: detectable change differs from text's"; }
# many regressions: still one screen, the rest counted in one line
many set.csv m-slow.csv 40 abc1234 "Test CPU 9000" "$(for k in $(seq 10 34); do printf 's%02d=2 ' "$k"; done)"
"$H" compare --format md m-slow.csv m-base.csv > md2.out && fail "md: 25 regressions passed"
[ "$(md_rows md2.out | wc -l)" -eq 15 ] && [ "$(wc -l < md2.out)" -le 40 ] || { cat md2.out; fail "md: longer than a screen"; }
md_rows md2.out | grep -vq '^| \*\*REGRESSION\*\* ' && { cat md2.out; fail "md: a row that is not a regression shown first"; }
grep -q '^_Not shown (25): 10 regressions, 15 no change; ' md2.out || { cat md2.out; fail "md: rest line"; }
# a hostile scene name and a report URL: text in the cell, never markup
python3 - slow.csv hostile-new.csv unset.csv hostile-base.csv <<'PY'
import csv, sys
for src, out in ((sys.argv[1], sys.argv[2]), (sys.argv[3], sys.argv[4])):
    rows = list(csv.DictReader(open(src)))
    for r in rows:
        r["scene"] = "<script>|x`y\nz"
    w = csv.DictWriter(open(out, "w", newline=""), fieldnames=list(rows[0].keys()), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
PY
"$H" compare --format md --report $'https://ci.example/r?a=1&b=(2)<x>\n[y]' hostile-new.csv hostile-base.csv > md3.out &&
    fail "md: hostile: a 2x slowdown passed"
md_rows md3.out > md3.rows
grep -qF '| **REGRESSION** | &lt;script&gt;\|x\`y z |' md3.rows || { cat md3.out; fail "md: scene not escaped"; }
grep -q '<script\|<x>\|^z' md3.out && { cat md3.out; fail "md: raw markup or a broken row"; }
# every row as many cells as the header: no unescaped | from the CSV
awk '/^\|/ { gsub(/\\\|/, ""); n = gsub(/\|/, ""); if (!c) c = n; else if (n != c) bad = 1 } END { exit bad || !c }' md3.out ||
    { cat md3.out; fail "md: a row with more cells"; }
[ "$(tail -n 1 md3.out)" = '[Full report](https://ci.example/r?a=1&b=%282%29%3Cx%3E%0A%5By%5D)' ] ||
    { cat md3.out; fail "md: report link"; }
# no regression: PASS and exit 0, as text
"$H" compare --format md fast.csv unset.csv > md4.out || { cat md4.out; fail "md: an improvement failed"; }
head -n 1 md4.out | grep -q '^\*\*PASS\*\*: 0 regressions, 1 improvement, 0 no change, 0 inconclusive ' || { cat md4.out; fail "md: PASS line"; }
# a bad --format names the option in one line; --report only with md
"$H" compare --format html slow.csv unset.csv > bad.out 2> bad.err && fail "--format html accepted"
[ "$(cat bad.err)" = "harness compare: --format: expected text, json or md, got 'html'" ] && [ ! -s bad.out ] ||
    fail "bad --format: $(cat bad.err)"
"$H" compare --report https://x slow.csv unset.csv > /dev/null 2> bad.err && fail "--report without md accepted"
[ "$(wc -l < bad.err)" -eq 1 ] && grep -q -- '--report: only with --format md' bad.err || fail "--report: $(cat bad.err)"
cat md1.out md3.out
echo "compare test passed"
