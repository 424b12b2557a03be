#!/bin/bash
# harness history publish, opened as a person would: Debian's chromium,
# headless, loads the pages from file:// URLs with every network fetch sent
# to a dead proxy, dumps the DOM and takes screenshots:
#   - twelve commits of two machines: index.html lists the metrics, machines
#     and studies; each metric's page holds one plot per machine (inline
#     SVG), no script, nothing fetched, no console error;
#   - render_ms: series whose medians differ 19x get a log axis (said);
#     the 10% step planted at the seventh commit is marked and tabled with
#     its commit, not confirmed; a page of equal values is linear;
#   - machines named by their CPU and GPU, legends by the settings that
#     differ, never a 16-hex-digit fingerprint or settings hash;
#   - a scene and a study named with <script>, quotes and & show as text;
#   - an empty database gives a page that says so; a missing file, a
#     corrupt one, another program's SQLite and a folder that is no report
#     or dashboard get one line and exit 1, nothing written outside DIR.
# usage: test-publish.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup publish "$1" "$2"
if "$H" history show --db none.db 2>&1 | grep -q "no SQLite"; then
    fail "this harness was built without SQLite (scripts/install-deps.sh installs libsqlite3-dev)"
fi
chrome=$(command -v chromium || command -v chromium-browser) ||
    fail "chromium missing (scripts/install-deps.sh installs Debian's chromium)"
command -v python3 > /dev/null || fail "python3 missing"
for s in oka okb okc; do echo "# dummy" > "$s.txt"; done
printf 'study: pub\nscene_dir: .\nscenes: oka okb okc\nrepeats: 5\npin: none\nraytrace: %s\n' "$FAKE" > p.conf
"$H" run p.conf -o one.csv -q 2> /dev/null || fail "the study"
# commit k (1..12) on machine A (no GPU): render_ms of oka 10 (11 from
# commit 7 on), okb 200, okc 50 (its scene renamed to markup), 2% noise;
# instructions exact. Machine B (a GPU): oka at 5.
python3 - one.csv << 'EOF' || fail "making the studies"
import csv, random, sys
rows = list(csv.reader(open(sys.argv[1], newline="")))
h = rows[0]
c = {n: i for i, n in enumerate(h)}
evil = "<script>alert(\"x\")</script> & 'q'"
base = {"oka": 10.0, "okb": 200.0, "okc": 50.0}
for k in range(1, 13):
    random.seed(k)
    a, b = [h], [h]
    for r in rows[1:]:
        r = list(r)
        sc = r[c["scene"]]
        step = 1.1 if sc == "oka" and k >= 7 else 1.0
        r[c["render_ms"]] = "%.4f" % (base[sc] * step * (1 + 0.04 * (random.random() - 0.5)))
        r[c["git_commit"]] = "c0ffee%02d" % k
        r[c["utc"]] = "2026-11-%02dT10:00:00Z" % k
        r[c["cpu_model"]], r[c["gpu_name"]] = "Contoso Xeon 9999 @ 2.50GHz", "-"
        r[c["fingerprint"]] = "0123456789abcdef"
        r[c["study"]] = "pub " + evil
        r[c["extra"]] += ";instructions=1000000"
        if sc == "okc":
            r[c["scene"]] = evil
            r[c["run_id"]] = r[c["run_id"]].replace("scene=okc", "scene=" + evil)
        a.append(r)
        if sc == "oka":
            r = list(r)
            r[c["cpu_model"]], r[c["gpu_name"]] = "Fabrikam EPYC 7000", "Fabrikam GPU X1 40GB"
            r[c["fingerprint"]], r[c["study"]] = "fedcba9876543210", "pub-b"
            r[c["render_ms"]] = "%.4f" % (5.0 * (1 + 0.04 * (random.random() - 0.5)))
            b.append(r)
    for name, out in (("a", a), ("b", b)):
        csv.writer(open("%s%d.csv" % (name, k), "w", newline=""), lineterminator="\n").writerows(out)
EOF
"$H" history add --db h.db a{1..12}.csv b{1..12}.csv > add.out || { cat add.out; fail "add"; }
[ "$(grep -c 'stored as study' add.out)" -eq 24 ] || { cat add.out; fail "not 24 studies stored"; }
"$H" history check --db h.db --metric render_ms > check.out
grep -q "at commit c0ffee07 (after c0ffee06)" check.out || { cat check.out; fail "check: the planted step"; }

# publish: nothing outside DIR changes, the database included
sum=$(md5sum h.db)
touch stamp
"$H" history publish --db h.db -o dash > pub.out 2> pub.err || { cat pub.out pub.err; fail "publish"; }
grep -q "^harness history publish: wrote dash/index.html and [0-9]* metric page(s)$" pub.out ||
    { cat pub.out; fail "publish: no 'wrote' line"; }
