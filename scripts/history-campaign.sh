#!/usr/bin/env bash
# history-campaign.sh [DIR] - does `history check --confirm` accuse only the
# commit that made a step? (docs/harness-verdicts.md, "Verdicts measured"). In a
# clone of this repository (DIR, default /tmp/history-campaign), twenty
# commits on top of HEAD: 6 empty (3, 6, 9, 12, 15, 18), one that plants a
# slowdown in the build (14: every tenth pixel traced twice, 10%; with
# PLANT="2 3", every second pixel three more times, 2.5x), the rest
# one line of text each. Each commit is built (one worktree, incremental)
# and measured with configs/ci.conf (5 repeats) into a history database,
# with stress-ng busy on every CPU while commits 6 to 9 are measured. Then
# `history check --metric render_ms --confirm configs/ci.conf` in the clone,
# which rebuilds the commits of each step it finds (scripts/build-commit.sh)
# and re-measures them interleaved. Prints the check; logs in DIR.
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
dir=${1:-/tmp/history-campaign}
read -r plant_every plant_times <<< "${PLANT:-10 1}"
h=$src/build/harness/harness
command -v stress-ng > /dev/null || { echo "history-campaign: stress-ng missing (scripts/install-deps.sh)" >&2; exit 1; }
[ -x "$h" ] || { echo "history-campaign: build first ($h)" >&2; exit 1; }
rm -rf "$dir"
mkdir -p "$dir/csv"
git clone -q "$src" "$dir/repo"
cd "$dir/repo"
git config user.email campaign@raybench.invalid
git config user.name "history campaign"
shas=()
for k in $(seq 1 20); do
    case $k in
    3 | 6 | 9 | 12 | 15 | 18) git commit -q --allow-empty -m "empty commit $k" ;;
    14)
        # the plant, as a real change of the build would make it
        sed -i "s|^m_dep = cc.find_library('m', required : false)|add_project_arguments('-DRT_PLANT_EVERY=$plant_every', '-DRT_PLANT_TIMES=$plant_times', language : ['c'])\n&|" meson.build
        grep -q "DRT_PLANT_EVERY=$plant_every'" meson.build || { echo "history-campaign: the plant did not apply" >&2; exit 1; }
        git commit -q -am "commit $k: every ${plant_every}th pixel traced $plant_times more time(s)" ;;
    *)
        echo "line $k" >> campaign.txt
        git add campaign.txt
        git commit -q -m "commit $k: text" ;;
    esac
    shas+=("$(git rev-parse --short HEAD)")
done
SCENEGEN=$src/build/renderer/scenegen scripts/gen-scenes.sh mesh10k > /dev/null
git worktree add -q --detach "$dir/wt" "${shas[0]}"
meson setup "$dir/wt/build" "$dir/wt" -Dharness=false -Dcuda=disabled -Dcourse_dir=none > "$dir/setup.log"
spid=""
trap '[ -z "$spid" ] || kill "$spid" 2> /dev/null || true' EXIT
for k in $(seq 1 20); do
    sha=${shas[$((k - 1))]}
    git -C "$dir/wt" checkout -q --detach "$sha"
    ninja -C "$dir/wt/build" renderer/raytrace > "$dir/build-$k.log"
    if [ "$k" = 6 ]; then
        stress-ng --cpu "$(nproc)" --timeout 3600s --quiet &
        spid=$!
        sleep 1
    fi
    "$h" run configs/ci.conf --raytrace "$dir/wt/build/renderer/raytrace" -o "$dir/csv/$k.csv" -q --set repeats=5 \
        2> /dev/null || true
    if [ "$k" = 9 ]; then kill "$spid"; wait "$spid" 2> /dev/null || true; spid=""; fi
    "$h" history add --db "$dir/history.db" "$dir/csv/$k.csv" > /dev/null
    echo "history-campaign: commit $k ($sha)$([ "$k" -ge 6 ] && [ "$k" -le 9 ] && echo ', stress-ng')" >&2
done
echo "commits: ${shas[*]} (empty: 3 6 9 12 15 18 = ${shas[2]} ${shas[5]} ${shas[8]} ${shas[11]} ${shas[14]} ${shas[17]};" \
     "planted (every $plant_every, $plant_times more): 14 = ${shas[13]}; stress-ng: 6-9)"
"$h" history check --db "$dir/history.db" --metric render_ms --confirm configs/ci.conf --build-dir "$dir/confirm" \
    > "$dir/check.txt" 2> "$dir/check.err" || true
cat "$dir/check.txt"
