#!/bin/sh
# gpu_stream.sh RAYTRACE SCENEGEN - the geometry copied up while the file is
# parsed (backends/cuda/geom_stream.cu): a generated scene of 352,354
# triangles (31 MB, parsed in chunks on several threads),
#   - --builder gpu on 4 parse threads: the record says geom_up=parse, the
#     tree passes --verify;
#   - on 1 thread (the serial parse hands nothing on): geom_up=build;
#   - both, the CPU's tree and a tree from --cache give the same image
#     (hits do not depend on the tree);
#   - a bad index on the file's last line fails with that one line, exit 1,
#     no image, the copies stopped (no crash, no hang).
# Exit 77 without a GPU.
RT=$1 GEN=$2
command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q '^GPU ' || { echo "SKIP: no GPU"; exit 77; }
TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT
"$GEN" --kind spheres --triangles 400000 --seed 2 --resolution 320x240 -o "$TMP/big.txt" > /dev/null ||
    { echo "FAIL: scenegen"; exit 1; }
field() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
fail=0
render() { # NAME OPTIONS...: the record of one render into $TMP/NAME.ppm
    name=$1; shift
    "$RT" -q --backend cuda "$@" -o "$TMP/$name.ppm" "$TMP/big.txt" 2> "$TMP/$name.err" ||
        { echo "FAIL $name: exit $?: $(cat "$TMP/$name.err")"; fail=1; }
}
rec_p=$(render parse --builder gpu --build-threads 4 --verify)
rec_b=$(render build --builder gpu --build-threads 1)
rec_c=$(render cpu --builder cpu --build-threads 4)
rec_s=$(render store --builder gpu --build-threads 4 --cache "$TMP/cache")
rec_l=$(render load --build-threads 4 --cache "$TMP/cache")
show() { # NAME RECORD
    printf '%s: builder=%s geom_up=%s geom_up_ms=%s build_ms=%s cache=%s image_fnv1a=%s\n' "$1" "$(field "$2" builder)" \
        "$(field "$2" geom_up)" "$(field "$2" geom_up_ms)" "$(field "$2" build_ms)" "$(field "$2" cache)" \
        "$(field "$2" image_fnv1a)"
}
show parse "$rec_p"; show build "$rec_b"; show cpu "$rec_c"; show store "$rec_s"; show load "$rec_l"
[ "$(field "$rec_p" builder)" = gpu ] && [ "$(field "$rec_p" geom_up)" = parse ] ||
    { echo "FAIL: 4 parse threads: expected builder=gpu geom_up=parse"; fail=1; }
[ "$(field "$rec_b" builder)" = gpu ] && [ "$(field "$rec_b" geom_up)" = build ] ||
    { echo "FAIL: 1 parse thread: expected builder=gpu geom_up=build"; fail=1; }
[ "$(field "$rec_s" geom_up)" = parse ] && [ "$(field "$rec_l" cache)" = loaded ] ||
    { echo "FAIL: --cache: expected geom_up=parse when stored, cache=loaded after"; fail=1; }
h=$(field "$rec_p" image_fnv1a)
for rec in "$rec_b" "$rec_c" "$rec_s" "$rec_l"; do
    [ -n "$h" ] && [ "$(field "$rec" image_fnv1a)" = "$h" ] || { echo "FAIL: the images differ"; fail=1; break; }
done
n=$(wc -l < "$TMP/big.txt")
printf 'triangle: 0 1 99999999\n' >> "$TMP/big.txt"
"$RT" -q --backend cuda --builder gpu --build-threads 4 -o "$TMP/bad.ppm" "$TMP/big.txt" > /dev/null 2> "$TMP/bad.err"
rc=$?
echo "bad index on line $((n + 1)): exit $rc: $(cat "$TMP/bad.err")"
[ $rc -eq 1 ] && [ "$(wc -l < "$TMP/bad.err")" -eq 1 ] && grep -q "big.txt:$((n + 1)): " "$TMP/bad.err" &&
    [ ! -e "$TMP/bad.ppm" ] || { echo "FAIL: expected one line naming line $((n + 1)), exit 1, no image"; fail=1; }
[ $fail -eq 0 ] && echo ok
exit $fail
