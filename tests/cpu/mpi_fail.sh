#!/bin/sh
# mpi_fail.sh RAYTRACE MPIRUN GOOD_SCENE
# Failures under mpirun -np 3: a bad scene, an unwritable output, and an
# error on rank 2 only (injected with RT_MPI_TEST_FAIL_RANK, which only the
# test build raytrace-testhooks reads) must each end
# every rank within a few seconds, with exit status 1, no record, and exactly
# one line on stderr (from rank 0; mpirun --quiet keeps Open MPI's own
# "process returned a non-zero exit code" banner out of the count). Ranks
# that read different scene bytes fail the same way; with --cache the ranks
# render the serial image. Also the scene's copies and whether ranks share
# cores (the record's scene_copies and core_sharing_ranks).
set -u
rt=$1 mpirun=$2 good=$3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# Open MPI's session folder under a base of this test's own (concurrent
# mpiruns sharing /tmp/ompi.HOST.UID race on its removal)
mkdir "$tmp/ompi" && export TMPDIR="$tmp/ompi"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_mpi_yield_when_idle=1
printf 'camera_pos: 0 0 0\nsphere: 1 2\n' > "$tmp/bad.txt"
fails=0
# What a good render takes here on three ranks (MPI's start and finalize
# included), and what mpirun takes to end three processes that exit 1 (its
# abort path: 1 s on the 2-core VM, 2.5 times a good render): the bound
# below is the longer three times plus 6 s, so it catches ranks that wait
# for each other, not an MPI that is slow to start and end on this machine.
# Where the host name does not resolve, as in a bare chroot, a good render
# took 5.4-10.5 s, the abort path up to 10.1 s and a rank's failure
# 10.4-17.4 s; a hang runs into the 60 s timeout.
run_ms() { # ARGS...: milliseconds mpirun takes to run ARGS on three ranks
    local start
    start=$(date +%s%N)
    timeout 60 "$mpirun" --quiet --oversubscribe -np 3 "$@" > /dev/null 2>&1
    echo $(( ($(date +%s%N) - start) / 1000000 ))
}
base_ms=$(run_ms "$rt" -q --backend mpi -r 8x6 -o "$tmp/base.ppm" "$good")
abort_ms=$(run_ms false)
slow_ms=$(( abort_ms > base_ms ? abort_ms : base_ms ))
bound_ms=$((3 * slow_ms + 6000))
echo "a good render on three ranks: $base_ms ms; three processes exiting 1: $abort_ms ms; a failure must end within $bound_ms ms"
expect_one_error() { # NAME PATTERN ARGS...
    name=$1 pat=$2; shift 2
    start=$(date +%s%N)
    timeout 60 "$mpirun" --quiet --oversubscribe -np 3 "$@" > "$tmp/out" 2> "$tmp/err"
    rc=$? ms=$(( ($(date +%s%N) - start) / 1000000 ))
    # Open MPI 4.1's launcher sometimes adds libevent noise when ranks abort
    # ("[warn] Epoll MOD(1) on fd N failed ..."), from mpirun itself, not from
    # raytrace: those lines are not counted.
    lines=$(grep -v -c '^\[warn\] Epoll ' "$tmp/err")
    echo "$name: exit $rc after $ms ms, stderr:"; sed 's/^/  | /' "$tmp/err"
    if [ $rc != 1 ]; then echo "FAIL $name: exit status $rc, expected 1"; fails=$((fails + 1)); fi
    # the ranks end at once; mpirun itself needs up to ~2.3 s after an exit(1)
    # on top of its own start: the bound catches a hang, not mpirun's pace
    if [ $ms -gt $bound_ms ]; then echo "FAIL $name: took $ms ms"; fails=$((fails + 1)); fi
    if [ "$lines" != 1 ]; then echo "FAIL $name: $lines stderr lines, expected 1"; fails=$((fails + 1)); fi
    if ! grep -q -- "$pat" "$tmp/err"; then echo "FAIL $name: message lacks '$pat'"; fails=$((fails + 1)); fi
    if grep -q '^record:' "$tmp/out"; then echo "FAIL $name: printed a record"; fails=$((fails + 1)); fi
}
for how in every bcast; do
    expect_one_error "bad scene ($how)" 'bad.txt:2:' "$rt" -q --backend mpi --mpi-scene $how -o "$tmp/x.ppm" "$tmp/bad.txt"