[ ! -s pub.err ] || { cat pub.err; fail "publish wrote to stderr"; }
[ "$(md5sum h.db)" = "$sum" ] || fail "publish changed the database"
[ -z "$(find . -mindepth 1 -newer stamp ! -path ./dash ! -path './dash/*' ! -name pub.out ! -name pub.err)" ] ||
    { find . -mindepth 1 -newer stamp; fail "publish wrote outside DIR"; }
[ -f dash/.raybench-report ] || fail "no mark in the dashboard's folder"
ls dash | grep -q part && fail "a .part file left behind"

# the browser: network to a dead proxy, so any fetch fails and is logged
view() { # PAGE PREFIX [shot]: PREFIX.dom, PREFIX.log, with shot PREFIX.png
    if [ $# -gt 2 ]; then
        timeout 120 "$chrome" --headless --no-sandbox --disable-gpu --proxy-server=http://127.0.0.1:9 \
            --enable-logging=stderr --v=0 --window-size=1200,2400 --screenshot="$PWD/$2.png" "file://$PWD/$1" \
            > /dev/null 2> "$2.log" || { tail -5 "$2.log"; fail "chromium could not take the screenshot of $1"; }
        [ -s "$2.png" ] && [ "$(head -c 4 "$2.png" | tail -c 3)" = PNG ] || fail "$2.png is not a PNG"
    fi
    timeout 120 "$chrome" --headless --no-sandbox --disable-gpu --proxy-server=http://127.0.0.1:9 \
        --enable-logging=stderr --v=0 --dump-dom "file://$PWD/$1" > "$2.dom" 2>> "$2.log" ||
        { tail -5 "$2.log"; fail "chromium could not dump the DOM of $1"; }
    ! grep -Ei 'CONSOLE|Uncaught|Failed to load resource|net::ERR' "$2.log" ||
        fail "$1: a script error or a fetch in the browser's log"
    ! grep -qi '<script' "$2.dom" || fail "$1: a script element in the page"
    ! grep -Eqi '(src|href)="(https?:)?//|@import|url\(' "$2.dom" || fail "$1: refers to something outside it"
    ! grep -Eq '[0-9a-f]{16}' "$2.dom" || { grep -Eo '.{40}[0-9a-f]{16}' "$2.dom"; fail "$1: a hash in the page"; }
}
view dash/index.html index shot
pages=$(grep -o 'href="[^"]*\.html"' index.dom | sed 's/href="//; s/"$//' | grep -v '^index.html$' | sort -u)
n=$(echo "$pages" | grep -c .)
[ "$n" -ge 8 ] || { echo "$pages"; fail "expected a page per metric, found $n"; }
for m in render_ms instructions mrays_per_s wall_ms; do
    echo "$pages" | grep -qx "$m.html" || fail "index: no page for $m"
done
! grep -q '<svg' index.dom || fail "index: a plot"
grep -q 'Contoso Xeon 9999 @ 2.50GHz' index.dom || fail "index: machine A's CPU not named"
grep -q 'Fabrikam EPYC 7000.*GPU Fabrikam GPU X1 40GB' index.dom || fail "index: machine B's CPU and GPU not named"
grep -q "pub &lt;script&gt;alert(\"x\")&lt;/script&gt; &amp; 'q'" index.dom || fail "index: the study's name not as text"
for p in $pages; do
    [ -f "dash/$p" ] || fail "index links $p, not written"
    case $p in render_ms.html | instructions.html) view "dash/$p" "${p%.html}" shot ;; *) view "dash/$p" "${p%.html}" ;; esac
    nsvg=$(grep -o '<svg' "${p%.html}.dom" | wc -l)
    [ "$nsvg" -eq 2 ] || fail "$p: expected a plot per machine (2), found $nsvg"
done

# render_ms: log axis, the step, machines and legends in words
grep -q 'render_ms (ms), log scale' render_ms.dom || fail "render_ms: the log axis is not said"
grep -q "the series' medians differ 1[89]x" render_ms.dom || fail "render_ms: the spread is not said"
grep -q '<td>S1</td>.*<code>c0ffee07</code>.*<code>c0ffee06</code>.*slower.*not confirmed' render_ms.dom ||
    fail "render_ms: the step at c0ffee07 is not in the table, not confirmed"
[ "$(grep -c '<td>S[0-9]*</td>' render_ms.dom)" -eq 1 ] || fail "render_ms: one step expected"
grep -q '>S1</text>' render_ms.dom || fail "render_ms: the step not marked on the plot"
grep -q '<h2>Contoso Xeon 9999 @ 2.50GHz (.*), no GPU</h2>' render_ms.dom || fail "render_ms: machine A's heading"
grep -q '<h2>Fabrikam EPYC 7000 (.*), GPU Fabrikam GPU X1 40GB</h2>' render_ms.dom || fail "render_ms: machine B's heading"
grep -q 'class="legend"[^>]*>scene oka<' render_ms.dom || fail "render_ms: legend 'scene oka'"
grep -q "class=\"legend\"[^>]*>scene &lt;script&gt;alert(\"x\")&lt;/script&gt; &amp; 'q'<" render_ms.dom ||
    fail "render_ms: the marked-up scene is not shown as text in the legend"
