#!/bin/sh
# harness run --set KEY=VALUE and growing a study with --resume:
#   - --set scene_dir finds the scenes in another folder (relative to the
#     current folder, not the config's); --set threads changes the plan
#     (--dry-run), and the dry run names the overrides; order: rounds runs
#     every configuration once per round;
#   - an unknown key, a missing '=', a bad value: one line naming the option,
#     exit 1, no CSV made, an existing CSV untouched;
#   - --resume with more repeats or a new swept value runs exactly the new
#     runs and keeps the old rows byte for byte; a changed scene_dir, timeout
#     or study name, or fewer repeats, is refused with what changed, and the
#     CSV is untouched.
# usage: test-set-resume.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup set-resume "$1" "$2"

rows() { echo $(($(wc -l < "$1") - 1)); }
# the repeat column (3rd; the fields before it hold no comma)
repeats_of() { tail -n +2 "$1" | cut -d, -f3 | sort | uniq -c | tr -s ' ' | sed 's/^ //' | tr '\n' ';'; }
# one line on stderr, exit 1, naming the option ($2: what it must say)
refused() { # NAME EXPECTED-TEXT
    [ "$rc" -eq 1 ] || fail "$1: exit $rc, want 1"
    [ "$(wc -l < err)" -eq 1 ] || fail "$1: not one line: $(cat err)"
    grep -qF -- "$2" err || fail "$1: message: $(cat err)"
}

mkdir -p a b conf/b
for d in a b conf/b; do echo "# dummy" > "$d/ok.txt"; done
cat > conf/s.conf <<CONF
study: s
scene_dir: a
scenes: ok
backend: openmp
threads: 1
repeats: 2
pin: none
oversubscribe: allow
raytrace: $FAKE
CONF

# ---- --set scene_dir: the scenes come from the other folder
"$H" run conf/s.conf -o dir.csv -q --set scene_dir=b 2> run.err || { cat run.err; fail "--set scene_dir=b"; }
[ "$(rows dir.csv)" -eq 2 ] || fail "--set scene_dir=b: $(rows dir.csv) rows"
[ "$(grep -c ',b/ok\.txt,' dir.csv)" -eq 2 ] || fail "--set scene_dir=b: scene_path is not b/ok.txt: $(cat dir.csv)"
grep -q ',a/ok\.txt,' dir.csv && fail "--set scene_dir=b still ran a/ok.txt"
# relative to the current folder: conf/b exists beside the config, but not here
rm -r b
"$H" run conf/s.conf --dry-run --set scene_dir=b > /dev/null 2> err
rc=$?
refused "--set scene_dir=b with no ./b" "harness: option --set 'scene_dir=b': scene_dir 'b' is not a directory"
mkdir b && echo "# dummy" > b/ok.txt

# ---- --set threads changes the plan, and the dry run names it
"$H" run conf/s.conf --dry-run > plain.txt 2> /dev/null || fail "dry run"
"$H" run conf/s.conf --dry-run --set threads='1 2' > set.txt 2> /dev/null || fail "dry run --set threads"
[ "$(grep -c 'threads=2 ' plain.txt)" -eq 0 ] || fail "the plain plan has threads=2"
[ "$(grep -c '^\[[0-9]*\] .*threads=1 .*#r[01] ' set.txt)" -eq 2 ] || fail "--set threads: threads=1 runs: $(cat set.txt)"
[ "$(grep -c '^\[[0-9]*\] .*threads=2 .*#r[01] ' set.txt)" -eq 2 ] || fail "--set threads: threads=2 runs: $(cat set.txt)"
grep -q '^study s: 4 runs' set.txt || fail "--set threads: header: $(head -1 set.txt)"
grep -qx "override: --set 'threads=1 2'" set.txt || fail "the dry run does not name the override"
# order: rounds runs round by round: threads 1, 2, then 1, 2 again
"$H" run conf/s.conf --dry-run --set threads='1 2' --set order=rounds > rounds.txt 2> /dev/null || fail "order: rounds"
got=$(grep -o '^\[[0-9]*\] .*threads=[12] .*#r[01]' rounds.txt | sed 's/^\[\([0-9]*\)\].*threads=\([12]\) .*#r\([01]\)$/\1:\2:\3/' | tr '\n' ' ')
[ "$got" = "1:1:0 2:2:0 3:1:1 4:2:1 " ] || fail "order: rounds: run order $got"
got=$(grep -o '^\[[0-9]*\] .*threads=[12] .*#r[01]' set.txt | sed 's/^\[\([0-9]*\)\].*threads=\([12]\) .*#r\([01]\)$/\1:\2:\3/' | tr '\n' ' ')
[ "$got" = "1:1:0 2:1:1 3:2:0 4:2:1 " ] || fail "the default order: $got"
"$H" run conf/s.conf --dry-run --set order=shuffled > /dev/null 2> err
rc=$?
refused "--set order=shuffled" "order: expected nested|rounds, got 'shuffled'"
# a key the config lacks is added
"$H" run conf/s.conf --dry-run --set resolution=8x6 > res.txt 2> /dev/null || fail "--set resolution"
grep -q -- '--resolution 8x6' res.txt || fail "--set resolution=8x6 not in the command: $(cat res.txt)"

