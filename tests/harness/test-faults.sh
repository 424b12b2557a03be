#!/bin/bash
# harness run under faults: no lost or torn row, a clear message, exit 1.
#   - two studies on one CSV: the second is refused (an exclusive lock),
#     with --resume or --overwrite alike, and the first keeps every row;
#   - -o /dev/full ends at once with exit 1 (it used to read /dev/full forever);
#   - a full disk (RLIMIT_FSIZE) mid-study: exit 1, the rows before stay whole,
#     the summary counts the rows on disk;
#   - `table` on a CSV with a torn last row says how to repair it; one cut
#     inside its last field (no line end) is left out, and said.
# usage: test-faults.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup faults "$1" "$2"
for s in ok slow gate; do echo "# dummy" > "$s.txt"; done
conf() { # NAME SCENE REPEATS
    printf 'study: %s\nscene_dir: .\nscenes: %s\nrepeats: %s\npin: none\nraytrace: %s\n' "$1" "$2" "$3" "$FAKE" > "$1.conf"
}

# ---- two writers: the first study's runs wait at a gate (the file go) until
# the others have tried, so it holds the file however slowly they start; its
# header is written once it holds the lock
conf slow gate 8
export FAKE_GATE=$PWD/go
"$H" run slow.conf -o two.csv -q 2> a.err &
a=$!
for _ in $(seq 300); do [ "$( { wc -l < two.csv; } 2>/dev/null || echo 0)" -ge 1 ] && break; sleep 0.1; done
[ "$( { wc -l < two.csv; } 2>/dev/null || echo 0)" -ge 1 ] || { touch go; fail "the first study wrote no header in 30 s"; }
first() { kill -0 $a 2> /dev/null && echo "still running" || echo "ended: $(cat a.err)"; }
timeout 20 "$H" run slow.conf -o two.csv --resume -q 2> b.err; rb=$? # (let in, it would wait at the gate)
timeout 20 "$H" run slow.conf -o two.csv --overwrite -q 2> c.err; rc=$?
state=$(first)
touch go
[ $rb -ne 0 ] || fail "a second writer with --resume was let in (the first: $state)"
grep -q "another harness run is writing it" b.err || fail "second writer's message: $(cat b.err)"
[ $rc -ne 0 ] || fail "a second writer with --overwrite was let in (the first: $state)"
grep -q "another harness run is writing it" c.err || fail "third writer's message: $(cat c.err)"
wait $a || { cat a.err; fail "the first study failed"; }
[ "$(($(wc -l < two.csv) - 1))" -eq 8 ] || fail "the first study kept $(($(wc -l < two.csv) - 1)) of 8 rows"
"$H" table two.csv > /dev/null || fail "the first study's CSV does not read back"
# the lock goes with the study: a later run may continue the file
"$H" run slow.conf -o two.csv --resume -q 2> d.err || { cat d.err; fail "--resume after the study ended"; }

# ---- /dev/full
conf ok ok 3
timeout 20 "$H" run ok.conf -o /dev/full -q 2> full.err
rc=$?
[ $rc -eq 1 ] || fail "-o /dev/full: exit $rc"
grep -q "/dev/full: not a regular file" full.err || fail "-o /dev/full: $(cat full.err)"

# ---- a full disk mid-study: the header and a few rows fit in 4 KiB, not 40
conf many ok 40
(trap '' XFSZ; ulimit -f 8; exec "$H" run many.conf -o fsize.csv -q) 2> fsize.err
rc=$?
[ $rc -eq 1 ] || { cat fsize.err; fail "a full disk: exit $rc"; }
grep -q "write failed" fsize.err || fail "a full disk: $(cat fsize.err)"
[ "$(tail -c 1 fsize.csv | od -An -c | tr -d ' ')" = '\n' ] || fail "a full disk left a torn row"
rows=$(($(wc -l < fsize.csv) - 1))
[ $rows -ge 1 ] && [ $rows -lt 40 ] || fail "a full disk: $rows rows"
grep -q "fsize.csv: $rows rows" fsize.err || fail "the summary does not count the $rows rows on disk: $(cat fsize.err)"
"$H" table fsize.csv > /dev/null || fail "the rows before the full disk do not read back"

# ---- a torn last row: table says how to repair it
conf torn ok 2
"$H" run torn.conf -o torn.csv -q 2> /dev/null || fail "torn study"
head -c -40 torn.csv > cut.csv
"$H" table cut.csv > /dev/null 2> cut.err && fail "table read a torn row"
grep -q -- "--resume" cut.err || fail "torn row message: $(cat cut.err)"
# --metric on a column that holds no number
"$H" table torn.csv --metric scene > /dev/null 2> nonum.err && fail "table --metric scene accepted"
[ "$(wc -l < nonum.err)" -eq 1 ] && grep -q "torn.csv: row 1: scene 'ok' is not a number" nonum.err ||
    fail "--metric scene: $(cat nonum.err)"
