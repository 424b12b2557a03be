#!/bin/sh
# model_test.sh RAYTRACE IMGDIFF - model files through Assimp, on Debian's
# assimp-testmodels (scripts/install-deps.sh installs them; they are never
# copied into the repository): `raytrace MODEL` for OBJ, PLY, STL, glTF and
# GLB; `mesh:` with a transform against the same box written out by hand
# with the transform's closed form; and import errors as one line naming
# the scene file and line. Exit 77 when the models are not installed.
RT=$1
DIFF=$2
M=/usr/share/assimp/models
[ -d "$M" ] || { echo "SKIP: no $M (Debian package assimp-testmodels)"; exit 77; }
fail=0
TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT
FAIL() { echo "FAIL: $*"; fail=1; }
key() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }

# raytrace MODEL: framed, lit, and the model's triangles all there
for m in OBJ/box.obj:12 PLY/cube.ply:12 OBJ/spider.obj: STL/Spider_binary.stl: \
         glTF2/BoxTextured-glTF/BoxTextured.gltf:12 glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb:; do
    f=${m%%:*} want=${m#*:}
    rec=$("$RT" -q -r 160x120 -o "$TMP/m.png" "$M/$f" 2> "$TMP/err") || { FAIL "$f: $(cat "$TMP/err")"; continue; }
    echo "$f: prims=$(key "$rec" prims) shadow_rays=$(key "$rec" shadow_rays)"
    [ -z "$want" ] || [ "$(key "$rec" prims)" = "$want" ] || FAIL "$f: $(key "$rec" prims) triangles, want $want"
    # the primary rays that hit the model cast shadow rays: it is in view
    [ "$(key "$rec" shadow_rays)" -gt 1000 ] || FAIL "$f: the model is not in view ($(key "$rec" shadow_rays) shadow rays)"
done

# mesh: with a transform, against the box's 8 corners put through the same
# map by hand: scale 1 2 3, translate 1 0 0, rotate y 90 ((x, y, z) ->
# (z, y, -x)), translate 0 0 -6: (x, y, z) -> (3z, 2y, -x - 7)
cp "$M/OBJ/box.obj" "$TMP/box.obj"
head='film_resolution: 96 72\ncamera_pos: 0 1.5 4\ncamera_fwd: 0 .15 1\nmaterial: .2 .2 .2 .7 .6 .5 0 0 0 10 0 0 0 1\nambient_light: .2 .2 .2\ndirectional_light: 1 1 1 .5 -1 -.7\n'
printf "${head}mesh: box.obj scale 1 2 3 translate 1 0 0 rotate y 90 translate 0 0 -6\n" > "$TMP/a.txt"
{ printf "$head"
  awk '/^v /{ printf "vertex: %.9g %.9g %.9g\n", 3*$4, 2*$3, -$2 - 7 }' "$TMP/box.obj"
  awk '/^f /{ for (i = 3; i < NF; i++) printf "triangle: %d %d %d\n", $2 - 1, $i - 1, $(i+1) - 1 }' "$TMP/box.obj"
} > "$TMP/b.txt"
"$RT" -q -o "$TMP/a.ppm" "$TMP/a.txt" > /dev/null 2> "$TMP/err" || FAIL "mesh scene: $(cat "$TMP/err")"
"$RT" -q -o "$TMP/b.ppm" "$TMP/b.txt" > /dev/null || FAIL "hand-written box"
"$DIFF" "$TMP/b.ppm" "$TMP/a.ppm" --min-psnr 45 --max-over2 0.5 || FAIL "mesh: with a transform differs from its closed form"
# (a wrong transform must fail that comparison)
printf "${head}mesh: box.obj scale 1 2 3 translate 1 0 0 rotate y -90 translate 0 0 -6\n" > "$TMP/c.txt"
"$RT" -q -o "$TMP/c.ppm" "$TMP/c.txt" > /dev/null 2>&1
"$DIFF" "$TMP/b.ppm" "$TMP/c.ppm" --min-psnr 45 --max-over2 0.5 > /dev/null && FAIL "the comparison cannot tell rotate y -90 from 90"

# errors: one line naming the scene file and line, exit 1, no image
bad() { # NAME EXPECTED LINE
    printf "${head}$3\n" > "$TMP/bad.txt"
    "$RT" -q -o "$TMP/bad.png" "$TMP/bad.txt" > /dev/null 2> "$TMP/err"
    rc=$?
    { [ $rc -eq 1 ] && [ "$(wc -l < "$TMP/err")" -eq 1 ] && grep -q "bad.txt:7: mesh: .*$2" "$TMP/err" &&
      [ ! -e "$TMP/bad.png" ]; } || FAIL "$1: exit $rc, $(cat "$TMP/err")"
}
printf 'not a model\n' > "$TMP/junk.stl"
cp "$M/OBJ/testline.obj" "$TMP/points.obj"
bad "missing model" "nothere.obj" "mesh: nothere.obj"
bad "unreadable model" "junk.stl" "mesh: junk.stl"
bad "no triangles" "no triangles" "mesh: points.obj"
bad "unknown transform" "unknown transform 'spin'" "mesh: box.obj spin 3"
bad "short translate" "translate: expected X Y Z" "mesh: box.obj translate 1 2"
bad "no file" "expected a model file name" "mesh:"
bad "overlong transform word" "cannot read the transform" "mesh: box.obj scale 2 $(printf 'r%.0s' $(seq 70)) 5"
bad "open quote in the transform" "cannot read the transform" 'mesh: box.obj translate 1 2 3 "scale 100'
mkfifo "$TMP/fifo.obj"
printf "${head}mesh: fifo.obj\n" > "$TMP/bad.txt"
timeout 20 "$RT" -q -o "$TMP/bad.png" "$TMP/bad.txt" > /dev/null 2> "$TMP/err"
rc=$?
{ [ $rc -eq 1 ] && grep -q "bad.txt:7: mesh: .*fifo.obj: not a regular file" "$TMP/err"; } || FAIL "a FIFO as a model: exit $rc, $(cat "$TMP/err")"
printf 'v 1e38 0 -5\nv 0 1 -5\nv 1 0 -5\nf 1 2 3\n' > "$TMP/huge.obj"
bad "a vertex past float range" "not finite" "mesh: huge.obj scale 10"
[ $fail -eq 0 ] && echo "models: ok"
exit $fail
