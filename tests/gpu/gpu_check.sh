#!/bin/sh
# gpu_check.sh RAYTRACE IMGDIFF SCENE_DIR MODE SCENE...
#
# The CUDA backend against the serial reference backend, per scene:
#   image: PSNR >= 45 dB and at most 0.2% of pixels with a channel off by more
#          than 2/255 (imgdiff --min-psnr 45 --max-over2 0.2);
#   rays:  primary, shadow and secondary ray counts within 0.1% of serial.
# MODE picks the renders compared with serial (bvh), each ACCEL:BLOCK[:TRAV]
# with TRAV the GPU traversal (RAYBENCH_CUDA_TRAVERSAL; default wide), or
# `pairs`: the wide traversal with two lanes per pixel (RAYBENCH_CUDA_PAIRS=1),
# `cover` or `center`: the wide traversal with the tiles in that order
# (RAYBENCH_CUDA_ORDER), `pairs-center`: both, `sorted`: the wide traversal
# with shadow rays' children sorted (RAYBENCH_CUDA_ANYHIT=sorted; the
# record must say anyhit=sorted), `default`: no variable set (the record
# must say order=center for the tree, tiles for brute force, and
# anyhit=slot, or sorted with pixel pairs), or `large`: no variable and no --block (BLOCK is `-`) at
# 2560x1920, against serial at that size (the record must say large=1
# sched=persistent anyhit=slot);
# other renders set PAIRS=0 and the row-major tile order:
#   full   cuda+bvh in blocks 8x8 16x8 16x16 32x8 32x32 13x7 128x1 (odd and
#          1024-thread shapes included), pixel pairs in 8x8 and 32x4, the
#          cover order in 8x8, the centre order in 16x8 (at the defaults),
#          sorted shadow rays in 16x8,
#          13x7 and with pairs in 32x4, the large-image defaults, the binary
#          tree's traversals (ldg, shared) in 16x16, and cuda+none in 16x16
#          and 32x32;
#   bvh    cuda+bvh in 16x16 and 32x32 only (scenes whose brute force is slow);
#   nogpu  expects `--backend cuda` to fail with one line and exit 1 (the
#          CI machine has no GPU); skipped where a GPU is present;
#   badenv expects each measurement variable given a value it refuses
#          (an unknown word, an integer out of range or with trailing
#          characters: checked before the GPU is touched, so this part runs
#          without a GPU and the message must name the variable; with a GPU
#          also pairs in a block of an odd width, a timeline file that
#          cannot be written, and slot-order shadow rays with pixel pairs)
#          to fail with one line and exit 1, writing no image.
# SCENE is Group/name under SCENE_DIR (the course scenes, e.g.
# InterestingScenes/dragon). Exit 77 (Meson's "skipped") without a GPU
# (but nogpu and badenv), or when the course scenes are not beside the
# checkout. GPU_CHECK_CSV=FILE
# appends one row per comparison; GPU_CHECK_BLOCKS overrides the bvh blocks.
set -u
. "$(dirname "$0")/../course.sh"
RT=$1; DIFF=$2; DIR=$(course_path "$3"); MODE=$4; shift 4

have_gpu() {
    command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q '^GPU '
}

if [ "$MODE" = nogpu ]; then
    if have_gpu; then echo "SKIP: a GPU is present"; exit 77; fi
    [ -d "$DIR" ] || { echo "SKIP: no course scenes at $DIR"; exit 77; }
    msg=$("$RT" -q --backend cuda -o /tmp/gpu_check_nogpu.$$.ppm "$DIR/$1.txt" 2>&1 >/dev/null)
    rc=$?
    lines=$(printf '%s\n' "$msg" | wc -l)
    echo "exit $rc, $lines line(s): $msg"
    [ -e /tmp/gpu_check_nogpu.$$.ppm ] && { echo "FAIL: an image was written"; rm -f /tmp/gpu_check_nogpu.$$.ppm; exit 1; }
    [ "$rc" -eq 1 ] && [ "$lines" -eq 1 ] && [ -n "$msg" ] || { echo "FAIL: expected one line and exit 1"; exit 1; }
    exit 0
fi

