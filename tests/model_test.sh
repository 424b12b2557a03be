#!/bin/sh
# model_test.sh RAYTRACE IMGDIFF - model files through Assimp, on Debian's
# assimp-testmodels (scripts/install-deps.sh installs them; they are never
# copied into the repository): `raytrace MODEL` for OBJ, PLY, STL, glTF and
# GLB; `mesh:` with a transform against the same box written out by hand
# with the transform's closed form; and import errors as one line naming
# the scene file and line. Missing models fail it.
RT=$1
DIFF=$2
M=/usr/share/assimp/models
[ -d "$M" ] || { echo "FAIL: no $M (scripts/install-deps.sh installs assimp-testmodels)"; exit 1; }
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
# --- the model's own file system: every file Assimp reads lies in the
# model's folder, is a regular file, and a refused one fails the import
mkdir -p "$TMP/m/sub"
echo secret > "$TMP/secret.bin"
python3 - "$TMP" <<'PY' || FAIL "python3 could not write the test models"
import base64, json, struct, sys
t = sys.argv[1]
pos = struct.pack('<9f', 0, 0, 0, 1, 0, 0, 0, 1, 0)
open(t + '/m/tri.bin', 'wb').write(pos)
def gltf(uri, nodes=None, scenes=(0,), tris=1):
    idx = struct.pack('<%dI' % (3 * tris), *([0, 1, 2] * tris))
    if uri is None:
        uri = 'data:application/octet-stream;base64,' + base64.b64encode(pos + idx).decode()
    return json.dumps({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(scenes)}],
        "nodes": nodes or [{"mesh": 0}], "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": 36 + len(idx), "uri": uri}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": len(idx)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5125, "count": 3 * tris, "type": "SCALAR"}]})
def put(name, text): open(t + '/m/' + name, 'w').write(text)
put('out.gltf', gltf('../secret.bin'))
put('abs.gltf', gltf(t + '/secret.bin'))
put('link.gltf', gltf('link.bin'))
put('inlink.gltf', gltf('sub/inlink.bin'))
put('fifo.gltf', gltf('fifo.bin'))
# the same index data: in-folder .bin renders (only the positions are in tri.bin: indices follow)
idx = struct.pack('<3I', 0, 1, 2)
open(t + '/m/sub/tri_idx.bin', 'wb').write(pos + idx)
put('in.gltf', gltf('sub/tri_idx.bin'))
# instancing: each level lists its child twice; 26 levels of one triangle
# expand to 2^26 triangles, 20 levels of empty nodes to 2^20 nodes
put('explode.gltf', gltf(None, [{"children": [i + 1, i + 1]} for i in range(26)] + [{"mesh": 0}]))
put('nodes.gltf', gltf(None, [{"children": [i + 1, i + 1]} for i in range(20)] + [{"mesh": 0}]))
put('cycle.gltf', gltf(None, [{"children": [1]}, {"children": [0], "mesh": 0}]))
# 10 levels of 2 instances of a 60,000-triangle mesh: 61 M triangles, 720 KB of indices
put('wide.gltf', gltf(None, [{"children": [i + 1, i + 1]} for i in range(10)] + [{"mesh": 0}], tris=60000))
# a modest instanced one: 3 levels of two children, one moved: 8 triangles
nodes = []
for i in range(3):
    nxt = 3 * (i + 1) if i < 2 else 9
    nodes += [{"children": [3 * i + 1, 3 * i + 2]}, {"children": [nxt], "translation": [2.0 ** i, 0, 0]},
              {"children": [nxt], "translation": [0, 2.0 ** i, 0]}]
put('inst.gltf', gltf(None, nodes + [{"mesh": 0}]))
# node transforms as PreTransformVertices applied them: the parent moves
# (0 0 -4), the child scales by 2 then moves (1 0 0): (x y z) -> (2x+1, 2y, 2z-4)
put('xf.gltf', gltf(None, [{"children": [1], "translation": [0, 0, -4]},
                           {"mesh": 0, "scale": [2, 2, 2], "translation": [1, 0, 0]}]))
