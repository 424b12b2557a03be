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
"$H" compare crash1.csv set.csv > c5.out || { cat c5.out; fail "a crashed first repeat made the configuration missing"; }
grep -q "1 configuration(s) compared, 0 regression(s)" c5.out || { cat c5.out; fail "crash1 not compared as one configuration"; }
echo "compare test passed"
