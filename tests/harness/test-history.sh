#!/bin/bash
# harness history against a real SQLite database:
#   - twelve studies of twelve commits go in; the same CSV twice is stored once;
#   - a 10% step of one configuration at the seventh commit is found there,
#     with 2% noise around it, and the flat configuration raises nothing;
#   - an exact metric (the same value at every repeat) steps on any change
#     over the threshold;
#   - a dirty tree's rows, a corrupt database and a missing one get one line
#     and exit 1, the database unchanged;
#   - run --history stores the study it ran;
#   - plot writes the PNG (gnuplot) from the stored rows.
# usage: test-history.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup history "$1" "$2"
if "$H" history show --db none.db 2>&1 | grep -q "no SQLite"; then
    fail "this harness was built without SQLite (scripts/install-deps.sh installs libsqlite3-dev)"
fi
echo "# dummy" > oka.txt
echo "# dummy" > okb.txt
printf 'study: h\nscene_dir: .\nscenes: oka okb\nrepeats: 5\npin: none\nraytrace: %s\n' "$FAKE" > h.conf
"$H" run h.conf -o one.csv -q 2> /dev/null || fail "the study"
# commit k (1..12): render_ms of oka 10 (11 from commit 7 on), of okb 10,
# times 1 + uniform noise of +-2%; instructions exact (oka +4% from commit 9)
for k in $(seq 1 12); do
    sha=$(printf 'c0ffee%02d' "$k")
    awk -F, -v OFS=, -v k="$k" -v sha="$sha" -v seed="$k" '
        NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; srand(seed); print; next }
        { step = ($c["scene"] == "oka" && k >= 7) ? 1.1 : 1.0
          $c["render_ms"] = sprintf("%.4f", 10 * step * (1 + 0.04 * (rand() - 0.5)))
          $c["git_commit"] = sha
          $c["utc"] = sprintf("2026-11-%02dT10:00:00Z", k)
          ir = ($c["scene"] == "oka" && k >= 9) ? 1040000 : 1000000
          $c["extra"] = $c["extra"] ";instructions=" ir
          print }' one.csv > "c$k.csv"
done
"$H" history add --db h.db c{1..12}.csv > add.out || { cat add.out; fail "add"; }
[ "$(grep -c 'stored as study' add.out)" -eq 12 ] || { cat add.out; fail "not 12 studies stored"; }
"$H" history add --db h.db c3.csv | grep -q "c3.csv: already stored as study 3" || fail "the same CSV stored twice"
"$H" history show --db h.db > show.out || fail "show"
grep -q "^12 studies in h.db" show.out || { cat show.out; fail "show: study count"; }
grep -q "c0ffee07" show.out || fail "show: commit missing"

"$H" history check --db h.db > check.out && { cat check.out; fail "a 10% step passed check"; }
grep -q "^STEP scene=oka .*: render_ms at commit c0ffee07 (after c0ffee06): +" check.out ||
    { cat check.out; fail "the step is not at commit 7"; }
grep -q "^STEP scene=okb" check.out && { cat check.out; fail "the flat configuration was flagged"; }
[ "$(grep -c '^STEP' check.out)" -eq 1 ] || { cat check.out; fail "one step expected"; }
"$H" history check --db h.db --scene okb > flat.out || { cat flat.out; fail "the flat configuration failed check"; }
grep -q "1 series, 0 slowdown step(s), 0 inconclusive" flat.out || { cat flat.out; fail "flat: summary"; }
grep -q "^no change scene=okb .*: last 5 commits against the 5 before: ratio in \[0\.9[5-9][0-9]*, 1\.0[0-4]" flat.out ||
    { cat flat.out; fail "flat: no 'no change' line"; }