if [ "$MODE" = badenv ]; then
    [ -d "$DIR" ] || { echo "SKIP: no course scenes at $DIR"; exit 77; }
    fail=0
    out=/tmp/gpu_check_badenv.$$.ppm
    # Values no variable accepts are refused before the GPU is touched, so
    # these run without one too. Every message must name its variable.
    cases="RAYBENCH_CUDA_SCHED=gird|8x8 RAYBENCH_CUDA_TRAVERSAL=binary|8x8 RAYBENCH_CUDA_ORDER=random|8x8
           RAYBENCH_CUDA_PAIRS=2|8x8 RAYBENCH_CUDA_SPEC=0|8x8 RAYBENCH_CUDA_RUNS=0|8x8 RAYBENCH_CUDA_RUNS=65|8x8
           RAYBENCH_CUDA_RUNS=5x|8x8 RAYBENCH_CUDA_WARMUP_MS=-1|8x8 RAYBENCH_CUDA_MINB=5|8x8
           RAYBENCH_CUDA_CARVEOUT=101|8x8 RAYBENCH_CUDA_ANYHIT=sort|8x8"
    # With a GPU, also what depends on the block or the file system.
    have_gpu && cases="$cases RAYBENCH_CUDA_PAIRS=1|7x8 RAYBENCH_CUDA_TIMELINE=/nonexistent-dir/t.csv|8x8
                       RAYBENCH_CUDA_ANYHIT=slot|8x8:RAYBENCH_CUDA_PAIRS=1"
    for case in $cases; do
        kv=${case%|*}; blk=${case#*|}
        # BLOCK:VAR=VALUE: a second variable that the first cannot go with
        kv2=RAYBENCH_CUDA_UNUSED=; case $blk in *:*) kv2=${blk#*:}; blk=${blk%%:*} ;; esac
        rm -f "$out"
        msg=$(env "$kv" "$kv2" "$RT" -q --backend cuda --block "$blk" -o "$out" "$DIR/$1.txt" 2>&1 >/dev/null)
        rc=$?
        lines=$(printf '%s\n' "$msg" | wc -l)
        with=""; [ "$kv2" = RAYBENCH_CUDA_UNUSED= ] || with=" $kv2"
        echo "$kv$with --block $blk: exit $rc, $lines line(s): $msg"
        if [ -e "$out" ]; then echo "FAIL: $kv: an image was written"; rm -f "$out"; fail=1; fi
        [ "$rc" -eq 1 ] && [ "$lines" -eq 1 ] && [ -n "$msg" ] || { echo "FAIL: $kv: expected one line and exit 1"; fail=1; }
        case $msg in *"${kv%%=*}"*) ;; *) echo "FAIL: $kv: the message does not name ${kv%%=*}"; fail=1 ;; esac
    done
    exit $fail
fi

if ! have_gpu; then echo "SKIP: no GPU (nvidia-smi finds none)"; exit 77; fi
[ -d "$DIR" ] || { echo "SKIP: no course scenes at $DIR"; exit 77; }

TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT
fail=0
CSV=${GPU_CHECK_CSV:-}
[ -n "$CSV" ] && [ ! -s "$CSV" ] && echo "scene,accel,block,psnr,over2_pct,maxdiff,rays_serial,rays_cuda,ray_diff_pct,node_visits_serial,node_visits_cuda,result,traversal" >"$CSV"

# key=value from a record line
field() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }

# the CUDA record says KEY=VALUE, or a FAIL line (the caller goes on to the
# next render)
says() {
    case $rec_c in *" $1=$2 "*) return 0 ;; esac
    echo "FAIL $name $accel $blk $kind: the record does not say $1=$2"
    fail=1
    return 1
}

# |a-b|/a*100 <= 0.1 for each ray counter
rays_ok() {
    awk -v a="$1" -v b="$2" 'BEGIN { d = a > b ? a - b : b - a; if (a == 0) exit (b != 0); exit (d * 1000 > a) }'
}