done
expect_one_error "unwritable output" 'cannot write' "$rt" -q --backend mpi -o /nonexistent-dir/x.ppm "$good"
expect_one_error "bad option" "option --tile" "$rt" -q --backend mpi --tile 0x1 "$good"
expect_one_error "rank 2 fails" 'rank 2:' env RT_MPI_TEST_FAIL_RANK=2 "$rt" -q --backend mpi -r 64x48 -o "$tmp/x.ppm" "$good"

# Ranks that read different bytes never render one image together: rank 0
# reads a.txt, the others b.txt (a.txt plus a sphere) - with --mpi-scene
# every, and with --cache where each rank loads its own file's entry (both
# stored by serial runs). Exit 1, one line naming the first rank that
# differs, no image. (Old code: no digest was compared, so the ranks
# rendered their rows of two different scenes and exit 0.)
cp "$good" "$tmp/a.txt"
{ cat "$good"; printf 'sphere: 0 1 -3 1\n'; } > "$tmp/b.txt"
# (mpirun starts this per rank: rank 0 runs CMD A, the others CMD B)
per_rank='if [ "$OMPI_COMM_WORLD_RANK" = 0 ]; then s=$1; else s=$2; fi; shift 2; exec "$@" "$s"'
for how in every bcast; do
    c="$tmp/c-$how"
    for f in a b; do
        "$rt" -q -r 32x24 --cache "$c" -o "$tmp/s.ppm" "$tmp/$f.txt" > /dev/null || { echo "FAIL: serial --cache run on $f.txt"; fails=$((fails + 1)); }
    done
    [ "$(ls "$c"/*.rbc 2> /dev/null | wc -l)" = 2 ] || { echo "FAIL: two entries expected in $c: $(ls "$c")"; fails=$((fails + 1)); }
    for cache in "" "--cache $c"; do
        [ $how = bcast ] && [ -z "$cache" ] && continue # (bcast alone: every rank gets rank 0's bytes)
        rm -f "$tmp/x.ppm"
        expect_one_error "ranks read different scenes ($how${cache:+, cache})" "rank 1: the scene this rank read differs from rank 0's" \
            sh -c "$per_rank" sh "$tmp/a.txt" "$tmp/b.txt" "$rt" -q --backend mpi --mpi-scene $how $cache -r 32x24 -o "$tmp/x.ppm"
        if [ -e "$tmp/x.ppm" ]; then echo "FAIL: ranks read different scenes ($how${cache:+, cache}): an image was written"; fails=$((fails + 1)); fi
    done
done

# The same scene on every rank with --cache: built, then loaded, and the
# image of a serial run.
key() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
serial=$("$rt" -q -r 64x48 -o "$tmp/s.ppm" "$good") || { echo "FAIL: serial run"; fails=$((fails + 1)); }
for how in every bcast; do
    for want in built loaded; do
        rec=$(timeout 60 "$mpirun" --quiet --oversubscribe -np 2 "$rt" -q --backend mpi --mpi-scene $how --cache "$tmp/cs-$how" \
              -r 64x48 -o "$tmp/m.ppm" "$good" 2> "$tmp/err")
        rc=$?
        echo "mpi --cache ($how): exit $rc, cache=$(key "$rec" cache) image_fnv1a=$(key "$rec" image_fnv1a)"
        if [ $rc != 0 ]; then echo "FAIL: mpi --cache ($how, $want): exit $rc: $(cat "$tmp/err")"; fails=$((fails + 1)); continue; fi
        [ "$(key "$rec" cache)" = $want ] || { echo "FAIL: mpi --cache ($how): cache=$(key "$rec" cache), want $want"; fails=$((fails + 1)); }
        [ -n "$(key "$rec" image_fnv1a)" ] && [ "$(key "$rec" image_fnv1a)" = "$(key "$serial" image_fnv1a)" ] ||
            { echo "FAIL: mpi --cache ($how, $want): image $(key "$rec" image_fnv1a), serial $(key "$serial" image_fnv1a)"; fails=$((fails + 1)); }
    done
