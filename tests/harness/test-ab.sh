#!/bin/bash
# harness ab: two commands run without a shell, interleaved with the first of
# each pair alternating, judged as compare judges: a 3x slowdown is a
# REGRESSION (exit 1), the reverse an IMPROVEMENT, the same command never a
# regression; a rate metric read from stdout; a missing or failing command
# is one line and exit 1 before any timing.
# usage: test-ab.sh HARNESS
set -u
. "$(dirname "$0")/common.sh"
test_setup ab "$1" "$1"
"$H" ab 'sleep 0.05' 'sleep 0.15' --rounds 6 > slow.out && { cat slow.out; fail "a 3x slowdown passed"; }
cat slow.out
grep -q '^REGRESSION B against A: median [0-9.]* -> [0-9.]* ms, ratio [23]\.' slow.out || fail "no REGRESSION line"
"$H" ab 'sleep 0.15' 'sleep 0.05' --rounds 6 > fast.out || { cat fast.out; fail "an improvement failed"; }
grep -q '^IMPROVEMENT B against A' fast.out || { cat fast.out; fail "no IMPROVEMENT line"; }
"$H" ab 'sleep 0.05' 'sleep 0.05' --rounds 6 > same.out || { cat same.out; fail "the same command flagged"; }
grep -Eq '^(no change|INCONCLUSIVE) B against A' same.out || { cat same.out; fail "the same command: verdict"; }
# the order: the untimed round A B, then A B, B A, A B, B A
"$H" ab "sh -c 'echo A >> order.log'" "sh -c 'echo B >> order.log'" --rounds 4 > order.out ||
    { cat order.out; fail "order study"; }
[ "$(tr -d '\n' < order.log)" = "ABABBAABBA" ] || fail "not interleaved alternately: $(tr -d '\n' < order.log)"
# no shell: the argument with ; $( ) and a quote reaches printf whole
# (one round: the wall-time verdict may go either way, so only the
# argument file and the verdict line are checked, not the exit status)
"$H" ab "sh -c 'printf %s \"\$1\" > arg.txt' sh 'x; touch PWNED \$(touch PWNED2) it\"s'" 'true' --rounds 1 > verb.out
grep -Eq '^(REGRESSION|IMPROVEMENT|no change|INCONCLUSIVE) B against A' verb.out || { cat verb.out; fail "verbatim: no verdict"; }
[ "$(cat arg.txt)" = 'x; touch PWNED $(touch PWNED2) it"s' ] || fail "verbatim: the argument arrived as '$(cat arg.txt)'"
[ ! -e PWNED ] && [ ! -e PWNED2 ] || fail "a shell ran"
"$H" ab "sh -c 'echo rate 10'" "sh -c 'echo rate 5'" --metric 'rate ([0-9]+)' --higher --rounds 5 > rate.out &&
    { cat rate.out; fail "a halved rate passed"; }
grep -q '^REGRESSION B against A: median 10.000 -> 5.000, cost ratio' rate.out || { cat rate.out; fail "rate"; }
for bad in "'no-such-program-x' 'true'" "'false' 'true'" "'true' ''" "'true' 'sh -c \"exit 3\"'"; do
    eval "\"\$H\" ab $bad --rounds 3" > bad.out 2> bad.err && fail "accepted: ab $bad"
    [ "$(wc -l < bad.err)" -eq 1 ] && [ ! -s bad.out ] || { cat bad.out bad.err; fail "ab $bad: not one line before timing"; }
    echo "  ab $bad: $(cat bad.err)"
done
"$H" ab 'true' "sh -c 'kill -SEGV \$\$'" --rounds 3 > sig.out 2> sig.err && fail "accepted: a B killed by a signal"
grep -q 'command B failed in the first, untimed round: killed by SIGSEGV' sig.err || { cat sig.err; fail "the signal is not named"; }
echo "ok"