# one commit of the flat series alone cannot tell
"$H" history check --db h.db --scene okb --window 20 --threshold 0.001 > unsure.out || fail "inconclusive fails"
grep -q "^INCONCLUSIVE scene=okb .*only steps beyond" unsure.out || { cat unsure.out; fail "no INCONCLUSIVE line"; }
"$H" history check --db h.db --metric instructions --threshold 0.03 --scene oka > ir.out && fail "an exact 4% step passed"
grep -q "at commit c0ffee09 (after c0ffee08): +4.0%, p=0" ir.out || { cat ir.out; fail "the exact step"; }
"$H" history check --db h.db --metric instructions --threshold 0.05 > ir5.out || { cat ir5.out; fail "a 4% step over a 5% threshold"; }
# one timing a side is not an exact metric: two commits of one run each
# cannot show a step, nor call it exact
head -n 2 c1.csv > one1.csv
head -n 2 c7.csv > one2.csv
"$H" history add --db one.db one1.csv one2.csv > /dev/null || fail "add one-run studies"
"$H" history check --db one.db --window 1 > one.out || { cat one.out; fail "one run a side flagged a step"; }
grep -q "p=0\|exact" one.out && { cat one.out; fail "one run a side taken as exact"; }
# commits git knows go in commit-time order; one it does not know (a CI
# checkout's merge commit) goes where it was first measured, after them,
# and a 20% step there is found there
command -v git > /dev/null || fail "git missing (scripts/install-deps.sh)"
mkdir repo && (cd repo && git init -q) || fail "git init"
for k in 1 2 3 4 5 6; do
    (cd repo && GIT_AUTHOR_NAME=t GIT_AUTHOR_EMAIL=t@t GIT_COMMITTER_NAME=t GIT_COMMITTER_EMAIL=t@t \
        GIT_AUTHOR_DATE="2026-01-0${k}T00:00:00Z" GIT_COMMITTER_DATE="2026-01-0${k}T00:00:00Z" \
        git commit -q --allow-empty -m "c$k") || fail "git commit"
    sha=$(git -C repo rev-parse HEAD)
    awk -F, -v OFS=, -v sha="$sha" -v k="$k" 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; print; next }
        $c["scene"] == "oka" { $c["git_commit"] = sha; $c["utc"] = sprintf("2026-11-%02dT10:00:00Z", 10 + k); print }' \
        c1.csv > "repo/k$k.csv"
done
awk -F, -v OFS=, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; print; next }
    $c["scene"] == "oka" { $c["git_commit"] = "deadbeefdeadbeefdeadbeefdeadbeefdeadbeef"
                           $c["utc"] = "2026-11-20T10:00:00Z"; $c["render_ms"] = $c["render_ms"] * 1.2; print }' \
    c1.csv > repo/u.csv
(cd repo && "$H" history add --db k.db k1.csv k2.csv k3.csv k4.csv k5.csv k6.csv u.csv > /dev/null) || fail "add the repo's studies"
(cd repo && "$H" history check --db k.db > ../k.out) && { cat k.out; fail "a 20% step at an unknown commit passed"; }
grep -q "^STEP scene=oka .*at commit deadbeefdeadbeefdeadbeefdeadbeefdeadbeef (after $sha): +20.0%" k.out ||
    { cat k.out; fail "the unknown commit not placed where it was measured"; }

# bad input: one line, exit 1, nothing stored
sed 's/c0ffee01/c0ffee01-dirty/' c1.csv > dirty.csv
"$H" history add --db h.db dirty.csv 2> dirty.err && fail "a dirty tree's rows were stored"
grep -q "dirty.csv:2: commit 'c0ffee01-dirty'" dirty.err || { cat dirty.err; fail "dirty: message"; }
[ "$(wc -l < dirty.err)" -eq 1 ] || { cat dirty.err; fail "dirty: more than one line"; }
"$H" history show --db h.db | grep -q "^12 studies" || fail "the refused CSV changed the database"
head -c 3000 /dev/urandom > junk.db
"$H" history add --db junk.db c1.csv 2> junk.err && fail "a corrupt database accepted rows"
grep -q "junk.db: file is not a database" junk.err || { cat junk.err; fail "corrupt: message"; }
"$H" history show --db missing.db 2> missing.err && fail "show of a missing database"
grep -q "missing.db: no such database" missing.err || { cat missing.err; fail "missing: message"; }
"$H" history add --db h.db nothere.csv 2> nocsv.err && fail "a missing CSV"
grep -q "nothere.csv" nocsv.err || { cat nocsv.err; fail "missing CSV: message"; }
"$H" history plot "$(printf 'a\nb')" --db h.db -o x 2> nl.err && fail "a metric with a newline accepted"
[ "$(wc -l < nl.err)" -eq 1 ] || { cat nl.err; fail "a metric with a newline: not one line"; }
"$H" history check --db h.db --threads x 2> tx.err && fail "--threads x accepted"
[ "$(cat tx.err)" = "harness history: --threads: expected an integer 1..4096, got 'x'" ] || fail "--threads x: $(cat tx.err)"
"$H" history check --db h.db --window 0 2> w.err && fail "--window 0 accepted"
grep -q -- "--window" w.err || fail "--window: message"