done

# The cross-node path on one node (RT_MPI_TEST_SEPARATE: claims by
# MPI_Fetch_and_op, tiles by MPI_Put) and the shared one (CPU atomics,
# pixels written in place): the serial image, claims on three ranks, and
# time in puts (ranks but 0, which writes its window) only on the first.
for sep in 1 0; do
    rec=$(RT_MPI_TEST_SEPARATE=$sep timeout 60 "$mpirun" --quiet --oversubscribe -np 3 "$rt" -q --backend mpi -r 64x48 \
          -o "$tmp/m.ppm" "$good" 2> "$tmp/err") || { echo "FAIL: separate=$sep: $(cat "$tmp/err")"; fails=$((fails + 1)); }
    echo "separate=$sep: rank_claims=$(key "$rec" rank_claims) rank_put_ms=$(key "$rec" rank_put_ms) rank_end_ms=$(key "$rec" rank_end_ms)"
    [ "$(key "$rec" image_fnv1a)" = "$(key "$serial" image_fnv1a)" ] || { echo "FAIL: separate=$sep: not the serial image"; fails=$((fails + 1)); }
    key "$rec" rank_claims | grep -Eq '^[0-9]+/[0-9]+/[0-9]+$' && [ "$(key "$rec" rank_claims | tr '/' '\n' | awk '{ s += $1 } END { print s + 0 }')" -gt 0 ] ||
        { echo "FAIL: separate=$sep: rank_claims"; fails=$((fails + 1)); }
    puts=$(key "$rec" rank_put_ms | tr '/' '\n' | awk '$1 > 0' | wc -l)
    if [ $sep = 1 ] && [ "$puts" = 0 ]; then echo "FAIL: separate: no time in puts"; fails=$((fails + 1)); fi
    if [ $sep = 0 ] && [ "$puts" != 0 ]; then echo "FAIL: shared: time in puts"; fails=$((fails + 1)); fi
    # (shared: each rank's frame starts at its team's first thread; the wait for the team is apart)
    # (across nodes it is not measured: zero)
    fork=$(key "$rec" rank_fork_ms)
    if { [ $sep = 0 ] && ! echo "$fork" | grep -Eq '^[0-9]+\.[0-9]{3}/[0-9]+\.[0-9]{3}/[0-9]+\.[0-9]{3}$'; } ||
       { [ $sep = 1 ] && [ "$fork" != 0.000/0.000/0.000 ]; }; then
        echo "FAIL: separate=$sep: rank_fork_ms '$fork'"; fails=$((fails + 1))
    fi
done

# One copy of the scene for the three ranks (unbound: one per node), by
# both ways the scene reaches them. Each rank keeps its own copy, and the
# image stays the serial one, where a rank's view differs in one count
# (RT_MPI_TEST_VIEW_DIFFERS), where rank 0 cannot make the shared copy and
# where rank 2 cannot map it (RT_MPI_TEST_SHM_FAIL).
for case in bcast every differs create map; do
    how=bcast want=3 differs= shm=
    case $case in
    bcast|every) how=$case want=1 ;;
    differs) differs=1 ;;
    create) shm=0 ;;
    map) shm=2 ;;
    esac
    rec=$(RT_MPI_TEST_VIEW_DIFFERS=$differs RT_MPI_TEST_SHM_FAIL=$shm timeout 60 "$mpirun" --quiet --oversubscribe \
          --bind-to none -np 3 "$rt" -q --backend mpi --mpi-scene $how -r 64x48 -o "$tmp/m.ppm" "$good" 2> "$tmp/err") ||
        { echo "FAIL: scene copies ($case): $(cat "$tmp/err")"; fails=$((fails + 1)); }
    echo "scene copies ($case): scene_copies=$(key "$rec" scene_copies)"
    [ "$(key "$rec" scene_copies)" = $want ] || { echo "FAIL: scene copies ($case): want $want"; fails=$((fails + 1)); }
    [ "$(key "$rec" image_fnv1a)" = "$(key "$serial" image_fnv1a)" ] ||
        { echo "FAIL: scene copies ($case): not the serial image"; fails=$((fails + 1)); }
