#!/bin/sh
# Provenance of a build outside the source tree: raytrace knows its commit
# from build time (Meson's vcs_tag), so the harness records it wherever the
# binary lies.
#   - `raytrace -V` names the source tree's commit (`git rev-parse --short
#     HEAD`, "-dirty" when a tracked file outside results/ and plots/
#     differs), and the record's commit= says the same;
#   - a copy of raytrace outside any git checkout: a one-scene study's
#     git_commit is that commit, not "unknown" (git in the binary's folder);
#   - `harness history add` takes that CSV into a fresh database (with
#     --allow-dirty when the build's tree was dirty, which it refuses without).
# usage: test-provenance.sh HARNESS RAYTRACE SOURCE_ROOT
set -u
. "$(dirname "$0")/common.sh" # fail
abs() { (cd "$(dirname "$1")" && echo "$(pwd)/$(basename "$1")") || fail "no such file $1"; }
H=$(abs "$1") RT=$(abs "$2") SRC=$(cd "$3" && pwd) || fail "no source root $3"
[ -f "$SRC/scenes/demo.txt" ] || fail "scenes/demo.txt missing (the project's demo scene)"
T=$(mktemp -d /tmp/hx-provenance-XXXXXX)
trap 'rm -rf "$T"' EXIT

# the commit the build should have taken, worked out as renderer/meson.build does
if [ -e "$SRC/.git" ] && command -v git > /dev/null; then
    want=$(git -C "$SRC" rev-parse --short HEAD) || fail "git rev-parse in $SRC"
    if [ -n "$(cd "$SRC" && git --no-optional-locks status --porcelain --untracked-files=no -- . ':!results' ':!plots')" ]; then
        want=$want-dirty
    fi
else
    want=unknown
fi
echo "source tree $SRC: commit $want"

# ---- raytrace -V and the record line
got=$("$RT" -V | sed -n 's/^commit: //p')
[ "$got" = "$want" ] || { "$RT" -V; fail "raytrace -V says commit '$got', want '$want'"; }
rec=$("$RT" -q -r 16x12 -o "$T/r.ppm" "$SRC/scenes/demo.txt") || fail "a render"
key() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
[ "$(key "$rec" commit)" = "$want" ] || fail "record: commit=$(key "$rec" commit), want $want: $rec"

# ---- a copy outside any checkout: the study records the build's commit
mkdir "$T/bin" "$T/scenes"
cp "$RT" "$T/bin/raytrace" || fail "copy raytrace"
cp "$SRC/scenes/demo.txt" "$T/scenes/" || fail "copy the scene"
if command -v git > /dev/null && git -C "$T/bin" rev-parse --git-dir > /dev/null 2>&1; then
    fail "$T/bin lies inside a git checkout: the test needs a folder outside one"
fi
cat > "$T/p.conf" << EOF
study: provenance
scene_dir: $T/scenes
scenes: demo
backend: serial
accel: bvh
resolution: 32x24
repeats: 1
pin: none
raytrace: $T/bin/raytrace
EOF
(cd "$T" && "$H" run p.conf -o p.csv -q 2> run.err) || { cat "$T/run.err"; fail "the study"; }
[ "$(($(wc -l < "$T/p.csv") - 1))" -eq 1 ] || { cat "$T/p.csv"; fail "one row expected"; }
col=$(head -1 "$T/p.csv" | tr ',' '\n' | grep -n '^git_commit$' | cut -d: -f1)
[ -n "$col" ] || fail "no git_commit column"
csv_commit=$(sed -n 2p "$T/p.csv" | cut -d, -f"$col")
[ "$csv_commit" = "$want" ] || fail "the CSV's git_commit is '$csv_commit', want '$want' (the build's)"
grep -q ',ok,' "$T/p.csv" || { cat "$T/p.csv"; fail "the run is not ok"; }

# ---- history add takes it
if "$H" history show --db "$T/none.db" 2>&1 | grep -q "no SQLite"; then
    echo "SKIP (history part): this harness was built without SQLite (libsqlite3-dev)"
    echo "provenance test passed"
    exit 0
fi
[ "$want" != unknown ] || { echo "provenance test passed (no git checkout: history add not tried)"; exit 0; }
case $want in
*-dirty)
    "$H" history add --db "$T/h.db" "$T/p.csv" 2> "$T/dirty.err" && fail "a dirty build's rows were stored"
    grep -q "commit '$want'" "$T/dirty.err" || { cat "$T/dirty.err"; fail "dirty: message"; }
    flag=--allow-dirty ;;
*) flag= ;;
esac
# shellcheck disable=SC2086 # $flag: empty or one word
(cd "$SRC" && "$H" history add --db "$T/h.db" $flag "$T/p.csv") > "$T/add.out" 2>&1 ||
    { cat "$T/add.out"; fail "history add refused the CSV"; }
grep -q 'stored as study' "$T/add.out" || { cat "$T/add.out"; fail "history add: not stored"; }
"$H" history show --db "$T/h.db" > "$T/show.out" || fail "history show"
grep -q "$want" "$T/show.out" || { cat "$T/show.out"; fail "history show: commit $want missing"; }
echo "provenance test passed"
