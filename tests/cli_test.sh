#!/bin/sh
# cli_test.sh RAYTRACE IMGDIFF SRCDIR - the raytrace command as a user meets it:
# options, the record line, image formats, and bad input (one line on stderr
# naming the file and line, exit status 1, no output file).
set -u
rt=$1 imgdiff=$2 src=$3
abspath() { echo "$(cd "$(dirname "$1")" && pwd)/$(basename "$1")"; }
rt=$(abspath "$rt") imgdiff=$(abspath "$imgdiff")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

# --- a good run: the record line has every documented key, in order
out=$("$rt" --quiet -o "$tmp/demo.png" "$src/scenes/demo.txt") || fail "demo render failed"
keys="scene width height backend accel threads ranks parse_ms build_ms render_ms write_ms total_ms rays primary_rays shadow_rays secondary_rays node_visits prim_tests mrays_per_s image_fnv1a"
pattern="^record:"
for k in $keys; do pattern="$pattern.* $k="; done
echo "$out" | grep -q "$pattern" || fail "record line lacks keys or order: $out"
[ "$(echo "$out" | wc -l)" -eq 1 ] || fail "more than one stdout line"
[ -s "$tmp/demo.png" ] || fail "no PNG written"
rays=$(echo "$out" | sed 's/.* rays=\([0-9]*\).*/\1/')
sum=$(echo "$out" | sed 's/.*primary_rays=\([0-9]*\) shadow_rays=\([0-9]*\) secondary_rays=\([0-9]*\).*/\1 + \2 + \3/')
[ "$rays" -eq "$(( $sum ))" ] || fail "rays ($rays) != primary + shadow + secondary ($sum)"

# --- every format holds the same pixels; the default name comes from the scene
"$rt" -q -o "$tmp/demo.bmp" "$src/scenes/demo.txt" >/dev/null || fail "bmp"
"$rt" -q -o "$tmp/demo.ppm" "$src/scenes/demo.txt" >/dev/null || fail "ppm"
"$imgdiff" "$tmp/demo.png" "$tmp/demo.bmp" | grep -q "maxdiff=0 " || fail "png and bmp differ"
"$imgdiff" "$tmp/demo.png" "$tmp/demo.ppm" | grep -q "maxdiff=0 " || fail "png and ppm differ"
(cd "$tmp" && "$rt" -q "$src/scenes/demo.txt" >/dev/null && [ -s demo.png ]) || fail "default output_image name"
printf 'sphere: 0 0 -5 1\nfilm_resolution: 16 12\n' > "$tmp/noname.txt"
(cd "$tmp" && "$rt" -q noname.txt >/dev/null && [ -s raytraced.bmp ]) || fail "format default raytraced.bmp"

# --- overrides
out=$("$rt" -q -r 40x30 -d 1 -o "$tmp/small.png" "$src/scenes/demo.txt") || fail "overrides"
echo "$out" | grep -q "width=40 height=30" || fail "--resolution ignored"
echo "$out" | grep -q "secondary_rays=0 " || fail "--max-depth 1 still traced secondary rays"
# --isa: a bad name is one line naming the option, exit 1; every entry this
# CPU runs gives the same image and counters (tests/unit/test_cpu_trace.c
# checks them ray by ray)
"$rt" -q --isa mmx -o "$tmp/isa.png" "$src/scenes/demo.txt" > /dev/null 2> "$tmp/isa.err" && fail "--isa mmx accepted"
grep -q "^raytrace: --isa: unknown instruction set 'mmx'" "$tmp/isa.err" && [ "$(wc -l < "$tmp/isa.err")" -eq 1 ] ||
    fail "--isa mmx: $(cat "$tmp/isa.err")"
ref=$("$rt" -q --isa c -r 40x30 -o "$tmp/isa.png" "$src/scenes/glass.txt" | tr ' ' '\n' | grep -E '^(image_fnv1a|node_visits|prim_tests)=')
for isa in sse2 avx2 avx512; do
    out=$("$rt" -q --isa $isa -r 40x30 -o "$tmp/isa.png" "$src/scenes/glass.txt" 2> /dev/null) || continue # (not this CPU's)
    [ "$(echo "$out" | tr ' ' '\n' | grep -E '^(image_fnv1a|node_visits|prim_tests)=')" = "$ref" ] || fail "--isa $isa differs from c"
    echo "$out" | grep -q " isa=$isa" || fail "--isa $isa: the record says otherwise"
