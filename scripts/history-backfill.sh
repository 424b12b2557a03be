#!/usr/bin/env bash
# history-backfill.sh DB COMMIT... - measures past commits into the history
# database DB (docs/harness-history.md, "History"): each COMMIT's renderer is built
# in a worktree (scripts/build-commit.sh) and runs configs/history.conf and
# configs/ci-instructions.conf with this checkout's harness; the CSVs go to
# DB's folder and into DB. Commits in the order given, oldest first.
#   scripts/history-backfill.sh results/history.db $(git rev-list --first-parent -n 12 --reverse HEAD)
set -euo pipefail
cd "$(dirname "$0")/.."
db=${1:?usage: history-backfill.sh DB COMMIT...}
shift
[ $# -gt 0 ] || { echo "usage: history-backfill.sh DB COMMIT..." >&2; exit 2; }
h=build/harness/harness
csvdir=$(dirname "$db")/history-csv
mkdir -p "$csvdir"
SCENEGEN=build/renderer/scenegen scripts/gen-scenes.sh mesh10k > /dev/null
i=0
for c in "$@"; do
    i=$((i + 1))
    sha=$(git rev-parse --short "$c")
    rt=$(scripts/build-commit.sh "$sha" "/tmp/raybench-history/$sha")
    echo "history-backfill: [$i/$#] $sha" >&2
    # (an older renderer may refuse a newer scene: its rows say so, and the
    # history keeps only ok runs)
    "$h" run configs/history.conf --raytrace "$rt" -o "$csvdir/$sha-times.csv" --overwrite -q || true
    "$h" run configs/ci-instructions.conf --raytrace "$rt" -o "$csvdir/$sha-instructions.csv" --overwrite -q || true
    "$h" history add --db "$db" "$csvdir/$sha-times.csv" "$csvdir/$sha-instructions.csv"
    git worktree remove --force "/tmp/raybench-history/$sha"
done