for sc in "$@"; do
    name=$(basename "$sc")
    ref="$TMP/$name-serial.ppm"
    rec_s=$("$RT" -q --backend serial --accel bvh -o "$ref" "$DIR/$sc.txt") || { echo "FAIL $name: serial render"; fail=1; continue; }
    rec_l="" # serial at 2560x1920, made for the first `large` render
    case $MODE in
        full) runs="${GPU_CHECK_BLOCKS:-bvh:8x8 bvh:16x8 bvh:16x16 bvh:32x8 bvh:32x32 bvh:13x7 bvh:128x1 bvh:8x8:pairs bvh:32x4:pairs bvh:8x8:cover bvh:16x8:sorted bvh:16x8:default bvh:-:large bvh:13x7:center bvh:32x4:pairs-center bvh:16x16:ldg bvh:16x16:shared} none:16x16 none:32x32" ;;
        *) runs="${GPU_CHECK_BLOCKS:-bvh:16x16 bvh:32x32}" ;;
    esac
    for r in $runs; do
        accel=${r%%:*}; blk=${r#*:}; trav=wide
        case $blk in *:*) trav=${blk#*:}; blk=${blk%%:*} ;; esac
        pairs=0; order=tiles; kind=$trav; size=""; bref=$ref; srec=$rec_s; blkopt="--block $blk"; anyhit=
        case $kind in
            sorted) anyhit=sorted; trav=wide ;;
            pairs) pairs=1; trav=wide ;;
            cover | center) order=$kind; trav=wide ;;
            pairs-center) pairs=1; order=center; trav=wide ;;
            default) pairs=; order=; trav=wide ;;
            large)
                pairs=; order=; trav=wide; size="-r 2560x1920"; blkopt=""
                bref="$TMP/$name-serial-large.ppm"
                if [ -z "$rec_l" ]; then
                    # shellcheck disable=SC2086
                    rec_l=$("$RT" -q --backend serial --accel bvh $size -o "$bref" "$DIR/$sc.txt") ||
                        { echo "FAIL $name: serial render at 2560x1920"; fail=1; continue; }
                fi
                srec=$rec_l ;;
        esac
        img="$TMP/$name-cuda-$accel-$blk-$kind.ppm"
        # an empty value is the default (as unset); pairs then stay auto
        # shellcheck disable=SC2086
        rec_c=$(RAYBENCH_CUDA_TRAVERSAL=$trav RAYBENCH_CUDA_ANYHIT=$anyhit RAYBENCH_CUDA_PAIRS=$pairs RAYBENCH_CUDA_ORDER=$order RAYBENCH_CUDA_RUNS=1 "$RT" -q --verify --backend cuda --accel "$accel" $blkopt $size -o "$img" "$DIR/$sc.txt")
        if [ $? -ne 0 ]; then echo "FAIL $name $accel $blk $trav pairs=$pairs: cuda render"; fail=1; continue; fi
        # brute force has no tree: its record says ldg
        want=$trav; [ "$accel" = none ] && want=ldg
        says traversal "$want" || continue
        if [ -n "$pairs" ]; then
            says pairs "$pairs" || continue
        fi
        if [ "$kind" = sorted ]; then
            says anyhit sorted || continue
        fi
        # the default order is center on the grid (the tree's schedule); at
        # 2560x1920 the defaults are the large image's: persistent, row-major
        [ "$kind" = default ] && order=center
        if [ "$kind" = default ] || [ "$kind" = large ]; then
            lw=0; [ "$kind" = large ] && lw=1
            says large "$lw" || continue
            # slot order, but for pixel pairs (small images) and the binary
            # traversals (brute force), which sort
            ah=slot; case $rec_c in *" pairs=1 "* | *" traversal=ldg "* | *" traversal=shared "*) ah=sorted ;; esac
            says anyhit "$ah" || continue
            if [ "$kind" = large ]; then
                order=tiles
                says sched persistent || continue
            fi
        fi
        # brute force has no tree to project and runs the persistent schedule:
        # its order stays tiles
        if [ "$order" != tiles ] && [ "$accel" = bvh ]; then
            says order "$order" || continue
        fi
        case $kind in pairs | cover | center | pairs-center | sorted | default | large) trav=$kind; want=$kind ;; esac
        d=$("$DIFF" "$bref" "$img" --min-psnr 45 --max-over2 0.2); drc=$?
        ok=ok; [ $drc -eq 0 ] || ok=image
        for k in primary_rays shadow_rays secondary_rays; do
            rays_ok "$(field "$srec" $k)" "$(field "$rec_c" $k)" || ok="$ok+$k"
        done
        [ "$ok" = ok ] || { ok=FAIL:$ok; fail=1; }
        rs=$(field "$srec" rays); rcu=$(field "$rec_c" rays)
        pct=$(awk -v a="$rs" -v b="$rcu" 'BEGIN { printf "%.4f", a ? (b - a) * 100 / a : 0 }')
        echo "$name $accel $blk $trav: $d rays $rs/$rcu ($pct%) $ok"
        [ -n "$CSV" ] && echo "$name,$accel,$blk,$(field "$d" psnr),$(field "$d" over2 | tr -d %),$(field "$d" maxdiff),$rs,$rcu,$pct,$(field "$srec" node_visits),$(field "$rec_c" node_visits),$ok,$want" >>"$CSV"
    done
done
exit $fail
