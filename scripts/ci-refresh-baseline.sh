#!/usr/bin/env bash
# ci-refresh-baseline.sh - makes this commit the CI performance baseline
# (results/ci-baseline.txt; docs/harness-verdicts.md, "CI and the baseline"). Refuses
# a tree with uncommitted changes, so the baseline is always a commit that
# exists. Commit the file afterwards:
#   scripts/ci-refresh-baseline.sh && git commit -m "CI baseline: $(git rev-parse --short HEAD)" results/ci-baseline.txt
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "$(git status --porcelain --untracked-files=no)" ]; then
    echo "ci-refresh-baseline: the tree has uncommitted changes; commit them first" >&2
    exit 1
fi
sha=$(git rev-parse --short HEAD)
cat > results/ci-baseline.txt <<EOT
# The commit the CI performance check measures against (scripts/ci-perf-check.sh
# builds it and runs both in the same job). Refresh: scripts/ci-refresh-baseline.sh
commit: $sha
refreshed: $(date -u +%Y-%m-%dT%H:%M:%SZ)
EOT
echo "ci-refresh-baseline: baseline is now $sha (commit results/ci-baseline.txt)"
