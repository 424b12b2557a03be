#!/bin/sh
# cache_test.sh RAYTRACE SCENE - the scene cache (--cache DIR): a second run
# loads what the first built, with the same image and counters; a changed
# scene, another accelerator, a corrupt or truncated entry and a tampered
# header all build again (never trusted); an unwritable directory is a
# warning, not a failure; the memo of a file's hash is used only while the
# file is unchanged; a bad option value is one line and exit 1.
RT=$1
SRC=$2
fail=0
TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT
FAIL() { echo "FAIL: $*"; fail=1; }
key() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
cp "$SRC" "$TMP/s.txt"
run() { "$RT" -q -r 48x36 --cache "$TMP/c" -o "$TMP/o.ppm" "$@" "$TMP/s.txt"; }
same() { # the image and the exact counters of two records
    for k in image_fnv1a rays node_visits prim_tests prims bvh_nodes sah_cost; do
        [ "$(key "$1" $k)" = "$(key "$2" $k)" ] || { FAIL "$3: $k $(key "$1" $k) vs $(key "$2" $k)"; return; }
    done
}

off=$("$RT" -q -r 48x36 -o "$TMP/o.ppm" "$TMP/s.txt") || FAIL "no cache: the run failed"
[ "$(key "$off" cache)" = off ] || FAIL "without --cache: cache=$(key "$off" cache)"
a=$(run) || FAIL "first run"
b=$(run) || FAIL "second run"
[ "$(key "$a" cache)/$(key "$b" cache)" = built/loaded ] || FAIL "built then loaded: $(key "$a" cache)/$(key "$b" cache)"
same "$off" "$b" "loaded vs no cache"
[ "$(ls "$TMP/c"/*.rbc | wc -l)" = 1 ] || FAIL "one entry expected: $(ls "$TMP/c")"

n=$(run --accel none) || FAIL "accel none"
[ "$(key "$n" cache)" = built ] || FAIL "another accelerator loaded the tree's entry"

