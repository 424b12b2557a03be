#!/bin/bash
# harness report, opened as a person would: Debian's chromium, headless,
# loads the page from a file:// URL with every network fetch sent to a dead
# proxy, dumps the DOM and takes a screenshot:
#   - the study's tables (provenance, flags, pinning map, statistics, fit,
#     cross table) and its plots inline as SVG; no script, nothing fetched,
#     no console error;
#   - a CSV whose scene name holds <script>, quotes and & shows it as text;
#   - a CSV with no ok rows gives a page that says so; a study of one
#     configuration gives its table and no scaling plot;
#   - a folder that exists and is not a report is refused, untouched.
# usage: test-report.sh HARNESS RAYTRACE SOURCE_ROOT
set -u
. "$(dirname "$0")/common.sh"
RT=$(realpath "$2") SRC=$(realpath "$3")
test_setup report "$1" "$1"
chrome=$(command -v chromium || command -v chromium-browser) ||
    fail "chromium missing (scripts/install-deps.sh installs Debian's chromium)"
command -v gnuplot > /dev/null || fail "gnuplot missing (scripts/install-deps.sh)"
cp "$SRC/scenes/glass.txt" .
printf 'study: rep\nscene_dir: .\nscenes: glass\nbackend: serial openmp\nthreads: 1 2\nresolution: 64x48\nrepeats: 3\npin: close\nraytrace: %s\n' \
    "$RT" > r.conf
"$H" run r.conf -o r.csv -q 2> /dev/null || fail "the study"
"$H" report r.csv -o rep > rep.out 2> rep.err || { cat rep.out rep.err; fail "report"; }
grep -q "^harness report: wrote rep/index.html$" rep.out || { cat rep.out; fail "report: no 'wrote' line"; }
[ -f rep/study1.csv ] && cmp -s r.csv rep/study1.csv || fail "the CSV is not beside the page"
# the browser: network to a dead proxy, so any fetch fails and is logged
view() { # PAGE PREFIX: PREFIX.dom, PREFIX.png, PREFIX.log
    timeout 120 "$chrome" --headless --no-sandbox --disable-gpu --proxy-server=http://127.0.0.1:9 \
        --enable-logging=stderr --v=0 --window-size=1200,3000 --screenshot="$PWD/$2.png" "file://$PWD/$1" \
        > /dev/null 2> "$2.log" || { tail -5 "$2.log"; fail "chromium could not take the screenshot of $1"; }
    timeout 120 "$chrome" --headless --no-sandbox --disable-gpu --proxy-server=http://127.0.0.1:9 \
        --enable-logging=stderr --v=0 --dump-dom "file://$PWD/$1" > "$2.dom" 2>> "$2.log" ||
        { tail -5 "$2.log"; fail "chromium could not dump the DOM of $1"; }
    [ -s "$2.png" ] && [ "$(head -c 4 "$2.png" | tail -c 3)" = PNG ] || fail "$2.png is not a PNG"
    ! grep -Ei 'CONSOLE|Uncaught|Failed to load resource|net::ERR' "$2.log" ||
        fail "$1: a script error or a fetch in the browser's log"
}
view rep/index.html page
for t in Provenance "Runs, pinning and noise" "Per configuration" "Amdahl fit" "Scenes x configurations"; do
    grep -q "<h3>$t" page.dom || fail "the page has no '$t' table"
done
# the pinning map folded when every run held, open when one did not
if python3 -c 'import csv, sys; sys.exit(any(r["pin_held"] not in ("yes", "-") for r in csv.DictReader(open("r.csv"))))'; then
    grep -q "<details><summary><b>Pinning map</b>: every run's pinning held" page.dom || fail "no folded pinning map"
else
    grep -q "<details open=\"\"><summary><b>Pinning map</b>: some runs' pinning did not hold" page.dom ||
        fail "the pinning map of runs whose pinning did not hold is folded"
fi
# the plots come before the tables
[ "$(grep -o '<svg\|<h3>Per configuration' page.dom | head -1)" = "<svg" ] || fail "a table before the plots"
[ "$(grep -o '<table' page.dom | wc -l)" -ge 6 ] || fail "fewer than 6 tables"
nsvg=$(grep -o '<svg' page.dom | wc -l)
[ "$nsvg" -ge 3 ] || fail "expected the speedup, efficiency and scenes plots inline, found $nsvg <svg>"
grep -q "openmp T=2" page.dom || fail "the configuration T=2 is not in the page"
! grep -qi '<script' page.dom || fail "a script in the page"
! grep -Eqi '(src|href)="(https?:)?//|@import|url\(' page.dom || fail "the page refers to something outside it"
echo "  page: $(grep -o '<table' page.dom | wc -l) tables, $nsvg plots, screenshot $(stat -c %s page.png) bytes"

# a scene name with markup in it (a CSV is anyone's): text, not markup
python3 - r.csv evil.csv << 'EOF'
import csv, sys
rows = list(csv.reader(open(sys.argv[1], newline="")))
i = rows[0].index("scene")
for r in rows[1:]:
    r[i] = "<script>alert(\"x\")</script> & 'q'"
csv.writer(open(sys.argv[2], "w", newline=""), lineterminator="\n").writerows(rows)
EOF
"$H" report evil.csv -o evil > /dev/null 2>&1 || fail "report of the marked-up scene"
view evil/index.html evil
! grep -qi '<script' evil.dom || fail "the scene name became a script element"
grep -q '&lt;script&gt;alert("x")&lt;/script&gt; &amp;' evil.dom || fail "the scene name is not shown as text"

# no ok rows: said, and no plot
awk -F, -v OFS=, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "status") c = i; print; next } { $c = "error"; print }' \
    r.csv > bad.csv
"$H" report bad.csv -o bad > /dev/null 2>&1 || fail "report of a CSV without ok rows"
grep -q "No ok rows" bad/index.html || fail "no ok rows: not said"
! grep -q "<svg" bad/index.html || fail "no ok rows: a plot drawn"
# one configuration: its table, no scaling plot
printf 'study: one\nscene_dir: .\nscenes: glass\nresolution: 32x24\nrepeats: 3\npin: none\nraytrace: %s\n' "$RT" > one.conf
"$H" run one.conf -o one.csv -q 2> /dev/null || fail "the one-configuration study"
"$H" report one.csv -o one > /dev/null 2>&1 || fail "report of one configuration"
grep -q "<h3>Per configuration" one/index.html || fail "one configuration: no table"
! grep -q "Speedup against one worker" one/index.html || fail "one configuration: a speedup plot"
# a folder that is not a report: refused, untouched
mkdir mine && echo keep > mine/notes.txt
"$H" report r.csv -o mine > /dev/null 2> mine.err && fail "a folder that is not a report was written"
grep -q "mine exists and is not a report" mine.err && [ "$(wc -l < mine.err)" -eq 1 ] || { cat mine.err; fail "refusal"; }
[ "$(ls mine)" = notes.txt ] && [ "$(cat mine/notes.txt)" = keep ] || fail "the folder was changed"
"$H" report r.csv -o rep > /dev/null 2>&1 || fail "a report folder could not be written again"
echo "ok"