done
"$rt" -q --calibrate -r 16x12 -o "$tmp/cal.png" "$src/scenes/demo.txt" | grep -q ' calib_ms=[0-9.]*$' || fail "--calibrate adds no calib_ms"
"$rt" --version | grep -q "raybench" || fail "--version"
"$rt" --help | grep -q -- "--accel" || fail "--help"

# --- bad input: exit 1, exactly one stderr line naming the place, no output
bad() { # bad NAME EXPECTED_SUBSTRING ARGS...
    name=$1 want=$2
    shift 2
    rm -f "$tmp/out.png"
    "$rt" -q -o "$tmp/out.png" "$@" > "$tmp/stdout" 2> "$tmp/stderr"
    rc=$?
    [ $rc -eq 1 ] || fail "$name: exit status $rc, want 1"
    [ "$(wc -l < "$tmp/stderr")" -eq 1 ] || fail "$name: stderr is not one line: $(cat "$tmp/stderr")"
    grep -q -- "$want" "$tmp/stderr" || fail "$name: stderr '$(cat "$tmp/stderr")' lacks '$want'"
    [ ! -s "$tmp/stdout" ] || fail "$name: printed a record"
    [ ! -e "$tmp/out.png" ] || fail "$name: wrote an output file"
    ls "$tmp" | grep -q '\.tmp\.' && fail "$name: left a temporary file"
}
bad "huge pages" "--huge-pages" --huge-pages maybe "$src/scenes/glass.txt"
bad "gpu split" "--gpu-split" --gpu-split 101 "$src/scenes/glass.txt"
bad "gpu split" "--gpu-split" --gpu-split -1 "$src/scenes/glass.txt"
bad "gpu split" "--gpu-split" --gpu-split automatic "$src/scenes/glass.txt"
"$rt" -q --gpu-split auto -r 8x6 -o "$tmp/split.png" "$src/scenes/glass.txt" > /dev/null || fail "--gpu-split auto refused"
for h in on off; do # the same image and work either way; the record says which
    out=$("$rt" -q --huge-pages $h -r 40x30 -o "$tmp/h.png" "$src/scenes/glass.txt") || fail "--huge-pages $h failed"
    echo "$out" | tr ' ' '\n' | grep -qx "huge_pages=$h" || fail "--huge-pages $h: the record lacks huge_pages=$h"
    echo "$out" | tr ' ' '\n' | grep -E '^(image_fnv1a|node_visits|prim_tests|sah_cost)=' > "$tmp/huge-$h.txt"
done
cmp -s "$tmp/huge-on.txt" "$tmp/huge-off.txt" || fail "--huge-pages off changed the image or the tree"
printf 'sphere: 0 0 -5 1\n\nsphere: 1 2\n' > "$tmp/count.txt"
bad "wrong count" "count.txt:3:" "$tmp/count.txt"
printf 'vertex: 0 0 0\ntriangle: 0 1 2\n' > "$tmp/index.txt"
bad "index range" "index.txt:2:" "$tmp/index.txt"
printf 'camera_fwd: 0 0 0\n' > "$tmp/cam.txt"
bad "zero camera_fwd" "cam.txt:1:" "$tmp/cam.txt"
printf 'film_resolution: 100000 100000\n' > "$tmp/huge.txt"
bad "absurd resolution" "huge.txt:1:.*GiB" "$tmp/huge.txt"
head -c 3000 /dev/urandom > "$tmp/garbage.txt"
printf '\001\002' >> "$tmp/garbage.txt"
bad "binary garbage" "garbage.txt:" "$tmp/garbage.txt"
bad "missing file" "nothere.txt: cannot open" "$tmp/nothere.txt"
bad "bad accel" "--accel" --accel fast "$src/scenes/demo.txt"
bad "bad resolution option" "--resolution" --resolution 0x10 "$src/scenes/demo.txt"
bad "bad depth option" "--max-depth" --max-depth -2 "$src/scenes/demo.txt"
bad "unknown backend" "unknown backend" --backend vulkan "$src/scenes/demo.txt"
bad "unknown option" "unknown option" --frobnicate "$src/scenes/demo.txt"
printf 'sphere: 0 0 -5 1\nmaterial: 0 0 0 0 0 0 0 0 0 1 .5 .5 .5 0\n' > "$tmp/glass0.txt"
bad "transmissive ior 0" "glass0.txt:2:.*index of refraction" "$tmp/glass0.txt"
# an output_image name the writer cannot use: the scene's file and line, and
# nothing written in the current directory
printf 'film_resolution: 8 6\noutput_image: out.xyz\nsphere: 0 0 -5 1\n' > "$tmp/badout.txt"
(cd "$tmp" && "$rt" -q badout.txt > stdout 2> stderr)
[ $? -eq 1 ] || fail "output_image out.xyz: wrong exit status"
[ "$(cat "$tmp/stderr")" = "badout.txt:2: output_image: out.xyz: unknown image format (use .png, .bmp or .ppm)" ] ||
    fail "output_image out.xyz: stderr '$(cat "$tmp/stderr")'"