PY
ln -s ../secret.bin "$TMP/m/link.bin"
cp "$TMP/m/sub/tri_idx.bin" "$TMP/m/sub/real.bin"
ln -s real.bin "$TMP/m/sub/inlink.bin"
mkfifo "$TMP/m/fifo.bin" "$TMP/m/fifo.mtl"
printf 'mtllib ../secret.bin\nv 0 0 -5\nv 1 0 -5\nv 0 1 -5\nf 1 2 3\n' > "$TMP/m/out.obj"
printf 'mtllib fifo.mtl\nv 0 0 -5\nv 1 0 -5\nv 0 1 -5\nf 1 2 3\n' > "$TMP/m/fifo.obj"
# bad, under a time limit: a model that makes the import hang fails the test
bad_t() { # NAME EXPECTED LINE [SECONDS]
    printf "${head}$3\n" > "$TMP/bad.txt"
    ( ulimit -v 2000000; exec timeout "${4:-10}" "$RT" -q -o "$TMP/bad.png" "$TMP/bad.txt" ) > /dev/null 2> "$TMP/err"
    rc=$?
    [ $rc -ne 124 ] || { FAIL "$1: still running after ${4:-10} s"; return; }
    { [ $rc -eq 1 ] && [ "$(wc -l < "$TMP/err")" -eq 1 ] && grep -q "bad.txt:7: mesh: .*$2" "$TMP/err" &&
      [ ! -e "$TMP/bad.png" ]; } || FAIL "$1: exit $rc, $(cat "$TMP/err")"
}
bad_t "glTF buffer outside the folder" "m/out.gltf: reference '../secret.bin' leaves the model's folder" "mesh: m/out.gltf"
bad_t "glTF buffer by absolute path" "m/abs.gltf: reference '/.*secret.bin' leaves the model's folder" "mesh: m/abs.gltf"
bad_t "glTF buffer through a link out of the folder" "m/link.gltf: reference 'link.bin' leaves the model's folder" "mesh: m/link.gltf"
bad_t "OBJ mtllib outside the folder" "m/out.obj: reference '../secret.bin' leaves the model's folder" "mesh: m/out.obj"
bad_t "a FIFO as glTF buffer" "m/fifo.gltf: reference 'fifo.bin' cannot be read: .*not a regular file" "mesh: m/fifo.gltf"
bad_t "a FIFO as mtllib" "m/fifo.obj: reference 'fifo.mtl' cannot be read: .*not a regular file" "mesh: m/fifo.obj"
# references inside the folder render: a .bin in a subfolder, a link to a file beside it
for f in in inlink; do
    printf "${head}mesh: m/$f.gltf translate 0 0 -3\n" > "$TMP/ok.txt"
    rec=$("$RT" -q -o "$TMP/ok.png" "$TMP/ok.txt" 2> "$TMP/err") || FAIL "$f.gltf (buffer inside the folder): $(cat "$TMP/err")"
    [ "$(key "$rec" prims)" = 1 ] || FAIL "$f.gltf: $(key "$rec" prims) triangles, want 1"
done

# --- instancing: the expanded count refused before anything grows
bad_t "26 levels of doubled children" "m/explode.gltf: expands to more than 50000000 triangles (nodes instanced repeatedly); raise the limit with --max-model-triangles N" "mesh: m/explode.gltf" 5
bad_t "20 levels of doubled empty nodes" "m/nodes.gltf: expands to more than 1000000 node instances" "mesh: m/nodes.gltf" 5
bad_t "a node graph with a cycle" "m/cycle.gltf: the node graph has a cycle" "mesh: m/cycle.gltf" 5
bad_t "10 levels of a 60,000-triangle mesh" "m/wide.gltf: expands to more than 50000000 triangles" "mesh: m/wide.gltf" 5
rec=$("$RT" -q -r 160x120 -o "$TMP/inst.png" "$TMP/m/inst.gltf" 2> "$TMP/err") || FAIL "inst.gltf: $(cat "$TMP/err")"
[ "$(key "$rec" prims)" = 8 ] || FAIL "inst.gltf: $(key "$rec" prims) triangles, want 8 (2^3 instances)"
# (8 unit triangles spread over 8x8 units: about 200 of the 19,200 pixels)
[ "$(key "$rec" shadow_rays)" -gt 100 ] || FAIL "inst.gltf: not in view ($(key "$rec" shadow_rays) shadow rays)"
printf "${head}mesh: m/xf.gltf\n" > "$TMP/xf.txt"
printf "${head}vertex: 1 0 -4\nvertex: 3 0 -4\nvertex: 1 2 -4\ntriangle: 0 1 2\n" > "$TMP/xf_hand.txt"
"$RT" -q -o "$TMP/xf.ppm" "$TMP/xf.txt" > /dev/null 2> "$TMP/err" || FAIL "xf.gltf: $(cat "$TMP/err")"
"$RT" -q -o "$TMP/xf_hand.ppm" "$TMP/xf_hand.txt" > /dev/null || FAIL "xf_hand.txt"
"$DIFF" "$TMP/xf_hand.ppm" "$TMP/xf.ppm" --min-psnr 45 --max-over2 0.5 || FAIL "glTF node transforms differ from their closed form"
# the limit is the user's: inst.gltf's 8 triangles pass at 8 and are refused at 7
rec=$("$RT" -q -r 32x24 --max-model-triangles 8 -o "$TMP/w.png" "$TMP/m/inst.gltf" 2> "$TMP/err") ||
    FAIL "--max-model-triangles 8 on inst.gltf: $(cat "$TMP/err")"
[ "$(key "$rec" prims)" = 8 ] || FAIL "inst.gltf at the limit: $(key "$rec" prims) triangles, want 8"
"$RT" -q -r 32x24 --max-model-triangles 7 -o "$TMP/w.png" "$TMP/m/inst.gltf" > /dev/null 2> "$TMP/err" &&
    FAIL "--max-model-triangles 7 let inst.gltf's 8 triangles through"