# run --history: the finished study goes in (or, from a dirty tree, is refused
# with the CSV's line and the run exits 1, its CSV written)
"$H" run h.conf -o runh.csv --history runh.db -q > runh.out 2> runh.err
rc=$?
commit=$(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "git_commit") c = i; next } { print $c; exit }' runh.csv)
if echo "$commit" | grep -Eq '^[0-9a-f]{4,40}$'; then
    [ $rc -eq 0 ] && grep -q "runh.csv: stored as study 1 (10 runs)" runh.out || { cat runh.out runh.err; fail "run --history"; }
else
    [ $rc -ne 0 ] && grep -q "runh.csv:2: commit '$commit'" runh.err || { cat runh.err; fail "run --history, dirty tree"; }
fi
[ "$(grep -c . runh.csv)" -eq 11 ] || fail "run --history: the CSV"

command -v gnuplot > /dev/null || fail "gnuplot missing (scripts/install-deps.sh installs gnuplot-nox)"
"$H" history plot render_ms --db h.db -o hist > plot.out 2>&1 || { cat plot.out; fail "plot"; }
[ -s hist-history.png ] && [ -s hist-history.svg ] || fail "no PNG/SVG"
[ "$(grep -c '^[0-9]' hist-history.dat)" -eq 24 ] || { cat hist-history.dat; fail "plot data: 12 commits x 2 series"; }
# legends of what differs, the machine in words, never a hash
grep -qE '[0-9a-f]{8}/' hist-history.dat && fail "a hash in the history plot's legends: $(head -3 hist-history.dat)"
[ "$(grep -c '^"scene ' hist-history.dat)" -eq 2 ] || { head -3 hist-history.dat; fail "legends not the scene that differs"; }
grep -q "on .* cores" hist-history.gp || fail "no machine in words in the history plot's title"
# control characters from a CSV (a terminal escape that clears the screen,
# a bell, a backspace, a carriage return, a quoted newline) reach show and
# check as '?': the twelve studies again, with them in text fields
e=$(printf '\033[2J\a\b\r')
for k in $(seq 1 12); do
    awk -F, -v OFS=, -v e="$e" '
        NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; print; next }
        { q = "\""; $c["study"] = q "st" e "udy" q; $c["host"] = q "ho" e "st" q
          $c["fingerprint"] = q "fp" e q; $c["scene"] = q $c["scene"] e "\nx" q
          sub(/scene=ok/, "scene=ok" e, $c["run_id"]); $c["run_id"] = q $c["run_id"] q; print }' "c$k.csv" > "esc$k.csv"
done
grep -q "$(printf '\033')" esc1.csv || fail "escape: no ESC in the CSV"
"$H" history add --db esc.db esc{1..12}.csv > esc-add.out || { cat -A esc-add.out; fail "escape: add"; }
"$H" history show --db esc.db > esc-show.out || fail "escape: show"
grep -q "^12 studies in esc.db" esc-show.out || { cat -A esc-show.out; fail "escape: show: study count"; }
grep -q 'st?\[2J???udy .* ho?\[2J???st  *fp?\[2J???  *esc1.csv$' esc-show.out ||
    { cat -A esc-show.out; fail "escape: show: the fields not shown with '?'"; }
"$H" history check --db esc.db > esc-check.out && { cat -A esc-check.out; fail "escape: check found no step"; }
grep -q '^STEP scene=ok?\[2J???a .*\[fp?\[2J??? [0-9a-f]*\]: render_ms at commit c0ffee07' esc-check.out ||
    { cat -A esc-check.out; fail "escape: check: the STEP line"; }
for f in esc-show.out esc-check.out; do
    LC_ALL=C grep -q "$(printf '[\001-\010\013-\037\177]')" "$f" && { cat -A "$f"; fail "escape: $f holds a control character"; }
done
echo "history: ok"