[ ! -e "$tmp/out.xyz" ] || fail "output_image out.xyz: wrote a file"
# -o overrides the scene's name, so the scene's unusable name cannot matter
"$rt" -q -o "$tmp/ok.ppm" "$tmp/badout.txt" > /dev/null || fail "-o did not override a bad output_image"

# A scene's own output_image stays in the working folder: an absolute path,
# "..", or a folder that is a link out are refused with the scene's file and
# line, and no file is written there; -o stays the user's free choice.
mkdir -p "$tmp/victim" "$tmp/work/sub" && ln -s "$tmp/victim" "$tmp/work/out"
for o in "$tmp/victim/photo.png" ../victim/photo.png sub/../../victim/photo.png out/photo.png; do
    printf 'film_resolution: 8 6\noutput_image: %s\nsphere: 0 0 -5 1\n' "$o" > "$tmp/work/esc.txt"
    (cd "$tmp/work" && "$rt" -q esc.txt > stdout 2> stderr)
    [ $? -eq 1 ] || fail "output_image $o: not refused"
    grep -q "^esc.txt:2: output_image: '$o'" "$tmp/work/stderr" || fail "output_image $o: stderr '$(cat "$tmp/work/stderr")'"
    [ -z "$(ls -A "$tmp/victim")" ] || fail "output_image $o: wrote $(ls -A "$tmp/victim")"
done
printf 'film_resolution: 8 6\noutput_image: sub/in.ppm\nsphere: 0 0 -5 1\n' > "$tmp/work/in.txt"
(cd "$tmp/work" && "$rt" -q in.txt > /dev/null) && [ -s "$tmp/work/sub/in.ppm" ] || fail "output_image sub/in.ppm inside the folder refused"
"$rt" -q -o "$tmp/victim/mine.ppm" "$tmp/work/esc.txt" > /dev/null && [ -s "$tmp/victim/mine.ppm" ] || fail "-o outside the folder refused"

# Bytes that are not UTF-8 quoted from a scene into a message come out
# escaped (\xNN; the parser already refuses control bytes as binary data);
# UTF-8 text is kept.
for v in '\377\233' '\303\251'; do
    printf "film_resolution: 8 6\\nsphere: 0 0 -5 1$v\\n" > "$tmp/esc2.txt"
    "$rt" -q -o "$tmp/e.ppm" "$tmp/esc2.txt" > /dev/null 2> "$tmp/stderr"
    [ $? -eq 1 ] || fail "a bad value with bytes $v: wrong exit status"
    LC_ALL=C grep -q "$(printf '[\001-\010\013-\037\177\377\233]')" "$tmp/stderr" && fail "raw bytes in a message: $(od -c "$tmp/stderr" | head -3)"
done
grep -q "esc2.txt:2: .*'1$(printf '\303\251')'" "$tmp/stderr" || fail "UTF-8 in a message was escaped: '$(cat "$tmp/stderr")'"
printf 'film_resolution: 8 6\nsphere: 0 0 -5 1\377\233\n' > "$tmp/esc2.txt"
"$rt" -q -o "$tmp/e.ppm" "$tmp/esc2.txt" > /dev/null 2> "$tmp/stderr"
grep -q "esc2.txt:2: .*'1\\\\xff\\\\x9b'" "$tmp/stderr" || fail "escaped message: '$(cat "$tmp/stderr")'"

