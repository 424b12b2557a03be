# common.sh - sourced by the harness's shell tests: absolute paths for the
# programs meson passes (build-relative), a private temporary folder removed
# on exit (cwd), and fail.
#   . "$(dirname "$0")/common.sh"; test_setup NAME HARNESS FAKE_RAYTRACE
abs() { (cd "$(dirname "$1")" && echo "$(pwd)/$(basename "$1")"); }
fail() { echo "FAIL: $*"; exit 1; }
test_setup() { # NAME HARNESS FAKE: sets H, FAKE, T and enters T
    H=$(abs "$2") FAKE=$(abs "$3")
    T=$(mktemp -d "/tmp/hx-$1-XXXXXX")
    trap 'rm -rf "$T"' EXIT
    cd "$T" || exit 1
}
