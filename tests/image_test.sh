#!/bin/sh
# image_test.sh RAYTRACE IMGDIFF SCENE REFERENCE MODE
# Renders SCENE with the serial backend and the BVH and compares it with an
# image. MODE:
#   ref        the course's reference image (an independent double-precision
#              renderer): PSNR >= 45 dB and at most 0.2% of pixels with a
#              channel off by more than 2/255 (a float32 renderer following
#              the rules reaches 48-57 dB and under 0.02%)
#   ref+none   also brute force, which must give the same image_fnv1a
#   none@WxH   brute force and BVH at a reduced resolution, same image_fnv1a
#   golden@WxH    a golden image of the project's own scenes (tests/golden,
#              made by this renderer's serial backend; its README says at
#              which commit), rendered at WxH: PSNR >= 50 dB and at most 0.1%
#              of pixels over 2/255, so a change of the shading shows while a
#              change of float rounding in the last bit does not
#   golden+none@WxH  also brute force at WxH, with the same image_fnv1a
#   png@WxH,WxH...  the PNG writer (pieces deflated on every core, io/image.c)
#              against PPM at each size: the same pixels read back by libpng
#              (CRCs and Adler-32 checked), the same bytes on 1 and 2 threads
# SCENE and REFERENCE may be course:PATH and reference:NAME (tests/course.sh).
# Exits 77 (skipped) when a course scene or reference image is missing.
set -u
. "$(dirname "$0")/course.sh"
rt=$1 diff=$2 scene=$(course_path "$3") ref=$(course_path "$4") mode=$5
[ -f "$scene" ] || { echo "skip: $scene not found (the course scenes: set RAYBENCH_COURSE_DIR)"; exit 77; }
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
golden@* | golden+none@*)
    res=${mode#*@}
    [ -f "$ref" ] || { echo "FAIL: golden image $ref missing"; exit 1; }
    "$rt" --quiet --verify --accel bvh -r "$res" -o "$tmp/bvh.png" "$scene" > "$tmp/bvh.rec" || exit 1
    echo "golden $ref: made by raytrace --backend serial --accel bvh -r $res (tests/golden/README.md)"
    "$diff" "$tmp/bvh.png" "$ref" --min-psnr 50 --max-over2 0.1 || exit 1
    case "$mode" in golden+none@*)
        "$rt" --quiet --verify --accel none -r "$res" -o "$tmp/none.png" "$scene" > "$tmp/none.rec" || exit 1
        hb=$(hash_of "$tmp/bvh.rec") hn=$(hash_of "$tmp/none.rec")
        echo "bvh $hb none $hn at $res"
        [ -n "$hb" ] && [ "$hb" = "$hn" ] || { echo "FAIL: bvh and none images differ"; exit 1; }
    esac
    ;;
png@*)
    for res in $(echo "${mode#png@}" | tr ',' ' '); do
        "$rt" --quiet -r "$res" -o "$tmp/a.ppm" "$scene" > /dev/null || exit 1
        OMP_NUM_THREADS=1 "$rt" --quiet -r "$res" -o "$tmp/a1.png" "$scene" > /dev/null || exit 1
        OMP_NUM_THREADS=2 "$rt" --quiet -r "$res" -o "$tmp/a2.png" "$scene" > /dev/null || exit 1
        "$diff" "$tmp/a1.png" "$tmp/a.ppm" --min-psnr 1000 --max-over2 0 || { echo "FAIL: png at $res"; exit 1; }
        cmp -s "$tmp/a1.png" "$tmp/a2.png" || { echo "FAIL: png at $res: other bytes on 2 threads"; exit 1; }
        echo "png $res: $(wc -c < "$tmp/a1.png") bytes, the PPM's pixels"
    done
    ;;
*) echo "bad mode $mode"; exit 2 ;;
esac
exit 0
