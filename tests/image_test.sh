#!/bin/sh
# image_test.sh RAYTRACE IMGDIFF SCENE REFERENCE MODE
# Renders SCENE with the serial backend and the BVH and compares it with the
# reference image: PSNR >= 45 dB and at most 0.2% of pixels with a channel off
# by more than 2/255 (a float32 renderer following the rules reaches 48-57 dB
# and under 0.02%). MODE:
#   ref        only the reference comparison
#   ref+none   also brute force, which must give the same image_fnv1a
#   none@WxH   brute force and BVH at a reduced resolution, same image_fnv1a
# Exits 77 (skipped) when ../shared is not beside the checkout.
set -u
rt=$1 diff=$2 scene=$3 ref=$4 mode=$5
[ -f "$scene" ] || { echo "skip: $scene not found"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
hash_of() { sed -n 's/.*image_fnv1a=\([0-9a-f]*\).*/\1/p' "$1"; }

case "$mode" in
ref|ref+none)
    "$rt" --quiet --verify --accel bvh -o "$tmp/bvh.png" "$scene" > "$tmp/bvh.rec" || exit 1
    [ -f "$ref" ] || { echo "skip: $ref not found"; exit 77; }
    "$diff" "$tmp/bvh.png" "$ref" --min-psnr 45 --max-over2 0.2 || exit 1
    if [ "$mode" = ref+none ]; then
        "$rt" --quiet --verify --accel none -o "$tmp/none.png" "$scene" > "$tmp/none.rec" || exit 1
        hb=$(hash_of "$tmp/bvh.rec") hn=$(hash_of "$tmp/none.rec")
        echo "bvh $hb none $hn"
        [ -n "$hb" ] && [ "$hb" = "$hn" ] || { echo "FAIL: bvh and none images differ"; exit 1; }
        cmp -s "$tmp/bvh.png" "$tmp/none.png" || { echo "FAIL: bvh and none files differ"; exit 1; }
    fi
    ;;
none@*)
    res=${mode#none@}
    "$rt" --quiet --verify --accel bvh -r "$res" -o "$tmp/bvh.ppm" "$scene" > "$tmp/bvh.rec" || exit 1
    "$rt" --quiet --verify --accel none -r "$res" -o "$tmp/none.ppm" "$scene" > "$tmp/none.rec" || exit 1
    hb=$(hash_of "$tmp/bvh.rec") hn=$(hash_of "$tmp/none.rec")
    echo "bvh $hb none $hn at $res"
    [ -n "$hb" ] && [ "$hb" = "$hn" ] || { echo "FAIL: bvh and none images differ"; exit 1; }
    ;;
*) echo "bad mode $mode"; exit 2 ;;
esac
exit 0
