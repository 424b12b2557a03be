#!/usr/bin/env bash
# build-commit.sh COMMIT DIR - builds the renderer (raytrace, scenegen) of
# COMMIT of this repository: a detached git worktree in DIR, built in
# DIR/build, so the harness records the commit itself (clean, not "-dirty").
# Prints the raytrace path. Used by the CI performance check (the baseline)
# and scripts/history-backfill.sh. No other checkout is touched.
set -euo pipefail
cd "$(dirname "$0")/.."
commit=${1:?usage: build-commit.sh COMMIT DIR}
dir=${2:?usage: build-commit.sh COMMIT DIR}
sha=$(git rev-parse --verify --quiet "$commit^{commit}") ||
    { echo "build-commit: $commit: no such commit in this repository" >&2; exit 1; }
if [ "$(git -C "$dir" rev-parse HEAD 2>/dev/null)" != "$sha" ]; then
    git worktree remove --force "$dir" 2> /dev/null || rm -rf "$dir"
    git worktree prune
    git worktree add --detach "$dir" "$sha" > /dev/null 2>&1 ||
        { echo "build-commit: cannot check out $sha in $dir" >&2; exit 1; }
fi
if [ ! -f "$dir/build/build.ninja" ]; then
    # the renderer as users build it; the harness, GPU and course tests are
    # not needed (each option only where that commit has it)
    opts=()
    for o in harness=false cuda=disabled course_dir=none; do
        grep -q "option('${o%%=*}'" "$dir/meson_options.txt" && opts+=("-D$o")
    done
    meson setup "$dir/build" "$dir" "${opts[@]}" > "$dir/build.log" 2>&1 ||
        { echo "build-commit: meson setup of $sha failed (see $dir/build.log)" >&2; exit 1; }
fi
ninja -C "$dir/build" renderer/raytrace renderer/scenegen > "$dir/build.log" 2>&1 ||
    { echo "build-commit: building $sha failed (see $dir/build.log)" >&2; exit 1; }
echo "$dir/build/renderer/raytrace"
