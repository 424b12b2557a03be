#!/bin/sh
# gpu_check.sh RAYTRACE IMGDIFF SCENE_DIR MODE SCENE...
#
# The CUDA backend against the serial reference backend, per scene:
#   image: PSNR >= 45 dB and at most 0.2% of pixels with a channel off by more
#          than 2/255 (imgdiff --min-psnr 45 --max-over2 0.2);
#   rays:  primary, shadow and secondary ray counts within 0.1% of serial.
# MODE picks the renders compared with serial, each ACCEL:BLOCK[:KIND]:
#   full   cuda+bvh in blocks 8x8 16x8 16x16 32x8 32x32 13x7 128x1 (odd and
#          1024-thread shapes included; pixel pairs wherever the automatic
#          choice takes them, and 13x7 never), `default`: no --block (the
#          record must say sched=grid order=center large=0, and anyhit=slot,
#          or sorted with pixel pairs), `large`: no --block at 2560x1920
#          against serial at that size (large=1 sched=persistent order=tiles
#          anyhit=slot pairs=0), `runs`: 16x8 with --runs 3 --warmup 1 (the
#          record must count them), `gpubuild`: no --block, --builder gpu
#          (the record must say builder=gpu, and the image hash and ray
#          counts equal `default`'s, whose tree the CPU built: hits do not
#          depend on the tree), and cuda+none in 16x16 and 32x32 (the
#          binary traversal, persistent schedule);
#   bvh    cuda+bvh in 16x16 and 32x32 only (scenes whose brute force is slow);
#   nogpu  expects `--backend cuda` to fail with one line and exit 1 (the
#          CI machine has no GPU); skipped where a GPU is present.
# SCENE is Group/name under SCENE_DIR (the course scenes, e.g.
# InterestingScenes/dragon). Exit 77 (Meson's "skipped") without a GPU
# (but nogpu), or when the course scenes are not beside the
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
    rec_default="" # the `default` render, for `gpubuild`
    case $MODE in
        full) runs="${GPU_CHECK_BLOCKS:-bvh:8x8 bvh:16x8 bvh:16x16 bvh:32x8 bvh:32x32 bvh:13x7 bvh:128x1 bvh:16x8:runs bvh:-:default bvh:-:gpubuild bvh:-:large} none:16x16 none:32x32" ;;
        *) runs="${GPU_CHECK_BLOCKS:-bvh:16x16 bvh:32x32}" ;;
    esac
    for r in $runs; do
        accel=${r%%:*}; blk=${r#*:}; kind=block
        case $blk in *:*) kind=${blk#*:}; blk=${blk%%:*} ;; esac
        size=""; bref=$ref; srec=$rec_s; opts="--block $blk --runs 1 --warmup 0"
        case $kind in
            runs) opts="--block $blk --runs 3 --warmup 1" ;;
            default) opts="--builder cpu" ;;
            gpubuild) opts="--builder gpu" ;;
            large)
                size="-r 2560x1920"; opts=""
                bref="$TMP/$name-serial-large.ppm"
                if [ -z "$rec_l" ]; then
                    # shellcheck disable=SC2086
                    rec_l=$("$RT" -q --backend serial --accel bvh $size -o "$bref" "$DIR/$sc.txt") ||
                        { echo "FAIL $name: serial render at 2560x1920"; fail=1; continue; }
                fi
                srec=$rec_l ;;
        esac
        img="$TMP/$name-cuda-$accel-$blk-$kind.ppm"
        # shellcheck disable=SC2086
        rec_c=$("$RT" -q --verify --backend cuda --accel "$accel" $opts $size -o "$img" "$DIR/$sc.txt")
        if [ $? -ne 0 ]; then echo "FAIL $name $accel $blk $kind: cuda render"; fail=1; continue; fi
        if [ "$accel" = none ]; then
            says traversal binary && says sched persistent && says pairs 0 || continue
        else
            says traversal wide || continue
        fi
        # pixel pairs need an even block width and whole warps
        [ "$blk" = 13x7 ] && { says pairs 0 || continue; }
        case $kind in
            runs) says runs 3 && says warmups 1 && says frames 3 && says warmup_frames 1 || continue ;;
            default)
                ah=slot; case $rec_c in *" pairs=1 "*) ah=sorted ;; esac
                says large 0 && says sched grid && says order center && says anyhit "$ah" || continue
                rec_default=$rec_c ;;
            gpubuild)
                says builder gpu || continue
                for k in image_fnv1a primary_rays shadow_rays secondary_rays; do
                    [ "$(field "$rec_c" $k)" = "$(field "$rec_default" $k)" ] ||
                        { echo "FAIL $name gpubuild: $k $(field "$rec_c" $k), the CPU's tree $(field "$rec_default" $k)"; fail=1; }
                done ;;
            large) says large 1 && says sched persistent && says order tiles && says anyhit slot && says pairs 0 || continue ;;
        esac
        trav=$kind; want=$kind
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