entry=$(ls "$TMP/c"/*.rbc | head -n 1)
for bad in flip truncate header; do
    rm -rf "$TMP/c"
    run > /dev/null || FAIL "$bad: build"
    entry=$(ls "$TMP/c"/*.rbc)
    size=$(stat -c %s "$entry")
    case $bad in
        flip) printf '\377' | dd of="$entry" bs=1 seek=$((size - 100)) conv=notrunc 2> /dev/null ;;
        truncate) truncate -s $((size - 64)) "$entry" ;;
        header) printf '\377\377\377\177' | dd of="$entry" bs=1 seek=16 conv=notrunc 2> /dev/null ;;
    esac
    c=$(run) || FAIL "$bad: the run failed"
    [ "$(key "$c" cache)" = built ] || FAIL "$bad: a damaged entry was trusted (cache=$(key "$c" cache))"
    same "$off" "$c" "$bad"
    d=$(run) || FAIL "$bad: the run after the rebuild failed"
    [ "$(key "$d" cache)" = loaded ] || FAIL "$bad: the rebuilt entry did not load"
done

# overrides (-d, -r) apply after the cache: an entry built with them serves
# a run without them with the scene's own settings
rm -rf "$TMP/c"
run -d 0 > /dev/null || FAIL "-d 0 build"
o=$(run) || FAIL "after -d 0"
[ "$(key "$o" cache)" = loaded ] && same "$off" "$o" "an entry built with -d 0, loaded without"
"$RT" -q --cache "$TMP/c2" -r 24x18 -o "$TMP/o.ppm" "$TMP/s.txt" > /dev/null || FAIL "-r build"
w2=$("$RT" -q --cache "$TMP/c2" -o "$TMP/o.ppm" "$TMP/s.txt") || FAIL "after -r"
[ "$(key "$w2" width)x$(key "$w2" height)" = "$(key "$("$RT" -q -o "$TMP/o.ppm" "$TMP/s.txt")" width)x$(key "$("$RT" -q -o "$TMP/o.ppm" "$TMP/s.txt")" height)" ] ||
    FAIL "an entry built with -r 24x18 gave $(key "$w2" width)x$(key "$w2" height) without -r"

# an empty scene renders with the cache as without
: > "$TMP/empty.txt"
"$RT" -q -r 8x6 --cache "$TMP/c" -o "$TMP/e.ppm" "$TMP/empty.txt" > /dev/null 2> "$TMP/err" || FAIL "empty scene with --cache: $(cat "$TMP/err")"

# a changed scene: another entry, and the new scene's image
printf 'sphere: 0 3 -12 1\n' >> "$TMP/s.txt"
e=$(run) || FAIL "changed scene"
[ "$(key "$e" cache)" = built ] || FAIL "a changed scene loaded the old entry"
[ "$(key "$e" image_fnv1a)" != "$(key "$off" image_fnv1a)" ] || FAIL "the changed scene rendered the old image"

# an unwritable cache directory: a warning, and the render goes on
mkdir -p "$TMP/ro" && printf x > "$TMP/ro/c"
w=$("$RT" -q -r 48x36 --cache "$TMP/ro/c" -o "$TMP/o.ppm" "$TMP/s.txt" 2> "$TMP/err") || FAIL "unwritable cache: the run failed"
grep -q "warning: scene cache: cannot" "$TMP/err" || FAIL "unwritable cache: no warning: $(cat "$TMP/err")"
[ "$(key "$w" cache)" = built ] || FAIL "unwritable cache: cache=$(key "$w" cache)"

# the memo of a settled file's hash (DIR/stat): written once the file is 2 s
# old, used while it is unchanged, and worthless after a change in place of
# the same size (the ctime moved), as after a damaged memo
cp "$SRC" "$TMP/m.txt"
sleep 3
runm() { "$RT" -q -r 48x36 --cache "$TMP/cm" -o "$TMP/o.ppm" "$TMP/m.txt"; }
m1=$(runm) || FAIL "memo: first run"
ls "$TMP/cm/stat/"*.memo > /dev/null 2>&1 || FAIL "memo: none written for a settled scene"
m2=$(runm) || FAIL "memo: second run"
[ "$(key "$m1" cache)/$(key "$m2" cache)" = built/loaded ] || FAIL "memo: built then loaded: $(key "$m1" cache)/$(key "$m2" cache)"
same "$off" "$m2" "memo: loaded"
for memo in "$TMP/cm/stat/"*.memo; do printf '\377' | dd of="$memo" bs=1 seek=60 conv=notrunc 2> /dev/null; done
m3=$(runm) || FAIL "memo: damaged memo"
[ "$(key "$m3" cache)" = loaded ] || FAIL "memo: a damaged memo lost the entry (cache=$(key "$m3" cache))"
at=$(grep -bo 'camera_fov_ha: 20' "$TMP/m.txt" | cut -d: -f1)
printf '21' | dd of="$TMP/m.txt" bs=1 seek=$((at + 15)) conv=notrunc 2> /dev/null
m4=$(runm) || FAIL "memo: changed scene"
[ "$(key "$m4" cache)" = built ] || FAIL "memo: a scene changed in place loaded the old entry"
[ "$(key "$m4" image_fnv1a)" != "$(key "$m2" image_fnv1a)" ] || FAIL "memo: the changed scene rendered the old image"

"$RT" -q --cache "" -o "$TMP/o.ppm" "$TMP/s.txt" > /dev/null 2> "$TMP/err"
rc=$?
[ $rc -eq 1 ] && [ "$(wc -l < "$TMP/err")" -eq 1 ] && grep -q -- "--cache" "$TMP/err" || FAIL "--cache '': exit $rc, $(cat "$TMP/err")"
[ $fail -eq 0 ] && echo "cache: ok"
exit $fail