# --- the course's tools write ior 0 for opaque materials: such a scene renders
printf 'film_resolution: 16 12\nmaterial: .1 .7 0 .1 .7 0 0 0 0 0 0 0 0 0\nsphere: 0 0 -5 1\n' > "$tmp/ior0.txt"
printf 'film_resolution: 16 12\nmaterial: .1 .7 0 .1 .7 0 0 0 0 0 0 0 0 1\nsphere: 0 0 -5 1\n' > "$tmp/ior1.txt"
h0=$("$rt" -q -o "$tmp/ior0.ppm" "$tmp/ior0.txt" | sed -n 's/.*image_fnv1a=\([0-9a-f]*\).*/\1/p')
h1=$("$rt" -q -o "$tmp/ior1.ppm" "$tmp/ior1.txt" | sed -n 's/.*image_fnv1a=\([0-9a-f]*\).*/\1/p')
[ -n "$h0" ] && [ "$h0" = "$h1" ] || fail "opaque material with ior 0: '$h0', with ior 1: '$h1'"

# --- a FIFO as the scene is refused at once instead of waiting for a writer
mkfifo "$tmp/fifo.txt"
timeout 10 "$rt" -q -o "$tmp/f.ppm" "$tmp/fifo.txt" > /dev/null 2> "$tmp/stderr"
rc=$?
[ $rc -eq 1 ] && grep -q "fifo.txt: not a regular file" "$tmp/stderr" || fail "FIFO scene: exit $rc, '$(cat "$tmp/stderr")'"

# --- a material that reflects and transmits at max_depth 32: warned up front
# (the render is the user's choice; a harness timeout bounds it: test-e2e.sh)
printf 'film_resolution: 1 1\nmax_depth: 32\nmaterial: 0 0 0 0 0 0 .5 .5 .5 10 .5 .5 .5 1.5\nsphere: 0 0 -5 1\n' > "$tmp/deep.txt"
"$rt" -q -o "$tmp/deep.ppm" "$tmp/deep.txt" > /dev/null 2> "$tmp/stderr" || fail "deep scene (the ray misses) failed"
grep -q "deep.txt:2: warning: max_depth 32 .* 4.29e+09 rays per pixel" "$tmp/stderr" || fail "no deep-recursion warning: '$(cat "$tmp/stderr")'"
"$rt" -q -d 5 -o "$tmp/deep.ppm" "$tmp/deep.txt" > /dev/null 2> "$tmp/stderr" || fail "deep scene at -d 5"
[ ! -s "$tmp/stderr" ] || fail "a warning at max_depth 5: '$(cat "$tmp/stderr")'"

# --- SIGTERM or SIGKILL while the image is being written: no file of any
# name is left. The image is written unnamed (O_TMPFILE) and named only once
# whole, so the test waits until the process holds a file open in the
# output folder (/proc/PID/fd: a 6000x6000 PPM takes about half a second to
# write), then signals. SIGINT takes SIGTERM's handler, but a shell's
# background job ignores it, so it is not tried here.
printf 'film_resolution: 6000 6000\n' > "$tmp/big.txt"
mkdir "$tmp/sig"
for sig in TERM KILL; do
    "$rt" -q -o "$tmp/sig/big.ppm" "$tmp/big.txt" > /dev/null 2>&1 &
    pid=$!
    seen=0
    for _ in $(seq 3000); do
        if ls -l /proc/$pid/fd 2> /dev/null | grep -q "$tmp/sig/"; then seen=1; break; fi
        kill -0 $pid 2> /dev/null || break
        sleep 0.005
    done
    kill -$sig $pid 2> /dev/null
    wait $pid
    [ $seen = 1 ] || fail "SIG$sig: the image file being written never showed (the write was too quick to catch)"
    [ -z "$(ls -A "$tmp/sig")" ] || fail "SIG$sig during the write left: $(ls -A "$tmp/sig")"
done

# --- --quiet hides progress, not warnings (README)
printf 'film_resolution: 8 6\nsphere: 0 0 -5 1\nshininess: 3\n' > "$tmp/warn.txt"
"$rt" -q -o "$tmp/w.ppm" "$tmp/warn.txt" > /dev/null 2> "$tmp/stderr" || fail "warning scene failed"
grep -q "warn.txt:3: warning: unknown command 'shininess'" "$tmp/stderr" || fail "--quiet hid the warning: '$(cat "$tmp/stderr")'"

rm -f "$tmp/out.png"
"$rt" -q -o "$tmp/out.tga" "$src/scenes/demo.txt" > /dev/null 2> "$tmp/stderr"
[ $? -eq 1 ] && grep -q "unknown image format" "$tmp/stderr" || fail "unknown extension accepted"
"$rt" -q -o "$tmp/no/such/dir/out.png" "$src/scenes/demo.txt" > /dev/null 2> "$tmp/stderr"
[ $? -eq 1 ] && grep -q "cannot write" "$tmp/stderr" || fail "unwritable output accepted"