grep -q "expands to more than 7 triangles" "$TMP/err" || FAIL "--max-model-triangles 7: '$(cat "$TMP/err")'"
"$RT" -q --max-model-triangles 0 "$TMP/m/inst.gltf" > /dev/null 2> "$TMP/err" && FAIL "--max-model-triangles 0 accepted"
grep -q "option --max-model-triangles '0'" "$TMP/err" || FAIL "--max-model-triangles 0: '$(cat "$TMP/err")'"

# --- PLY headers Assimp 5.2.5 loops on or allocates gigabytes for
printf 'ply\nformat ascii 1.0\n' > "$TMP/m/noend.ply"
bad_t "PLY without end_header" "m/noend.ply: PLY header without end_header" "mesh: m/noend.ply"
{ printf 'ply\nformat ascii 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\nproperty float z\n'
  printf 'element face 1\nproperty list uchar int vertex_indices\nend_header\n'
  for i in $(seq 30); do printf '0 0 0\n'; done; } > "$TMP/m/big.ply"
bad_t "PLY declaring 10^8 vertices in 180 bytes" "m/big.ply: header declares 100000000 vertices but the file holds 180 bytes after it" "mesh: m/big.ply"
{ printf 'ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n'
  printf 'element face 100000000\nproperty list uchar int vertex_indices\nend_header\n'
  head -c 36 /dev/zero; } > "$TMP/m/bigface.ply"
bad_t "binary PLY declaring 10^8 faces" "m/bigface.ply: header declares 100000000 faces but the file holds 36 bytes after it" "mesh: m/bigface.ply"
# two PLY files the fuzz target found (tests/fuzz) that crash Assimp 5.2.5
# under the old import: a short vertex line ("1 00") shifts the tokens and
# leaves faces without indices, which SortByPType reads past (SIGBUS); an
# element declared twice makes the loader jump to a wild address (SIGSEGV)
cat > "$TMP/m/shifted.ply" <<'EOF'
ply
format ascii 1.0
comment tiny
element vertex 8
property float x
property float y
property float z
element face 6
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
1 00
1 1 0
0 1 0
0 0 1
1 0 1
1 1 1
0 1 1
4 0 3 2 1
4 4 5 6 7
4 0 1 5 4
4 1 2 6 5
4 2 3 7 6
4 3 0 4 7
EOF
cat > "$TMP/m/twice.ply" <<'EOF'
ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
property float nx
property float ny
property float nz
element face 1
property list uchar uint vertex_indices
end_z
element face 6
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
1 0 1
1 1 1
0 1 1
4 0 3 2 1
4 4 5 6 7
4 0 1 5 4
4 1 2 6 5
4 2 3 7 6
4 3 0 4 7
EOF
printf 'ply\nformat ascii 1.0\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n2147483647 0 0 0 0 1\n' > "$TMP/m/longlist.ply"
bad_t "PLY list of 2^31 indices (Assimp reads on for minutes)" "m/longlist.ply: PLY list of too many items" "mesh: m/longlist.ply"
# found by fuzz-model: Assimp allocated 32 GB on an element name that is
# not a word, and on data that does not match the header
printf 'ply\nformat ascii 1.0\nelement ve}tex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n4294967295 0 0\n1 0 0\n0 1 0\n3 0 1 2\n' > "$TMP/m/name.ply"
bad_t "PLY element name that is not a word" "m/name.ply: PLY element name 've}tex' is not a word" "mesh: m/name.ply"
printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 nan 0\n1 0 0\n0 1 0\n3 0 1 2\n' > "$TMP/m/nan.ply"
bad_t "PLY data that is not a number" "m/nan.ply: PLY data of element 'vertex' 0 does not match its header" "mesh: m/nan.ply"
# found by fuzz-model: an accessor index past the file's made Assimp allocate tens of GB
printf '{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],"meshes":[{"primitives":[{"attributes":{"POSITION":18446744073709551615}}]}]}' > "$TMP/m/acc.gltf"
bad_t "glTF accessor index past the file's" "m/acc.gltf: a mesh primitive names an accessor the file does not have" "mesh: m/acc.gltf"
bad_t "PLY faces without indices (a short vertex line shifts the data)" "m/shifted.ply: PLY element 'vertex' 5 has more values than its header says" "mesh: m/shifted.ply"
# a property of a type Assimp does not know: it allocated 33 GB (found by fuzz-model)
printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty f,oty float ny\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n0 0 0 1\n1 0 0 1\n0 1 0 1\n3 0 1 2\n' > "$TMP/m/badtype.ply"
bad_t "PLY property of an unknown type" "m/badtype.ply: PLY property line of an unknown type or shape: 'property f,oty float ny'" "mesh: m/badtype.ply"
printf 'ply\nformat ascii 1.0\nelement face 1\nproperty list uchar vertex_indices\nend_header\n3 0 1 2\n' > "$TMP/m/shortlist.ply"
bad_t "PLY list property without its item type" "m/shortlist.ply: PLY property line of an unknown type or shape" "mesh: m/shortlist.ply"
bad_t "PLY element declared twice" "m/twice.ply: PLY header declares element 'face' twice" "mesh: m/twice.ply"
[ $fail -eq 0 ] && echo "models: ok"
exit $fail