# cut inside the last field: as many fields, but no line end: left out, and said
head -c -3 torn.csv > cut2.csv
"$H" table cut2.csv > cut2.md 2> cut2.err || fail "table of a CSV whose last row has no line end: $(cat cut2.err)"
[ "$(wc -l < cut2.err)" -eq 1 ] && grep -q "cut2.csv: line 3 has no line end: left out as torn (cut short; .*--resume" cut2.err ||
    fail "torn last field: $(cat cut2.err)"
grep -q "| 1/1 |" cut2.md || { cat cut2.md; fail "the torn row was read"; }
# ---- a plan of a billion runs is refused up front, with its count
{ printf 'study: huge\nscene_dir: .\nscenes: ok\nbackend: mpi\nrepeats: 1000\n'
  printf 'threads:'; seq -s ' ' 1 1000; printf 'ranks:'; seq -s ' ' 1 1000; } > huge.conf
timeout 10 "$H" run huge.conf --dry-run > /dev/null 2> huge.err
rc=$?
[ $rc -eq 1 ] || fail "a billion-run plan: exit $rc"
grep -q "huge.conf: the study expands to 1000000000 runs" huge.err || fail "plan limit message: $(cat huge.err)"
# params whose product is past the limit are not counted to the end: "more"
printf 'study: p\ncommand: true\nparam a: 1..1000\nparam b: 1..1000\nparam c: 1..1000\nrepeats: 1\n' > params.conf
timeout 10 "$H" run params.conf --dry-run > /dev/null 2> params.err && fail "a plan of 10^9 params' runs accepted"
[ "$(cat params.err)" = "params.conf: the study expands to more runs than the limit of 1000000 (warm-ups included): split it into several configs" ] ||
    fail "params plan limit: $(cat params.err)"
# ---- --resume only continues the same study
conf resA ok 2
"$H" run resA.conf -o res.csv -q 2> /dev/null || fail "study A"
head -n 2 res.csv > res2.csv && mv res2.csv res.csv   # one run left to do
printf 'study: resA\nscene_dir: .\nscenes: slow\nrepeats: 2\npin: none\nraytrace: %s\n' "$FAKE" > resB.conf
"$H" run resB.conf -o res.csv --resume -q 2> resB.err && fail "--resume mixed another study's runs in"
grep -q "1 row(s) are runs this config does not plan (e.g. 'scene=ok" resB.err || fail "resume message: $(cat resB.err)"
printf 'study: resA\nscene_dir: .\nscenes: ok\nrepeats: 2\npin: none\ntimeout: 9\nraytrace: %s\n' "$FAKE" > resC.conf
"$H" run resC.conf -o res.csv --resume -q 2> resC.err && fail "--resume took a study with another timeout"
grep -q "come from a configuration with other settings" resC.err || fail "resume message: $(cat resC.err)"
[ "$(($(wc -l < res.csv) - 1))" -eq 1 ] || fail "a refused resume changed the CSV"
"$H" run resA.conf -o res.csv --resume -q 2> resA.err || { cat resA.err; fail "--resume of the same study"; }
[ "$(($(wc -l < res.csv) - 1))" -eq 2 ] || fail "--resume did not complete the study"

# ---- provenance: the study's own CSV does not make the commit dirty
command -v git > /dev/null || fail "git missing (scripts/install-deps.sh)"
git init -q repo && mkdir repo/bin repo/results && ln -s "$FAKE" repo/bin/raytrace
printf 'study: prov\nscene_dir: %s\nscenes: ok\nrepeats: 1\npin: none\n' "$T" > repo/prov.conf
"$H" run repo/prov.conf --raytrace repo/bin/raytrace -o repo/results/prov.csv -q 2> /dev/null || fail "prov study"
git -C repo add -A && git -C repo -c user.name=t -c user.email=t@t commit -q -m prov || fail "git commit"
"$H" run repo/prov.conf --raytrace repo/bin/raytrace -o repo/results/prov.csv --overwrite -q 2> /dev/null || fail "prov again"
c=$(git -C repo rev-parse --short HEAD)
grep -q ",$c," repo/results/prov.csv || fail "git_commit is not $c: $(tail -1 repo/results/prov.csv)"
echo "# changed" >> repo/prov.conf
"$H" run repo/prov.conf --raytrace repo/bin/raytrace -o repo/results/prov.csv --overwrite -q 2> /dev/null || fail "prov dirty"
grep -q ",$c-dirty," repo/results/prov.csv || fail "a changed tracked file did not make the commit dirty"
uname_r=$(uname -r)
grep -q ",Linux $uname_r," repo/results/prov.csv || fail "no kernel column"
echo "faults test passed"
