#!/bin/sh
# cpu_equiv.sh RAYTRACE MPIRUN SCENE RESOLUTION ACCELS
# The CPU backends against the serial oracle on one scene: OpenMP (1, 2, 3
# threads; 7x5 and 16x16 tiles; the pixels schedule; 12 threads of 4x4 tiles) and MPI (no mpirun, and
# mpirun -np 1, 2, 3 with rows and dynamic; 2 ranks x 2 threads; 1 rank x 12 threads; every rank
# parsing the scene instead of the broadcast default) must give the serial image_fnv1a and every work
# counter exactly. Every run uses --verify (the image is poisoned first and
# any unwritten pixel fails). RESOLUTION should have a height that 2 and 3 do
# not divide and a width that 16 and 7 do not divide, so that row blocks and
# tiles are uneven. ACCELS: "bvh" or "bvh none". MPIRUN may be "none".
# SCENE may be course:PATH (tests/course.sh); exits 77 (skipped) when such a
# course scene is missing.
set -u
. "$(dirname "$0")/../course.sh"
rt=$1 mpirun=$2 scene=$(course_path "$3") res=$4 accels=$5
[ -f "$scene" ] || { echo "skip: $scene not found (the course scenes: set RAYBENCH_COURSE_DIR)"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# Open MPI's session folder under a base of this test's own: two mpiruns of
# concurrent tests sharing /tmp/ompi.HOST.UID race on its removal (one
# removes it while the other creates its pid.N folder in it).
mkdir "$tmp/ompi" && export TMPDIR="$tmp/ompi"
# mpirun as root (containers, CI) needs both; waiting ranks yield the core
# because the test oversubscribes 2 cores with 3 ranks.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_mpi_yield_when_idle=1
unset OMP_NUM_THREADS

# image hash and every counter: the part of a record that must not change
sig() {
    tr ' ' '\n' < "$1" | grep -E '^(width|height|image_fnv1a|rays|primary_rays|shadow_rays|secondary_rays|node_visits|prim_tests)=' | tr '\n' ' '
}
fails=0 n=0
check() { # NAME CMD...
    name=$1; shift
    n=$((n + 1))
    if ! "$@" > "$tmp/run.rec" 2> "$tmp/run.err"; then
        echo "FAIL $name: exit status $? ($(head -c 300 "$tmp/run.err"))"
        fails=$((fails + 1)); return
    fi
    if [ "$(grep -c '^record: ' "$tmp/run.rec")" != 1 ]; then
        echo "FAIL $name: expected exactly one record line"; cat "$tmp/run.rec"
        fails=$((fails + 1)); return
    fi
    got=$(sig "$tmp/run.rec")
    if [ "$got" != "$want" ]; then
        echo "FAIL $name:"; echo "  serial: $want"; echo "  got:    $got"
        fails=$((fails + 1)); return
    fi
}

for accel in $accels; do
    common="--quiet --verify --accel $accel -r $res -o $tmp/img.ppm"
    "$rt" $common --backend serial "$scene" > "$tmp/serial.rec" || { echo "FAIL: serial run"; exit 1; }
    want=$(sig "$tmp/serial.rec")
    echo "$accel serial: $want"
    case "$want" in *image_fnv1a=*) ;; *) echo "FAIL: no image_fnv1a in the serial record"; exit 1 ;; esac

    for t in 1 2 3; do
        for tile in 7x5 16x16; do
            check "openmp threads=$t tile=$tile $accel" "$rt" $common --backend openmp --threads $t --tile $tile "$scene"
        done
        check "openmp threads=$t pixels $accel" "$rt" $common --backend openmp --threads $t --schedule pixels "$scene"
    done
    # far more threads than cores: threads lose their core while they hold
    # tiles, and others back those up (cpu_tiles.h); one image either way
    check "openmp threads=12 tile=4x4 $accel" "$rt" $common --backend openmp --threads 12 --tile 4x4 "$scene"
    echo "$accel openmp 12 threads:$(tr ' ' '\n' < "$tmp/run.rec" | grep -E '^(backups|backups_won)=' | tr '\n' ' ')"
    check "openmp OMP_NUM_THREADS=3 $accel" env OMP_NUM_THREADS=3 "$rt" $common --backend openmp "$scene"
    grep -q ' threads=3 ' "$tmp/run.rec" || { echo "FAIL: OMP_NUM_THREADS=3 did not give 3 threads"; fails=$((fails + 1)); }

    check "mpi without mpirun $accel" "$rt" $common --backend mpi "$scene"
    [ "$mpirun" = none ] && continue
    for np in 1 2 3; do
        for s in rows dynamic; do
            check "mpi np=$np $s $accel" "$mpirun" --oversubscribe -np $np "$rt" $common --backend mpi --mpi-schedule $s "$scene"
        done
    done
    grep -q ' ranks=3 ' "$tmp/run.rec" || { echo "FAIL: -np 3 did not report ranks=3"; fails=$((fails + 1)); }
    for s in rows dynamic; do
        check "mpi hybrid 2x2 $s $accel" "$mpirun" --oversubscribe --bind-to none -np 2 "$rt" $common --backend mpi \
            --threads 2 --tile 7x5 --mpi-schedule $s "$scene"
    done
    # a lone rank's threads claim for themselves, and back each other up
    # when far more of them than cores lose theirs (mpi.c)
    check "mpi 1 rank x 12 threads tile=4x4 $accel" "$mpirun" --oversubscribe --bind-to none -np 1 "$rt" $common \
        --backend mpi --threads 12 --tile 4x4 "$scene"
    check "mpi np=3 every rank parses $accel" "$mpirun" --oversubscribe -np 3 "$rt" $common --backend mpi --mpi-scene every "$scene"
done
echo "$n runs, $fails failed"
[ "$fails" = 0 ]
