# common.sh - sourced by the harness's shell tests: absolute paths for the
# programs meson passes (build-relative), a private temporary folder removed
# on exit (cwd), and fail.
#   . "$(dirname "$0")/common.sh"; test_setup NAME HARNESS FAKE_RAYTRACE
abs() { (cd "$(dirname "$1")" && echo "$(pwd)/$(basename "$1")"); }
fail() { echo "FAIL: $*"; exit 1; }
# Checks for leftover processes need pgrep (procps): without it, or when it
# fails, they would pass having looked at nothing.
need_pgrep() { command -v pgrep > /dev/null || fail "pgrep missing (procps)"; }
# Sets PIDS to the pids whose command line matches $1 (pgrep -f), empty for
# none; pgrep's exit 1 is "no match", anything above is an error.
pids_matching() {
    need_pgrep
    PIDS=$(pgrep -f "$1")
    [ $? -le 1 ] || fail "pgrep -f '$1' failed"
}
test_setup() { # NAME HARNESS FAKE: sets H, FAKE, T and enters T
    H=$(abs "$2") FAKE=$(abs "$3")
    T=$(mktemp -d "/tmp/hx-$1-XXXXXX")
    # the fake's hanging runs sleep this long: a duration of this test's own,
    # so that looking for them (pids_matching "sleep $FAKE_HANG_S") never
    # finds another test's, run at the same time
    export FAKE_HANG_S="31.$$"
    trap 'rm -rf "$T"' EXIT
    cd "$T" || exit 1
}
