#!/bin/bash
# The harness's own measurement of every run: peak memory (maxrss_kib, from
# wait4's rusage) within 5% of what a program of known peak allocates, 64
# and 256 MiB, and CPU time (user_ms, sys_ms) present: once as raytrace (the
# record line's workload), once as a command study of the plain program.
# usage: test-memory.sh HARNESS ALLOC_PROGRAM
set -u
. "$(dirname "$0")/common.sh"
test_setup memory "$1" "$2"
for m in 64 256; do echo "# dummy" > "alloc$m.txt"; done
printf 'study: mem\nscene_dir: .\nscenes: alloc64 alloc256\nrepeats: 2\npin: none\nraytrace: %s\n' "$FAKE" > mem.conf
"$H" run mem.conf -o mem.csv -q > run.out 2>&1 || { cat run.out; fail "harness run failed"; }
printf 'command: %s {mib}
param mib: 64 256
repeats: 2
pin: none
' "$FAKE" > cmd.conf
"$H" run cmd.conf -o cmd.csv -q > run.out 2>&1 || { cat run.out; fail "harness run (command study) failed"; }
col() { awk -F, -v want="$1" 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == want) c = i; next } c { print $c }' "$2"; }
rows=$(paste -d' ' <(col scene mem.csv) <(col maxrss_kib mem.csv) <(col user_ms mem.csv) <(col sys_ms mem.csv) &&
    paste -d' ' <(col params cmd.csv | sed 's/^mib=/alloc/') <(col maxrss_kib cmd.csv) <(col user_ms cmd.csv) \
        <(col sys_ms cmd.csv)) 2> /dev/null || fail "cannot read the columns"
[ "$(printf '%s\n' "$rows" | grep -c .)" -eq 8 ] || fail "expected 8 rows: $rows"
printf '%s\n' "$rows" | while read -r scene rss user sys; do
    mib=${scene#alloc}
    want=$((mib * 1024))
    echo "$scene: maxrss_kib=$rss (want $want within 5%) user_ms=$user sys_ms=$sys"
    [ -n "$rss" ] && [ "$rss" -ge $((want * 95 / 100)) ] && [ "$rss" -le $((want * 105 / 100)) ] ||
        fail "$scene: maxrss_kib $rss is not within 5% of $want"
    case "$user$sys" in *[!0-9.]* | "") fail "$scene: user_ms '$user' or sys_ms '$sys' missing" ;; esac
done || exit 1
echo "ok"