grep -q 'no change' render_ms.dom || fail "render_ms: the flat series have no verdict"
# instructions: equal everywhere, linear
! grep -q 'log scale' instructions.dom || fail "instructions: a log axis for equal values"
grep -q 'instructions, log\|<td>S1</td>' instructions.dom && fail "instructions: a step in equal values"

# again into the same folder: written, and a page no longer published goes
echo '<p>old</p>' > dash/gone.html
"$H" history publish --db h.db -o dash > /dev/null 2>&1 || fail "publish into its own folder again"
[ ! -e dash/gone.html ] || fail "a stale page was kept"
# filters: only machine A's okb left
"$H" history publish --db h.db -o dash-okb --scene okb > /dev/null 2>&1 || fail "publish --scene okb"
[ "$(grep -o '<svg' dash-okb/render_ms.html | wc -l)" -eq 1 ] || fail "--scene okb: one plot expected"

# a hand-made CSV whose metric_info names '../x' and a key of that name:
# the other metrics' pages are still written, and nothing outside DIR
python3 - one.csv evilmetric.csv << 'PY' || fail "making the study with a bad metric name"
import csv, sys
rows = list(csv.reader(open(sys.argv[1], newline="")))
c = {n: i for i, n in enumerate(rows[0])}
for r in rows[1:]:
    r[c["git_commit"]] = "c0ffee13"
    r[c["metric_info"]] = "../x:ms:lower"
    r[c["extra"]] += ";../x=3"
csv.writer(open(sys.argv[2], "w", newline=""), lineterminator="\n").writerows(rows)
PY
cp h.db hx.db
"$H" history add --db hx.db evilmetric.csv > /dev/null 2>&1 || fail "add of the study with a bad metric name"
"$H" history publish --db hx.db -o dash-x > /dev/null 2> x.err || { cat x.err; fail "a bad metric name stopped publish"; }
[ -s dash-x/render_ms.html ] && [ ! -e x.html ] && [ ! -e ../x.html ] || { ls -R dash-x; fail "bad metric name: pages"; }

# an empty database: a page that says so (a study without rows; a new file)
head -n 1 one.csv > header.csv
"$H" history add --db empty.db header.csv > /dev/null || fail "add of a header-only CSV"
: > zero.db
for db in empty zero; do
    "$H" history publish --db $db.db -o dash-$db > /dev/null 2> $db.err || { cat $db.err; fail "$db database"; }
    view dash-$db/index.html $db
    grep -q 'No history yet' $db.dom || fail "$db database: not said"
    [ "$(ls dash-$db)" = index.html ] || { ls dash-$db; fail "$db database: more than the index"; }
done

# bad input: one line naming it, exit 1, nothing written outside DIR
bad() { # WHAT EXPECTED-TEXT ARGS...: refused with one line holding the text
    local what=$1 text=$2
    shift 2
    touch stamp
    "$H" history publish "$@" > bad.out 2> bad.err && fail "$what: accepted"
    [ "$(wc -l < bad.err)" -eq 1 ] && grep -q -- "$text" bad.err || { cat bad.err; fail "$what: message"; }
    [ -z "$(find . -mindepth 1 -newer stamp ! -name 'bad.*')" ] || { find . -newer stamp; fail "$what: wrote"; }
}
bad "a missing database" "missing.db: no such database" --db missing.db -o out
head -c 3000 /dev/urandom > junk.db
bad "a corrupt database" "junk.db: file is not a database" --db junk.db -o out
python3 -c "import sqlite3; c = sqlite3.connect('other.db'); c.execute('create table t(x)'); c.commit()"
sum=$(md5sum other.db)
bad "another program's database" "other.db: not a raybench history database" --db other.db -o out
[ "$(md5sum other.db)" = "$sum" ] || fail "another program's database was changed"
bad "no -o" "expected -o DIR" --db h.db
mkdir mine && echo keep > mine/notes.txt
bad "a folder that is no dashboard" "mine exists and is not a report or dashboard" --db h.db -o mine
[ "$(ls mine)" = notes.txt ] && [ "$(cat mine/notes.txt)" = keep ] || fail "the folder was changed"
"$H" history --help | grep -q "publish -o DIR" || fail "history --help: no publish"
echo "  index: $n metric pages; render_ms screenshot $(stat -c %s render_ms.png) bytes"
echo "ok"