mkdir -p "$tmp/isdir.png"
"$rt" -q -o "$tmp/isdir.png" "$src/scenes/demo.txt" > /dev/null 2> "$tmp/stderr"
[ $? -eq 1 ] && grep -q "is a directory" "$tmp/stderr" || fail "a directory as output accepted"
bad "overlong option value" "--resolution" -r "64x$(printf '0%.0s' $(seq 58))640" "$src/scenes/demo.txt"
for v in 0 1001 -1 5x ""; do bad "--runs '$v'" "--runs" --runs "$v" "$src/scenes/demo.txt"; done
for v in -1 1001 5x ms 5s 600001ms; do bad "--warmup '$v'" "--warmup" --warmup "$v" "$src/scenes/demo.txt"; done

# --- --runs and --warmup: every backend counts them the same way; the image
# and the counters are the single render's, render_ms is the median of the
# runs and render_ms_best the fastest (never above the median)
one=$("$rt" -q -r 32x24 -o "$tmp/r1.ppm" "$src/scenes/demo.txt") || fail "one run"
three=$("$rt" -q -r 32x24 --runs 3 --warmup 2 -o "$tmp/r3.ppm" "$src/scenes/demo.txt") || fail "--runs 3 --warmup 2"
key() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
[ "$(key "$one" runs)/$(key "$one" warmups)" = 1/0 ] || fail "defaults: runs=$(key "$one" runs) warmups=$(key "$one" warmups)"
[ "$(key "$three" runs)/$(key "$three" warmups)" = 3/2 ] || fail "--runs 3 --warmup 2: runs=$(key "$three" runs) warmups=$(key "$three" warmups)"
for k in image_fnv1a rays node_visits prim_tests; do
    [ "$(key "$one" $k)" = "$(key "$three" $k)" ] || fail "--runs 3 changed $k: $(key "$one" $k) vs $(key "$three" $k)"
done
awk -v b="$(key "$three" render_ms_best)" -v m="$(key "$three" render_ms)" 'BEGIN { exit !(b > 0 && b <= m) }' ||
    fail "render_ms_best $(key "$three" render_ms_best) vs render_ms $(key "$three" render_ms)"
timed=$("$rt" -q -r 32x24 --warmup 30ms -o "$tmp/r4.ppm" "$src/scenes/demo.txt") || fail "--warmup 30ms"
[ "$(key "$timed" warmups)" -ge 1 ] || fail "--warmup 30ms: warmups=$(key "$timed" warmups)"

# --- the product reads no tuning variables from the environment: every
# choice a user has is an option (docs/gpu.md)
if strings "$rt" | grep -E '^RAYBENCH_' > "$tmp/env"; then
    fail "raytrace names environment variables: $(tr '\n' ' ' < "$tmp/env")"
fi

# --- images get the usual permissions (0666 less the umask), not mkstemp's 0600
(umask 022 && "$rt" -q -r 16x12 -o "$tmp/mode.png" "$src/scenes/demo.txt" > /dev/null) || fail "mode render"
[ "$(stat -c %a "$tmp/mode.png")" = 644 ] || fail "image mode $(stat -c %a "$tmp/mode.png"), want 644"

# --- an existing output survives a failed run untouched
cp "$tmp/demo.png" "$tmp/keep.png"
"$rt" -q -o "$tmp/keep.png" "$tmp/count.txt" > /dev/null 2>&1
cmp -s "$tmp/demo.png" "$tmp/keep.png" || fail "a failed run damaged an existing image"

echo "cli_test: $fails failures"
[ $fails -eq 0 ]

# --- the commit raytrace was built from (renderer/meson.build, vcs_tag): a
# short hash with -dirty, or unknown outside a checkout; -V and the record agree
commit=$("$rt" -V | sed -n 's/^commit: //p')
echo "$commit" | grep -Eq '^([0-9a-f]{4,40}(-dirty)?|unknown)$' || fail "-V: commit '$commit'"
[ "$(key "$one" commit)" = "$commit" ] || fail "record: commit=$(key "$one" commit), -V says '$commit'"
echo "cli_test (with commit): $fails failures"
[ $fails -eq 0 ]
