#!/bin/bash
# harness table's statistics on a hybrid study with known times
# T(threads, ranks) = 0.2 + 8 / (threads * ranks) ms (fake renderer, rows
# rewritten), so every series has a known serial fraction in [0, 1]:
#   - a series is one fixed value of every dimension but the swept one:
#     per T over ranks and per P over threads, never one lump;
#   - an oversubscribed point is marked and left out of its fit;
#   - times that grow with workers give a fit marked implausible, and no
#     Karp-Flatt value where the speedup is below 1;
#   - the default Markdown table fits 100 columns; --format json parses.
# usage: test-stats.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup stats "$1" "$2"
echo "# dummy" > ok.txt
# an mpirun that runs the program once: the fake renderer stands for all ranks
printf '#!/bin/sh\nwhile [ $# -gt 0 ] && [ ! -x "$1" ]; do case $1 in -np|--map-by|--bind-to|-x) shift 2 ;; *) shift ;; esac; done\nexec "$@"\n' > mpirun
chmod +x mpirun
printf 'study: hyb\nscene_dir: .\nscenes: ok\nbackend: mpi\nthreads: 1 2\nranks: 1 2\nrepeats: 4\npin: none\noversubscribe: allow\nmpirun: %s\nraytrace: %s\n' \
    "$T/mpirun" "$FAKE" > hyb.conf
"$H" run hyb.conf -o raw.csv -q 2> run.err || { cat run.err; fail "hybrid study"; }
[ "$(($(wc -l < raw.csv) - 1))" -eq 16 ] || fail "expected 16 rows"
# times from the model, a little spread per repeat; rows by column name
rewrite() { # IN OUT AWK-EXPRESSION-FOR-TIME [OVERSUB-T OVERSUB-P]
    awk -F, -v OFS=, -v ot="${4:-0}" -v op="${5:-0}" '
        NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; print; next }
        { t = $c["threads"]; p = $c["ranks"]; r = $c["repeat"];
          $c["render_ms"] = sprintf("%.4f", '"$3"' * (1 + 0.01 * r));
          $c["oversubscribed"] = t == ot && p == op ? 1 : 0   # as if on a 4-core machine
          print }' "$1" > "$2"
}
rewrite raw.csv hyb.csv '0.2 + 8 / (t * p)'
"$H" table hyb.csv > t.md 2> t.err || { cat t.err; fail "table"; }
cat t.md
for s in "mpi T=1 | ranks" "mpi T=2 | ranks" "mpi P=1 | threads" "mpi P=2 | threads"; do
    grep -q "| ok | $s | 8 | 0.0[0-9]* " t.md || fail "no series '$s' with a serial fraction in [0, 0.1)"
done
[ "$(grep -c '| ok | mpi' t.md | head -1)" -ge 4 ] || fail "series missing"
awk 'length($0) > 100 { bad = 1 } END { exit bad }' t.md || fail "the default table is wider than 100 columns"
"$H" table --wide hyb.csv | grep -q 'Karp-Flatt' || fail "--wide lacks its columns"

# an oversubscribed point is marked and kept out of its fit
rewrite raw.csv over.csv '0.2 + 8 / (t * p)' 2 2
"$H" table over.csv > o.md || fail "table over"
grep -q '| ok | mpi T=2 P=2 | .*[| ]OS[ |]' o.md && grep -q '^Notes: .*OS = oversubscribed' o.md ||
    fail "the oversubscribed point is not marked"
grep -q '| ok | mpi T=2 | ranks | 4 | - | .* no fit L4 |$' o.md ||
    fail "the suspect point was fitted"
"$H" table --include-suspect over.csv | grep -q '| ok | mpi T=2 | ranks | 8 |' || fail "--include-suspect"

# slower with more workers: an implausible fit, no Karp-Flatt below speedup 1
rewrite raw.csv worse.csv '1 + t * p'
"$H" table --wide worse.csv > w.md || fail "table worse"
grep -q 'implausible: serial fraction outside \[0, 1\]' w.md || fail "an impossible fit is not marked"
kf=$(grep '| ok | mpi T=2 P=2 |' w.md | head -1 | awk -F'|' '{ gsub(/ /, "", $13); print $13 }')
[ "$kf" = "-" ] || fail "Karp-Flatt '$kf' printed for a speedup below 1"
grep -q 'slower than 1 worker' w.md || fail "a slowdown is not noted"

# JSON
"$H" table --format json hyb.csv > t.json || fail "json"
command -v python3 > /dev/null || fail "python3 missing (it reads the JSON; scripts/install-deps.sh)"
python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); assert d["schema"]=="raybench-table/1"; assert len(d["configurations"])==4; assert len(d["fits"])==4; assert all(0<=f["serial_fraction"]<=1 for f in d["fits"]); assert all(c["median_ci95_ms"][0]<=c["median_ms"]<=c["median_ci95_ms"][1] for c in d["configurations"]); assert all(c["speedup_a_ci95"][0]<=c["speedup_a"]<=c["speedup_a_ci95"][1] for c in d["configurations"] if c["axis"]>1)' t.json ||
    fail "the JSON does not hold the study: $(cat t.json)"
echo "stats test passed"
