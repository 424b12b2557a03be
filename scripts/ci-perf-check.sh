#!/bin/sh
# CI performance/regression check: runs the CI study and compares it with the
# committed baseline (docs/harness.md, "Regression check"). Exit 1 on a
# counter/image change or a real slowdown; machine noise does not fail it.
# usage: scripts/ci-perf-check.sh [BUILD_DIR]   (from the repository root)
set -eu
build=${1:-build}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
SCENEGEN=$build/renderer/scenegen scripts/gen-scenes.sh mesh10k > /dev/null
"$build/harness/harness" run configs/ci.conf -o "$tmp/ci.csv" --overwrite -q
"$build/harness/harness" compare "$tmp/ci.csv" results/ci-baseline.csv
