#!/bin/sh
# cache_test.sh RAYTRACE SCENE - the scene cache (--cache DIR): a second run
# loads what the first built, with the same image and counters; a changed
# scene, another accelerator, a corrupt or truncated entry and a tampered
# header all build again (never trusted); an unwritable directory is a
# warning, not a failure; the memo of a file's hash is used only while the
# file is unchanged; a bad option value is one line and exit 1.
RT=$1
SRC=$2
case $RT in /*) ;; *) RT=$(pwd)/$RT ;; esac # (item 2 runs in the model's folder)
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
# ---------------------------------------------------------------------------
# What follows checks the cache against a scene that changes while it is
# read, model files that change, a folder others could write, a writer that
# is killed, and files too large to hash. Each item prints its time.
now_ms() { echo $(($(date +%s%N) / 1000000)); }
# runs perl's loop in the background: MODE mv (a whole copy renamed over
# DST), inplace (DST rewritten in place) or trunc (DST written, then
# truncated to 0), alternating SRC files, until the file STOP exists
start_writer() { # MODE DST STOP SRC...
    perl -e '
        my ($mode, $dst, $stop, @src) = @ARGV;
        my @c = map { local $/; open my $f, "<", $_ or die "$_: $!"; scalar <$f> } @src;
        for (my $n = 0; !-e $stop; $n++) {
            my $c = $c[$n % @c];
            if ($mode eq "mv") {
                open my $f, ">", "$dst.new" or die; print $f $c; close $f; rename "$dst.new", $dst or die;
            } elsif ($mode eq "inplace") {
                open my $f, ">", $dst or die; print $f $c; close $f;
            } else {
                open my $f, ">", $dst or die; print $f $c; close $f;
                select undef, undef, undef, 0.003;
                truncate $dst, 0 or die;
            }
            select undef, undef, undef, 0.001;
        }' "$@" &
    writer=$!
}
stop_writer() { : > "$1"; wait "$writer"; rm -f "$1"; }

# 1. The key is of the bytes parsed. Two scenes A and B are swapped onto
# s.txt while 30 runs, each with a fresh cache folder, render it; then each
# folder must give A's image for A and B's for B wherever it loads. Then the
# same with s.txt rewritten in place: a run may fail (exit 1, one line) but
# never dies of a signal. (Old code: cache_key hashed the file apart from
# the parse, so B's scene went under A's key - or an empty scene, read
# after the rewrite's truncation, under B's - and its mmap could SIGBUS.)
t0=$(now_ms)
R=$TMP/race
mkdir -p "$R"
cp "$SRC" "$R/A.txt"
{ cat "$SRC"; printf 'sphere: 0 3 -12 1\n'; } > "$R/B.txt"
rr() { "$RT" -q -r 24x18 --build-threads 1 -o "$R/o.ppm" "$@"; }
ha=$(key "$(rr "$R/A.txt")" image_fnv1a)
hb=$(key "$(rr "$R/B.txt")" image_fnv1a)
[ -n "$ha" ] && [ -n "$hb" ] && [ "$ha" != "$hb" ] || FAIL "race: A and B must render different images ($ha, $hb)"
for mode in mv inplace; do
    cp "$R/A.txt" "$R/s.txt"
    start_writer $mode "$R/s.txt" "$R/stop" "$R/A.txt" "$R/B.txt"
    ok=0 failed=0 i=0
    while [ $i -lt 30 ]; do
        i=$((i + 1))
        rr --cache "$R/c$mode$i" "$R/s.txt" > /dev/null 2> "$R/err"
        rc=$?
        if [ $rc -eq 0 ]; then
            ok=$((ok + 1))
        elif [ $rc -ge 128 ]; then
            FAIL "race ($mode): run $i died of signal $((rc - 128)): $(cat "$R/err")"
        elif [ $rc -eq 1 ] && [ "$(wc -l < "$R/err")" -eq 1 ] && { grep -q 'changed while it was read' "$R/err" ||
             { [ $mode = inplace ] && grep -q 's\.txt:[0-9]*:' "$R/err"; }; }; then
            # (read while written, or - mv - while renamed over, which moves
            # the old file's ctime: refused; in place, a half-written line)
            failed=$((failed + 1))
        else
            FAIL "race ($mode): run $i: exit $rc, $(cat "$R/err")"
        fi
    done
    stop_writer "$R/stop"
    loaded=0
    i=0
    while [ $i -lt 30 ]; do
        i=$((i + 1))
        # (a folder holds the one entry its stress run stored, if any: once
        # A loaded, B cannot; A's own check may store A, never B)
        ls "$R/c$mode$i/"*.rbc > /dev/null 2>&1 || continue
        rec=
        for which in A B; do
            [ $which = B ] && [ "$(key "$rec" cache)" = loaded ] && continue
            cp "$R/$which.txt" "$R/s.txt"
            rec=$(rr --cache "$R/c$mode$i" "$R/s.txt" 2> "$R/err") || { FAIL "race ($mode): check $i $which: $(cat "$R/err")"; continue; }
            [ "$(key "$rec" cache)" = loaded ] || continue
            loaded=$((loaded + 1))
            want=$ha
            [ $which = B ] && want=$hb
            [ "$(key "$rec" image_fnv1a)" = "$want" ] ||
                FAIL "race ($mode): folder $i holds another scene under $which's key (image $(key "$rec" image_fnv1a), want $want)"
        done
    done
    echo "race ($mode): $ok runs rendered, $failed refused a file changing underneath, $loaded entries loaded and checked"
    [ $loaded -gt 0 ] || FAIL "race ($mode): no run stored A or B: nothing was checked"
done
rm -rf "$R"
echo "item 1 (key/parse race): $(($(now_ms) - t0)) ms"

# 2. Model dependencies: a glTF and the .bin it references. An entry lists
# the .bin with its hash; when the .bin changes (same size) the entry is
# built again and the new triangle renders - as a mesh: line and as
# raytrace MODEL. (Old code: a scene with mesh: was never stored, and
# raytrace MODEL's key covered the .gltf's bytes only, so a changed .bin
# loaded the old triangles.)
t0=$(now_ms)
G=$TMP/gltf
mkdir -p "$G"
printf '%s\n' '{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],' \
    ' "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],' \
    ' "buffers": [{"byteLength": 36, "uri": "m.bin"}], "bufferViews": [{"buffer": 0, "byteLength": 36}],' \
    ' "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",' \
    '   "min": [-1.5, -1, -3], "max": [1.5, 2, -3]}]}' > "$G/m.gltf"
bin1() { perl -e 'print pack("f<*", -1, -1, -3, 1, -1, -3, 0, 1, -3)' > "$G/m.bin"; }
bin2() { perl -e 'print pack("f<*", -1.5, -1, -3, 1.5, -.5, -3, .5, 2, -3)' > "$G/m.bin"; }
printf 'film_resolution: 40 30\ncamera_pos: 0 0 2\ncamera_fwd: 0 0 1\nmaterial: .2 .2 .2 .7 .6 .5 0 0 0 10 0 0 0 1\nambient_light: .2 .2 .2\ndirectional_light: 1 1 1 .2 -.3 -1\nmesh: m.gltf\n' > "$G/s.txt"
for target in s.txt m.gltf; do
    rm -rf "$G/c"
    bin1
    rg() { (cd "$G" && "$RT" -q -r 40x30 -o "$G/o.ppm" "$@" "$target") 2> "$G/err"; }
    p1=$(rg) || FAIL "model ($target): no cache: $(cat "$G/err")"
    g1=$(rg --cache "$G/c") || FAIL "model ($target): first run: $(cat "$G/err")"
    g2=$(rg --cache "$G/c") || FAIL "model ($target): second run: $(cat "$G/err")"
    [ "$(key "$g1" cache)/$(key "$g2" cache)" = built/loaded ] ||
        FAIL "model ($target): built then loaded: $(key "$g1" cache)/$(key "$g2" cache)"
    same "$p1" "$g2" "model ($target): loaded vs no cache"
    [ "$(key "$p1" prims)" = 1 ] || FAIL "model ($target): $(key "$p1" prims) primitives, want 1"
    bin2
    [ "$(stat -c %s "$G/m.bin")" = 36 ] || FAIL "model: m.bin is not 36 bytes"
    p2=$(rg) || FAIL "model ($target): no cache, changed m.bin: $(cat "$G/err")"
    g3=$(rg --cache "$G/c") || FAIL "model ($target): changed m.bin: $(cat "$G/err")"
    [ "$(key "$g3" cache)" = built ] || FAIL "model ($target): a changed m.bin loaded the old entry (cache=$(key "$g3" cache))"
    [ "$(key "$g3" image_fnv1a)" != "$(key "$g2" image_fnv1a)" ] || FAIL "model ($target): the changed m.bin rendered the old image"
    same "$p2" "$g3" "model ($target): changed m.bin vs no cache"
    g4=$(rg --cache "$G/c") || FAIL "model ($target): after the rebuild: $(cat "$G/err")"
    [ "$(key "$g4" cache)" = loaded ] || FAIL "model ($target): the rebuilt entry did not load (cache=$(key "$g4" cache))"
    same "$p2" "$g4" "model ($target): the rebuilt entry"
done
echo "item 2 (model dependencies): $(($(now_ms) - t0)) ms"

# 3. The folder: another user's, writable by group or others, or a symbolic
# link: exit 1, one line, no image. DIR/stat a link: not followed. (Old
# code: no such checks; memos were written through DIR/stat wherever it led.)
t0=$(now_ms)
F=$TMP/folders
mkdir -p "$F"
refused() { # NAME DIR PATTERN
    rm -f "$F/o.ppm"
    "$RT" -q -r 8x6 --cache "$2" -o "$F/o.ppm" "$TMP/m.txt" > /dev/null 2> "$F/err"
    rc=$?
    { [ $rc -eq 1 ] && [ "$(wc -l < "$F/err")" -eq 1 ] && grep -q "^raytrace: scene cache: $3" "$F/err" &&
      [ ! -e "$F/o.ppm" ]; } || FAIL "folder $1: exit $rc, image $([ -e "$F/o.ppm" ] && echo written || echo none), $(cat "$F/err")"
}
if [ "$(id -u)" = 0 ]; then
    mkdir -m 700 "$F/theirs" && chown nobody "$F/theirs" || FAIL "folder: chown nobody failed"
    refused "owned by nobody" "$F/theirs" "$F/theirs belongs to user $(id -u nobody), not to you: refused"
else
    refused "owned by root" / "/ belongs to user 0, not to you: refused"
fi
mkdir -m 700 "$F/c777" "$F/c770" "$F/good" && chmod 0777 "$F/c777" && chmod 0770 "$F/c770"
refused "mode 0777" "$F/c777" "$F/c777 is writable by others (mode 0777): refused; chmod go-w $F/c777"
refused "mode 0770" "$F/c770" "$F/c770 is writable by its group (mode 0770): refused"
ln -s good "$F/link"
refused "a symbolic link" "$F/link" "$F/link is a symbolic link: refused"
[ -z "$(ls -A "$F/good")" ] || FAIL "folder: something was written through the link: $(ls -A "$F/good")"
mkdir -m 700 "$F/x" "$F/withlink"
ln -s ../x "$F/withlink/stat"
# (m.txt settled long ago and the program is older still: memos are due)
s1=$("$RT" -q -r 8x6 --cache "$F/withlink" -o "$F/o.ppm" "$TMP/m.txt" 2> "$F/err") || FAIL "folder: stat a link: the run failed: $(cat "$F/err")"
[ "$(key "$s1" cache)" = built ] || FAIL "folder: stat a link: cache=$(key "$s1" cache)"
[ -z "$(ls -A "$F/x")" ] || FAIL "folder: memos were written through the link DIR/stat: $(ls -A "$F/x")"
[ -L "$F/withlink/stat" ] || FAIL "folder: the link DIR/stat was replaced"
"$RT" -q -r 8x6 --cache "$F/plain" -o "$F/o.ppm" "$TMP/m.txt" > /dev/null 2>&1 || FAIL "folder: a plain run failed"
ls "$F/plain/stat/"*.memo > /dev/null 2>&1 || FAIL "folder: a plain run wrote no memo (the link check proves nothing)"
[ "$(stat -c %a "$F/plain")" = 700 ] || FAIL "folder: a new cache folder has mode $(stat -c %a "$F/plain"), want 700"
echo "item 3 (folder checks): $(($(now_ms) - t0)) ms"

# 4. SIGKILL while a large entry is written leaves nothing behind: the
# entry is unnamed until whole. A watcher kills raytrace the moment one of
# its descriptors is a file in the cache folder (not DIR/stat). (Old code:
# the entry was written as DIR/KEY.rbc.tmp.XXXXXX, which a SIGKILL left.)
t0=$(now_ms)
K=$TMP/kill
mkdir -p "$K"
"$(dirname "$RT")/scenegen" --triangles 300000 --seed 1 -o "$K/big.txt" 2> /dev/null || FAIL "kill: scenegen failed"
caught=0 try=0
while [ $caught = 0 ] && [ $try -lt 5 ] && [ -s "$K/big.txt" ]; do
    try=$((try + 1))
    rm -rf "$K/c"
    "$RT" -q -r 8x6 --cache "$K/c" -o "$K/o.ppm" "$K/big.txt" > /dev/null 2>&1 &
    pid=$!
    seen=$(perl -e '
        my ($pid, $dir) = @ARGV;
        my $end = time + 60;
        while (time < $end) {
            opendir(my $d, "/proc/$pid/fd") or last;
            for my $fd (readdir $d) {
                my $t = readlink("/proc/$pid/fd/$fd");
                next unless defined $t && index($t, "$dir/") == 0 && $t ne "$dir/stat" && index($t, "$dir/stat/") != 0;
                kill "KILL", $pid;
                print "$t\n";
                exit 0;
            }
            closedir $d;
        }' "$pid" "$K/c")
    wait $pid
    rc=$?
    if [ -n "$seen" ]; then
        caught=1
        echo "kill: try $try: killed while writing $seen (exit $rc)"
        [ $rc = 137 ] || FAIL "kill: raytrace ended with $rc, not by SIGKILL ($seen)"
        left=$(ls -A "$K/c" | grep -v '^stat$')
        [ -z "$left" ] || FAIL "kill: the folder holds $left after a SIGKILL mid-write"
        ls "$K/c/stat" 2> /dev/null | grep -q '\.tmp\.' && FAIL "kill: DIR/stat holds $(ls "$K/c/stat")"
    fi
done
[ $caught = 1 ] || FAIL "kill: never caught raytrace writing its entry in $try tries (the test proves nothing)"
k2=$("$RT" -q -r 8x6 --cache "$K/c" -o "$K/o.ppm" "$K/big.txt" 2> "$K/err") || FAIL "kill: the run after the kill failed: $(cat "$K/err")"
[ "$(key "$k2" cache)" = built ] || FAIL "kill: cache=$(key "$k2" cache) after the killed store"
[ "$(ls "$K/c" | grep -c '\.rbc$')" = 1 ] || FAIL "kill: one entry expected: $(ls "$K/c")"
rm -rf "$K/c"
echo "item 4 (SIGKILL mid-store): $(($(now_ms) - t0)) ms"

# 5. A scene larger than 1 GiB is refused before a byte is hashed: a 4 GB
# sparse file fails at once. (Old code: the cache's key mapped and hashed
# all 4 GB before the parse refused it.)
t0=$(now_ms)
truncate -s 4G "$TMP/huge.txt" || FAIL "huge: truncate -s 4G failed"
timeout 5 "$RT" -q -r 8x6 --cache "$TMP/ch" -o "$TMP/h.ppm" "$TMP/huge.txt" > /dev/null 2> "$TMP/err"
rc=$?
ms=$(($(now_ms) - t0))
{ [ $rc -eq 1 ] && grep -q "1073741824-byte limit" "$TMP/err"; } || FAIL "huge: exit $rc after $ms ms, $(cat "$TMP/err")"
[ $ms -lt 2000 ] || FAIL "huge: took $ms ms (the size is known before a byte is read)"
rm -f "$TMP/huge.txt"
echo "item 5 (4 GB sparse scene): $ms ms"

# 6. Entries get 0666 less the umask. (Old code: chmod 0644 whatever the umask.)
t0=$(now_ms)
for u in 077:600 022:644; do
    rm -rf "$TMP/cu"
    (umask "${u%:*}" && exec "$RT" -q -r 8x6 --cache "$TMP/cu" -o "$TMP/o.ppm" "$TMP/m.txt") > /dev/null 2>&1 ||
        FAIL "umask ${u%:*}: the run failed"
    e=$(ls "$TMP/cu/"*.rbc 2> /dev/null | head -n 1)
    [ -n "$e" ] && [ "$(stat -c %a "$e")" = "${u#*:}" ] ||
        FAIL "umask ${u%:*}: entry mode $([ -n "$e" ] && stat -c %a "$e"), want ${u#*:}"
done
echo "item 6 (umask): $(($(now_ms) - t0)) ms"

# 7. A scene truncated underneath: a loop writes a ~5 MB scene and
# truncates it to 0 while 40 runs read it, with and without --cache: a run
# may fail, never of a signal. (Old code: the cache hashed the scene
# through mmap, and a truncation meanwhile was a SIGBUS.)
t0=$(now_ms)
T=$TMP/trunc
mkdir -p "$T"
"$(dirname "$RT")/scenegen" --triangles 70000 --seed 3 -o "$T/big.txt" 2> /dev/null || FAIL "trunc: scenegen failed"
[ "$(stat -c %s "$T/big.txt")" -gt 3000000 ] || FAIL "trunc: the scene is only $(stat -c %s "$T/big.txt") bytes"
cp "$T/big.txt" "$T/s.txt"
start_writer trunc "$T/s.txt" "$T/stop" "$T/big.txt"
i=0 ok=0
while [ $i -lt 40 ]; do
    i=$((i + 1))
    c=
    [ $((i % 2)) = 0 ] && c="--cache $T/c"
    "$RT" -q -r 8x6 $c -o "$T/o.ppm" "$T/s.txt" > /dev/null 2> "$T/err"
    rc=$?
    [ $rc -ge 128 ] && FAIL "trunc: run $i (${c:-no cache}) died of signal $((rc - 128))"
    [ $rc = 0 ] && ok=$((ok + 1))
done
stop_writer "$T/stop"
rm -rf "$T"
echo "item 7 (truncated underneath): $ok of 40 runs rendered, $(($(now_ms) - t0)) ms"

[ $fail -eq 0 ] && echo "cache: ok"
exit $fail
