#!/bin/bash
# Reading a CSV costs a small multiple of its size: `harness table` on a
# study of a million rows (the columns and values `harness run` writes,
# grown from a real study with the fake renderer) succeeds under a 1 GiB
# address-space limit, its peak RSS under 1 GiB, and counts every row. (Each
# field took 256 bytes or more before: 18 GB for these rows.)
# Of the rows, 1000 per configuration are ok and the rest timed out, so the
# table's bootstrap (2000 resamples of every ok sample) stays quick.
# usage: test-csv-memory.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup csvmem "$1" "$2"
[ -x /usr/bin/time ] || fail "/usr/bin/time missing (Debian package time, scripts/install-deps.sh)"
echo "# dummy" > oka.txt
echo "# dummy" > okb.txt
printf 'study: big\nscene_dir: .\nscenes: oka okb\nrepeats: 1\npin: none\nraytrace: %s\n' "$FAKE" > big.conf
"$H" run big.conf -o one.csv -q 2> run.err || { cat run.err; fail "the template study"; }
[ "$(wc -l < one.csv)" -eq 3 ] || fail "the template study has not 2 rows"
# row k: configuration k % 2, repeat k / 2; a timed-out row has no record.
# Each kind of row is built once with @R@ (the repeat) and @MS@ in it, and
# the loop only fills those in.
awk -F, -v OFS=, -v n=1000000 -v nok=1000 '
    NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; ncol = NF; print; next }
    NF != ncol { print "template row with a quoted comma" > "/dev/stderr"; exit 1 }
    {
        $c["repeat"] = "@R@"; sub(/#r0$/, "#r@R@", $c["run_id"]); $c["render_ms"] = "@MS@"
        split($0, ok, "@R@|@MS@")
        $c["status"] = "timeout"; $c["status_detail"] = "timed out after 60 s"; $c["exit_code"] = ""
        for (i = c["rec_scene"]; i <= c["rec_gpu"]; i++) $i = ""
        $c["extra"] = ""
        split($0, to, "@R@")
        for (i = 1; i <= 4; i++) okp[NR - 2, i] = ok[i]
        for (i = 1; i <= 3; i++) top[NR - 2, i] = to[i]
    }
    END {
        for (k = 0; k < n; k++) {
            t = k % 2; r = int(k / 2)
            if (r < nok)
                printf "%s%d%s%d%s%.3f%s\n", okp[t, 1], r, okp[t, 2], r, okp[t, 3], 10 + (k % 7) * 0.01, okp[t, 4]
            else
                printf "%s%d%s%d%s\n", top[t, 1], r, top[t, 2], r, top[t, 3]
        }
    }' one.csv > big.csv || fail "generating the CSV"
[ "$(wc -l < big.csv)" -eq 1000001 ] || fail "big.csv has not a million rows"
size=$(stat -c %s big.csv)
start=$(date +%s.%N)
( ulimit -v 1048576 && exec /usr/bin/time -f %M -o rss "$H" table big.csv > t.md 2> t.err )
rc=$?
took=$(echo "$start $(date +%s.%N)" | awk '{ printf "%.1f", $2 - $1 }')
rss=$(tail -1 rss)
echo "big.csv: $size bytes, 1e6 rows: harness table exit $rc, max RSS $rss KiB, $took s"
[ $rc -eq 0 ] || { head -5 t.err; fail "harness table exited $rc under a 1 GiB limit"; }
[ "$rss" -lt 1048576 ] || fail "max RSS $rss KiB"
for s in oka okb; do
    grep -q "^| $s | serial | 1000/500000 |" t.md || { head -20 t.md; fail "$s: not 1000 ok of 500000 rows"; }
done
echo "csv memory test passed"