# ---- bad overrides: one line, exit 1, no CSV; an existing one untouched
for bad in "frobnicate=1|unknown key 'frobnicate'" "threads|expected KEY=VALUE" \
           "threads=many|threads: expected an integer 1..4096, got 'many'" \
           "repeats=0|repeats: expected an integer >= 1, got '0'"; do
    opt=${bad%%|*} want=${bad#*|}
    "$H" run conf/s.conf -o new.csv -q --set "$opt" 2> err
    rc=$?
    refused "--set $opt" "harness: option --set '$opt': $want"
    [ -e new.csv ] && fail "--set $opt wrote a CSV"
    cp dir.csv keep.csv
    "$H" run conf/s.conf -o dir.csv --resume -q --set "$opt" 2> err
    rc=$?
    refused "--set $opt --resume" "harness: option --set '$opt': $want"
    cmp -s dir.csv keep.csv || fail "--set $opt changed an existing CSV"
done

# ---- grow the repeats: 2, then --resume with 3
"$H" run conf/s.conf -o g.csv -q 2> run.err || { cat run.err; fail "the study of 2 repeats"; }
cp g.csv g0.csv
"$H" run conf/s.conf -o g.csv --resume --set repeats=3 2> grow.err || { cat grow.err; fail "--resume with repeats=3"; }
[ "$(rows g.csv)" -eq 3 ] || fail "repeats 2 -> 3: $(rows g.csv) rows, want 3"
[ "$(repeats_of g.csv)" = "1 0;1 1;1 2;" ] || fail "repeats 2 -> 3: repeat column $(repeats_of g.csv)"
head -n 3 g.csv | cmp -s - g0.csv || fail "repeats 2 -> 3: the old rows changed"
grep -q 'g.csv: 1 rows (ok 1, .*), 2 skipped (resume)' grow.err || fail "repeats 2 -> 3: summary: $(cat grow.err)"
[ "$(grep -c '^\[' grow.err)" -eq 1 ] || fail "repeats 2 -> 3: runs executed: $(cat grow.err)"
tail -n 1 g.csv | grep -q '^s,scene=ok backend=openmp .* threads=1 .*#r2,2,' || fail "the new row: $(tail -n 1 g.csv)"
# ... and grow a swept key: threads 1 -> 1 2 (with the 3 repeats)
cp g.csv g1.csv
"$H" run conf/s.conf -o g.csv --resume --set repeats=3 --set threads='1 2' 2> grow.err ||
    { cat grow.err; fail "--resume with threads 1 2"; }
[ "$(rows g.csv)" -eq 6 ] || fail "threads 1 -> 1 2: $(rows g.csv) rows, want 6"
head -n 4 g.csv | cmp -s - g1.csv || fail "threads 1 -> 1 2: the old rows changed"
[ "$(tail -n 3 g.csv | grep -c 'threads=2 .*#r[012],[012],')" -eq 3 ] || fail "threads 1 -> 1 2: new rows: $(tail -n 3 g.csv)"
[ "$(repeats_of g.csv)" = "2 0;2 1;2 2;" ] || fail "threads 1 -> 1 2: repeat column $(repeats_of g.csv)"
grep -q '3 skipped (resume)' grow.err || fail "threads 1 -> 1 2: summary: $(cat grow.err)"
# growing by editing the config works the same way
sed 's/^repeats: 2/repeats: 4/' conf/s.conf > conf/s4.conf
sed -i 's/^threads: 1/threads: 1 2/' conf/s4.conf
"$H" run conf/s4.conf -o g.csv --resume -q 2> grow.err || { cat grow.err; fail "--resume of the edited config"; }
[ "$(rows g.csv)" -eq 8 ] || fail "repeats 3 -> 4 in the config: $(rows g.csv) rows, want 8"

# ---- refused: a changed scene_dir, timeout, study name; fewer repeats
cp g.csv g2.csv
"$H" run conf/s4.conf -o g.csv --resume -q --set scene_dir=b 2> err
rc=$?
refused "--resume with another scene_dir" \
    "g.csv: its runs were made with scene a/ok.txt, the config now gives b/ok.txt (scene_dir b)"
"$H" run conf/s4.conf -o g.csv --resume -q --set timeout=9 2> err
rc=$?
refused "--resume with another timeout" "come from a configuration with other settings"
"$H" run conf/s4.conf -o g.csv --resume -q --set study=t 2> err
rc=$?
refused "--resume with another study name" "its runs were made for study 's', the config now says 't'"
"$H" run conf/s4.conf -o g.csv --resume -q --set repeats=2 2> err
rc=$?
refused "--resume with fewer repeats" "repeat 2 is beyond 'repeats: 2'"
"$H" run conf/s4.conf -o g.csv --resume -q --set threads=2 2> err
rc=$?
refused "--resume without threads=1" "the config's threads no longer has '1'"
cmp -s g.csv g2.csv || fail "a refused --resume changed the CSV"
# the same study again: nothing to run
"$H" run conf/s4.conf -o g.csv --resume 2> again.err || { cat again.err; fail "--resume of a finished study"; }
grep -q 'g.csv: 0 rows .*, 8 skipped (resume)' again.err || fail "a finished study ran again: $(cat again.err)"
cmp -s g.csv g2.csv || fail "--resume of a finished study changed the CSV"
echo "PASS"