done

# A rank yields its core while it waits at the frame's start only where
# another rank may run there: none of two ranks on cores of their own, all
# three unbound on two cores. The image is the serial one either way.
for case in "0 --bind-to core -np 2" "3 --oversubscribe --bind-to none -np 3"; do
    set -- $case
    want=$1
    shift
    if [ "$want" = 0 ] && [ "$(nproc)" -lt 2 ]; then
        echo "core sharing ($*): not run: one CPU here, two ranks cannot have cores of their own"
        continue
    fi
    rec=$(timeout 60 "$mpirun" --quiet "$@" "$rt" -q --backend mpi -r 64x48 -o "$tmp/m.ppm" "$good" 2> "$tmp/err") ||
        { echo "FAIL: core sharing ($*): $(cat "$tmp/err")"; fails=$((fails + 1)); }
    echo "core sharing ($*): core_sharing_ranks=$(key "$rec" core_sharing_ranks) rank_cores=$(key "$rec" rank_cores)"
    [ "$(key "$rec" core_sharing_ranks)" = "$want" ] || { echo "FAIL: core sharing ($*): want $want"; fails=$((fails + 1)); }
    [ "$(key "$rec" image_fnv1a)" = "$(key "$serial" image_fnv1a)" ] ||
        { echo "FAIL: core sharing ($*): not the serial image"; fails=$((fails + 1)); }
done

# On one node every rank maps rank 0's image before the frame: the pages it
# writes fault there, not inside the frame (rank_faults: the frame's own; a
# rank writing half of a 512x384 image in the frame took hundreds)
rec=$(timeout 60 "$mpirun" --quiet --oversubscribe -np 2 "$rt" -q --backend mpi -r 512x384 -o "$tmp/m.ppm" "$good" \
      2> "$tmp/err") || { echo "FAIL: two ranks' faults: $(cat "$tmp/err")"; fails=$((fails + 1)); }
echo "two ranks, 512x384: rank_faults=$(key "$rec" rank_faults)"
[ "$(key "$rec" rank_faults | cut -d/ -f2)" -lt 50 ] 2> /dev/null ||
    { echo "FAIL: rank 1 faulted on rank 0's image inside the frame"; fails=$((fails + 1)); }

# A rank that claims no tile (3 ranks, one 8x8 tile) still names its core:
# the harness's pinning check must not see a rank that ran nowhere.
rec=$(timeout 60 "$mpirun" --quiet --oversubscribe -np 3 "$rt" -q --backend mpi -r 8x8 -o "$tmp/m.ppm" "$good" \
      2> "$tmp/err") || { echo "FAIL: one tile, three ranks: $(cat "$tmp/err")"; fails=$((fails + 1)); }
echo "one tile, three ranks: rank_claims=$(key "$rec" rank_claims) rank_cores=$(key "$rec" rank_cores)"
key "$rec" rank_cores | grep -Eq '^[0-9,]+/[0-9,]+/[0-9,]+$' ||
    { echo "FAIL: one tile, three ranks: a rank without a core: rank_cores=$(key "$rec" rank_cores)"; fails=$((fails + 1)); }
[ "$fails" = 0 ]
