#!/bin/sh
# gpu_oom.sh RAYTRACE HOG SCENEGEN - scenes that do not fit on the GPU:
# with all but 1 GiB of the device held by gpu_hog (the context takes some
# of what is left),
#   - a 10240x10240 render (1.2 GiB of image alone) must fail with one line
#     that says how much it needs and how much is free, exit 1, and write
#     no image;
#   - the GPU build of 3M triangles (about 1 GiB) must give way to the
#     CPU's with one notice line, then render (exit 0, an image, the record
#     saying builder=cpu) or fail with one more line saying what the render
#     needs and what is free (exit 1, no image); never crash.
# Exit 77 without a GPU.
RT=$1 HOG=$2 GEN=$3
command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q '^GPU ' || { echo "SKIP: no GPU"; exit 77; }
TMP=$(mktemp -d) || exit 1
"$HOG" 1024 > "$TMP/hog" 2>&1 &
hog=$!
trap 'kill $hog 2>/dev/null; wait $hog 2>/dev/null; rm -rf "$TMP"' EXIT
for _ in $(seq 200); do grep -q ready "$TMP/hog" && break; sleep 0.1; done
grep -q ready "$TMP/hog" || { echo "FAIL: gpu_hog did not start: $(cat "$TMP/hog")"; exit 1; }
echo "held: $(cat "$TMP/hog") MiB free"
printf 'material: .1 .1 .1 .7 .7 .7 0 0 0 10 0 0 0 1\npoint_light: 1 1 1 0 5 5\nsphere: 0 0 -5 1\n' > "$TMP/s.txt"
SCENE=$TMP/s.txt
"$RT" -q --backend cuda -r 10240x10240 -o "$TMP/o.ppm" "$SCENE" > /dev/null 2> "$TMP/err"
rc=$?
echo "exit $rc:"; cat "$TMP/err"
[ $rc -eq 1 ] && [ "$(wc -l < "$TMP/err")" -eq 1 ] && grep -q "out of device memory: .* need [0-9]* bytes .* MiB free" "$TMP/err" &&
    [ ! -e "$TMP/o.ppm" ] || { echo "FAIL: expected one line saying what is needed and free, exit 1, no image"; exit 1; }
"$GEN" --kind spheres --triangles 3000000 --seed 1 --resolution 64x36 -o "$TMP/big.txt" > /dev/null ||
    { echo "FAIL: scenegen"; exit 1; }
"$RT" -q --backend cuda --builder gpu -o "$TMP/b.ppm" "$TMP/big.txt" > "$TMP/rec" 2> "$TMP/err2"
rc=$?
echo "3M triangles, --builder gpu: exit $rc:"; cat "$TMP/err2"
case $rc in
0) [ "$(wc -l < "$TMP/err2")" -eq 1 ] && grep -q "note: building the BVH on the CPU: the GPU build of [0-9]* records needs [0-9.]* MiB" "$TMP/err2" &&
       [ -s "$TMP/b.ppm" ] && tr ' ' '\n' < "$TMP/rec" | grep -qx builder=cpu ||
       { echo "FAIL: expected one notice line, an image and builder=cpu"; exit 1; } ;;
1) [ "$(wc -l < "$TMP/err2")" -eq 2 ] && head -1 "$TMP/err2" | grep -q "note: building the BVH on the CPU: .* MiB" &&
       tail -1 "$TMP/err2" | grep -q "out of device memory: .* need [0-9]* bytes .* MiB free" && [ ! -e "$TMP/b.ppm" ] ||
       { echo "FAIL: expected the notice, one line saying what is needed and free, and no image"; exit 1; } ;;
*) echo "FAIL: exit $rc (a crash?)"; exit 1 ;;
esac
echo "ok"
