#!/usr/bin/env bash
# make-golden.sh [BUILD] - renders the golden images of the project's own
# scenes into tests/golden/ with the serial backend and the BVH, and writes
# tests/golden/README.md naming the commit that made them. Run it from a
# clean tree after a deliberate change of the images (the golden-* tests say
# by how much they moved), and commit the result.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
rt=$build/renderer/raytrace
gen=$build/renderer/scenegen
[ -x "$rt" ] && [ -x "$gen" ] || { echo "make-golden: build first (ninja -C $build)" >&2; exit 1; }
if [ -n "$(git status --porcelain -- renderer)" ]; then
    echo "make-golden: renderer/ has uncommitted changes; commit them first so the README names the code" >&2
    exit 1
fi
commit=$(git rev-parse --short HEAD)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# the same bytes as the mesh10k target in tests/meson.build
SCENEGEN=$gen scripts/gen-scenes.sh mesh10k > /dev/null
rows=""
for spec in demo:scenes/demo.txt:160x120 glass:scenes/glass.txt:160x120 odd:tests/scenes/odd.txt:37x23 \
            mesh10k:scenes/generated/mesh10k.txt:160x120; do
    IFS=: read -r name scene res <<< "$spec"
    "$rt" -q --backend serial --accel bvh -r "$res" -o "tests/golden/$name.png" "$scene" > "$tmp/rec"
    hash=$(tr ' ' '\n' < "$tmp/rec" | sed -n 's/^image_fnv1a=//p')
    shown=$scene; [ "$name" = mesh10k ] && shown="scenes/generated/mesh10k.txt (scripts/gen-scenes.sh mesh10k)"
    rows="$rows| \`$name.png\` | $shown | $res | \`$hash\` |"$'\n'
    echo "make-golden: tests/golden/$name.png ($res, image_fnv1a=$hash)"
done
cat > tests/golden/README.md <<MD
# Golden images

Images of the project's own scenes, made by raybench itself: \`raytrace
--backend serial --accel bvh -r WxH\` at commit \`$commit\`
(\`scripts/make-golden.sh\`). The \`golden-*\` tests (tests/image_test.sh)
render each scene again and require PSNR >= 50 dB and at most 0.1% of pixels
with a channel off by more than 2/255, so a change of the shading fails while
a last-bit change of float rounding does not. They catch regressions; the
shading itself is checked against closed-form values in
\`tests/unit/test_optics.c\` and against the course's independent reference
images in the course suite.

| file | scene | size | image_fnv1a |
|---|---|---|---|
$rows
After a deliberate change of the images, run \`scripts/make-golden.sh\` on a
clean tree and commit the images with this file.
MD
