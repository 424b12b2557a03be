#!/bin/bash
# harness run interrupted, and runs that leave processes behind:
#   - SIGTERM and SIGINT during a run end the run's whole process group, write
#     no row for it, remove the harness's temporary folder, exit 143 / 130,
#     and --resume then continues the study;
#   - a run that leaves a process in a session of its own (as mpirun's ranks
#     may) has it killed and reaped before the next run starts.
# usage: test-signals.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup signals "$1" "$2"
need_pgrep
mkdir tmp
export TMPDIR=$T/tmp
for s in ok hang escape; do echo "# dummy" > "$s.txt"; done
printf 'study: sig\nscene_dir: .\nscenes: ok hang\nrepeats: 1\npin: none\ntimeout: 60\nraytrace: %s\n' "$FAKE" > sig.conf

for sig in TERM INT; do
    rm -f sig.csv
    "$H" run sig.conf -o sig.csv -q 2> run.err &
    h=$!
    # wait for the hanging run: its sleep is a grandchild of the harness
    for _ in $(seq 100); do pids_matching "^sleep $FAKE_HANG_S\$"; [ -n "$PIDS" ] && break; sleep 0.05; done
    [ -n "$PIDS" ] || fail "the hanging run did not start"
    [ -n "$(ls tmp)" ] || fail "no temporary folder while running"
    kill -$sig $h
    wait $h
    rc=$?
    want=$((128 + $(kill -l $sig)))
    [ $rc -eq $want ] || { cat run.err; fail "SIG$sig: exit $rc, want $want"; }
    sleep 0.2
    pids_matching "^sleep $FAKE_HANG_S\$"
    [ -z "$PIDS" ] || { ps -fp $PIDS; fail "SIG$sig: the run's process outlived the harness"; }
    [ -z "$(ls tmp)" ] || fail "SIG$sig: temporary files left: $(ls tmp)"
    [ "$(($(wc -l < sig.csv) - 1))" -eq 1 ] || fail "SIG$sig: expected the one finished row: $(cat sig.csv)"
    grep -q -- "--resume" run.err || fail "SIG$sig: the message does not say how to continue: $(cat run.err)"
done

# a stray in its own session is gone before the next run starts
printf 'study: esc\nscene_dir: .\nscenes: escape ok\nrepeats: 1\npin: none\ntimeout: 1\nraytrace: %s\n' "$FAKE" > esc.conf
export FAKE_ESCAPE_PID=$T/escape.pid
"$H" run esc.conf -o esc.csv -q 2> esc.err
grep -q ',timeout,' esc.csv || { cat esc.err; fail "the escaping run did not time out"; }
[ -s escape.pid ] || fail "the fake wrote no pid"
p=$(cat escape.pid)
if kill -0 "$p" 2> /dev/null; then kill -9 "$p"; fail "the process the run left in its own session survived"; fi
echo "signals test passed"
