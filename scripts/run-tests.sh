#!/usr/bin/env bash
# run-tests.sh - builds raybench and runs the whole test suite (unit,
# sanitizer, CLI, image, CPU-backend, MPI, harness and GPU tests; GPU tests
# skip without a GPU). Installs missing Debian packages first when run as root.
# The experiments (experiments/README.md) are built and tested too.
# Ends with one line: "N passed, N failed, N skipped".
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "$(id -u)" -eq 0 ] || command -v sudo >/dev/null 2>&1; then
    scripts/install-deps.sh || { echo "install-deps failed"; echo "0 passed, 1 failed"; exit 1; }
fi
# Open MPI refuses root without these; --oversubscribe is passed by the tests.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
BUILD=${BUILD:-build}
# The course scenes (an extra suite, defined only where they are):
# RAYBENCH_COURSE_DIR, or ../shared/scenes/course beside the checkout.
course=${RAYBENCH_COURSE_DIR:-../shared/scenes/course}
if [ -d "$course" ]; then course=$(cd "$course" && pwd); else course=none; fi
if [ ! -f "$BUILD/build.ninja" ]; then
    meson setup "$BUILD" -Dcourse_dir="$course" -Dexperiments=true || { echo "0 passed, 1 failed"; exit 1; }
else
    # (a build made before the option existed needs --reconfigure to learn it)
    meson configure "$BUILD" -Dcourse_dir="$course" -Dexperiments=true > /dev/null 2>&1 ||
        meson setup --reconfigure "$BUILD" -Dcourse_dir="$course" -Dexperiments=true > /dev/null ||
        { echo "0 passed, 1 failed"; exit 1; }
fi
if [ "$course" = none ]; then
    echo "run-tests: no course scenes (set RAYBENCH_COURSE_DIR, or put shared/ beside the checkout): the course suite is left out"
else
    echo "run-tests: course suite on $course"
fi
if ! ninja -C "$BUILD"; then
    echo "build failed"
    echo "0 passed, 1 failed"
    exit 1
fi
meson test -C "$BUILD" --num-processes 2 --print-errorlogs "$@"
rc=$?
log="$BUILD/meson-logs/testlog.json"
if [ -f "$log" ]; then
    pass=$(grep -c '"result": "OK"' "$log")
    fail=$(grep -c -E '"result": "(FAIL|TIMEOUT|ERROR|UNEXPECTEDPASS)"' "$log")
    skip=$(grep -c '"result": "SKIP"' "$log")
    echo "$pass passed, $fail failed, $skip skipped"
else
    echo "0 passed, 1 failed"
    rc=1
fi
exit $rc
