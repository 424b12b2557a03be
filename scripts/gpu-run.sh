#!/usr/bin/env bash
# gpu-run.sh [STEPS] - everything the CUDA backend needs measured, in ONE call
# on the GPU machine (the device budget is small; a fresh machine is bare):
#   build    meson setup build-dev -Dharness=false -Dgpu_arch=9.0 + ninja, and
#            nvcc -Xptxas -v for every kernel instantiation (ptxas.txt)
#   time     cuda+bvh and cuda+none on every course scene at the default block,
#            both schedules, every register cap (timings.csv)
#   blocks   the block-size sweep on the report's scenes (blocks.csv)
#   big      the dragon at 3840x2160 (in timings.csv)
#   check    tests/gpu/gpu_check.sh on every course scene (images and counters
#            against serial) and tests/gpu/gpu_sanitize.sh (check.csv, testlog.txt)
#   exp      (not default) traversal variant x nvcc math flags x register cap
#   trav     (not default) wide vs binary traversal x register cap x block
#   tune     (not default) tile order x L1 carveout x block; image sizes
#   ncu      (not default) Nsight Compute on one launch of dragon and arm-reach
#   ab       (not default) GPU_AB_OLD=DIR (an unpacked `git archive REV`, e.g.
#            under .devcarry/) built beside this tree; both at their defaults on
#            the report's scenes, three interleaved repeats (ab.csv)
#   vars     (not default) GPU_VARIANTS="V ..." on the report's scenes at their
#            size and at 128x96 (dragon and arm-reach; every scene with
#            GPU_VARS_SMALL=all), two repeats (vars.csv); a variant is
#            VAR=VALUE pairs joined by '+', BLOCK=WxH for --block, or base
#   timeline (not default) RAYBENCH_CUDA_TIMELINE on the dragon and arm-reach
#            at their size and at 128x96, for each of GPU_VARIANTS (default:
#            base and persistent 4x8): every warp's chunk, its multiprocessor,
#            start, end and traversal steps (timeline.csv)
# STEPS defaults to "build time blocks big check". Results go to $OUT (the
# device tool's folder; /tmp/gpu-out when unset), at most 8 files:
#   log.txt setup.txt ptxas.txt timings.csv blocks.csv check.csv testlog.txt ncu.txt
#   (ab.csv and vars.csv replace two of them when those steps run)
# GPU_BUILD names the build folder (default build-dev).
# Scenes: the course scenes, copied beforehand into .devcarry/scenes/course
# (git-ignored, passed to the device tool with carry: [".devcarry"]).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/gpu-out}
mkdir -p "$OUT"
STEPS=${*:-build time blocks big check}
SC=${GPU_SCENES:-$PWD/.devcarry/scenes/course}
B=${GPU_BUILD:-build-dev}
RT=$B/renderer/raytrace
LOG=$OUT/log.txt
exec > >(tee -a "$LOG") 2>&1
has() { case " $STEPS " in *" $1 "*) return 0 ;; esac; return 1; }
export PATH=/usr/local/cuda/bin:$PATH

echo "== $(date -u +%FT%TZ) gpu-run.sh: $STEPS"
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm,clocks.sm,power.limit --format=csv || true
nvcc --version | tail -2; meson --version; nproc

if has build; then
    echo "== build"
    if [ ! -f $B/build.ninja ]; then
        meson setup $B -Dharness=false -Dgpu_arch=9.0 -Dpng=auto -Dmpi=disabled >$OUT/setup.txt 2>&1 || { tail -40 $OUT/setup.txt; exit 1; }
    fi
    ninja -C $B 2>&1 | tail -5 || exit 1
    # Resource use of every kernel instantiation, from the same flags the build used.
    cmd=$(ninja -C $B -t commands renderer/raytrace | grep -m1 'cuda\.cu')
    cmd=$(printf '%s\n' "$cmd" | sed 's| -o [^ ]*| -Xptxas -v -o /tmp/ptxas_probe.o|')
    (cd $B && eval "$cmd") >$OUT/ptxas.txt 2>&1 || true
    grep -E "Compiling entry|stack frame|Used" $OUT/ptxas.txt | sed 's/_Z16rt_render_kernelILi\([0-9]*\)ELi\([0-9]\)E.*/<\1,\2>/'
fi
[ -x $RT ] || { echo "no $RT"; exit 1; }

# one render -> one CSV row (selected record keys, plus the variable columns)
KEYS="scene width height accel render_ms kernel_min_ms first_ms warmup_launches traversal order carveout rays primary_rays shadow_rays secondary_rays node_visits prim_tests mrays_per_s block pairs sched kernel_runs regs local_bytes bounds blocks_per_sm grid upload_ms download_ms wall_ms init_ms image_fnv1a gpu"
header() { echo "$KEYS" | tr ' ' ','; }
row() { # CSV RECORD
    local csv=$1 rec=$2 line="" k v
    for k in $KEYS; do
        v=$(printf '%s\n' "$rec" | tr ' ' '\n' | sed -n "s/^$k=//p" | head -1)
        line="$line,$v"
    done
    echo "${line#,}" >>"$csv"
}
scene_path() { ls "$SC"/*/"$1".txt; }
render() { # CSV SCENE ARGS... (env passes RAYBENCH_CUDA_*)
    local csv=$1 s=$2; shift 2
    local rec
    rec=$("${RT}" -q --backend cuda -o /tmp/gpu-run.ppm "$@" "$(scene_path "$s")") || { echo "FAILED: $s $*"; return 1; }
    row "$csv" "$rec"
    printf '%-16s %-34s %s\n' "$s" "$*" "$(printf '%s\n' "$rec" | grep -o 'render_ms=[^ ]*\|kernel_min_ms=[^ ]*\|mrays_per_s=[^ ]*\|regs=[^ ]*\|blocks_per_sm=[^ ]*' | tr '\n' ' ')"
}
# render, then the row gets LABEL as its first column: render_as LABEL CSV SCENE ARGS...
render_as() {
    local label=$1 csv=$2; shift
    render "$@" && sed -i "\$s/^/$label,/" "$csv"
}
# A variant (VAR=VALUE pairs joined by '+', BLOCK=WxH, or base) -> render
# with those variables exported, the row labelled with the variant:
# render_variant VARIANT CSV SCENE ARGS...
render_variant() {
    local v=$1 csv=$2 s=$3 e blk=""; shift 3
    e=$(printf '%s' "$v" | sed 's/^base$//; s/+/ /g')
    case " $e " in *" BLOCK="*) blk=$(printf '%s' "$e" | sed 's/.*BLOCK=\([0-9x]*\).*/\1/'); e=$(printf '%s' "$e" | sed 's/BLOCK=[0-9x]*//') ;; esac
    ( for kv in $e; do export "${kv?}"; done
      render_as "$v" "$csv" "$s" ${blk:+--block $blk} "$@" )
}
REPORT="dragon arm-reach bottle bottle-nolabel ShadowTest test_reasonable bear"

if has time; then
    echo "== time: kernel time, median of 21 launches after a warm-up"
    T=$OUT/timings.csv; header | sed 's/^/variant,/' >$T
    for s in $REPORT spheres2; do
        for sched in persistent grid; do
            for minb in 1 2 3 4; do
                RAYBENCH_CUDA_RUNS=21 RAYBENCH_CUDA_SCHED=$sched RAYBENCH_CUDA_MINB=$minb \
                    render_as "bvh-$sched-minb$minb" /tmp/t.csv $s --accel bvh
            done
        done
        RAYBENCH_CUDA_RUNS=9 render /tmp/t.csv $s --accel none && sed -i '$s/^/none-default,/' /tmp/t.csv
        RAYBENCH_CUDA_RUNS=9 RAYBENCH_CUDA_SCHED=grid render /tmp/t.csv $s --accel none && sed -i '$s/^/none-grid,/' /tmp/t.csv
    done
    cat /tmp/t.csv >>$T; rm -f /tmp/t.csv
fi

if has blocks; then
    echo "== blocks: the sweep (default schedule and register cap)"
    C=$OUT/blocks.csv; header | sed 's/^/sched,/' >$C
    for s in dragon arm-reach bottle test_reasonable ShadowTest; do
        for blk in 8x4 8x8 16x8 16x16 32x4 32x8 32x16 32x32 64x4 64x8 128x1 256x1 512x1 1024x1 4x8 13x7; do
            for sched in persistent grid; do
                RAYBENCH_CUDA_RUNS=15 RAYBENCH_CUDA_SCHED=$sched render_as "$sched" /tmp/b.csv $s --accel bvh --block $blk
            done
        done
    done
    cat /tmp/b.csv >>$C; rm -f /tmp/b.csv
fi

if has big; then
    echo "== big: the dragon at 3840x2160"
    T=$OUT/timings.csv; [ -s $T ] || header | sed 's/^/variant,/' >$T
    for minb in 1 2 3 4; do
        RAYBENCH_CUDA_RUNS=11 RAYBENCH_CUDA_MINB=$minb render_as "4k-bvh-minb$minb" /tmp/t.csv dragon --accel bvh -r 3840x2160
    done
    RAYBENCH_CUDA_RUNS=11 render /tmp/t.csv arm-reach --accel bvh -r 3840x2160 && sed -i '$s/^/4k-bvh,/' /tmp/t.csv
    RAYBENCH_CUDA_RUNS=1 render /tmp/t.csv dragon --accel none -r 3840x2160 && sed -i '$s/^/4k-none,/' /tmp/t.csv
    cat /tmp/t.csv >>$T; rm -f /tmp/t.csv
fi

if has exp; then
    # Variants measured against each other in one call: the GPU traversal
    # (RAYBENCH_CUDA_TRAVERSAL shared|ldg), nvcc math flags (NVCC_APPEND_FLAGS, a
    # build folder each), register caps. Rows go to timings.csv.
    echo "== exp: traversal x math flags x register cap"
    T=$OUT/timings.csv; [ -s $T ] || header | sed 's/^/variant,/' >$T
    for fl in default fastdiv; do
        bd=$B; [ $fl = default ] || bd=$B-$fl
        if [ $fl = fastdiv ] && [ ! -f $bd/build.ninja ]; then
            meson setup $bd -Dharness=false -Dgpu_arch=9.0 -Dpng=auto -Dmpi=disabled >/dev/null 2>&1
            NVCC_APPEND_FLAGS="-prec-div=false -prec-sqrt=false -ftz=true" ninja -C $bd >/dev/null 2>&1 || echo "build $fl failed"
        fi
        for s in dragon arm-reach bottle test_reasonable; do
            for trav in shared ldg; do
                for minb in 1 2 3; do
                    RT=$bd/renderer/raytrace RAYBENCH_CUDA_RUNS=21 RAYBENCH_CUDA_TRAVERSAL=$trav RAYBENCH_CUDA_MINB=$minb \
                        render_as "exp-$fl-$trav-minb$minb" /tmp/t.csv $s --accel bvh
                done
                RT=$bd/renderer/raytrace RAYBENCH_CUDA_RUNS=21 RAYBENCH_CUDA_TRAVERSAL=$trav RAYBENCH_CUDA_WARMUP_MS=0 \
                    render_as "exp-$fl-$trav-minb1-nowarm" /tmp/t.csv $s --accel bvh
            done
        done
        RT=$bd/renderer/raytrace RAYBENCH_CUDA_RUNS=11 RAYBENCH_CUDA_TRAVERSAL=ldg render_as "exp-4k-$fl-ldg1" /tmp/t.csv dragon --accel bvh -r 3840x2160
        RT=$bd/renderer/raytrace RAYBENCH_CUDA_RUNS=5 RAYBENCH_CUDA_TRAVERSAL=ldg render_as "exp-none-$fl-ldg1" /tmp/t.csv dragon --accel none
        # correctness of the variant with this build (dragon, bottle, spheres2)
        for sc in InterestingScenes/dragon InterestingScenes/bottle SphereExamples/spheres2; do
            RAYBENCH_CUDA_TRAVERSAL=ldg GPU_CHECK_BLOCKS="bvh:8x8 bvh:32x32" tests/gpu/gpu_check.sh $bd/renderer/raytrace \
                $B/renderer/imgdiff "$SC" bvh $sc | sed "s/^/$fl ldg1: /"
        done
    done
    cat /tmp/t.csv >>$T; rm -f /tmp/t.csv
fi

if has tune; then
    # Tile order x L1 carveout x block on the report's scenes (the 4-wide
    # traversal), and the dragon and arm-reach over image sizes. Variant
    # ORDER-cCARVEOUT-BLOCK; size rows size-WxH.
    echo "== tune: tile order, carveout, block; image size"
    T=$OUT/timings.csv; [ -s $T ] || header | sed 's/^/variant,/' >$T
    for s in $REPORT; do
        for order in tiles scatter; do
            for co in -1 0; do
                for blk in 16x16 8x8 4x8; do
                    RAYBENCH_CUDA_ORDER=$order RAYBENCH_CUDA_CARVEOUT=$co RAYBENCH_CUDA_RUNS=21 \
                        render_as "$order-c$co-$blk" /tmp/t.csv $s --accel bvh --block $blk
                done
            done
        done
    done
    for s in dragon arm-reach; do
        for r in 128x96 256x192 512x384 800x600 1024x768 2048x1536; do
            RAYBENCH_CUDA_RUNS=11 render_as "size-$r" /tmp/t.csv $s --accel bvh -r $r
        done
    done
    cat /tmp/t.csv >>$T; rm -f /tmp/t.csv
fi

if has trav; then
    # The 4-wide traversal against the binary tree's GPU variant, in one call:
    # traversal x register cap x block on the report's scenes, and the dragon
    # and arm-reach at 4K. Rows go to timings.csv, variant TRAV-minbN-BLOCK.
    echo "== trav: wide vs binary (ldg) traversal"
    T=$OUT/timings.csv; [ -s $T ] || header | sed 's/^/variant,/' >$T
    for s in $REPORT spheres2; do
        for trav in wide ldg; do
            for minb in 1 2 3 4; do
                for blk in 16x16 8x8 4x8; do
                    RAYBENCH_CUDA_TRAVERSAL=$trav RAYBENCH_CUDA_MINB=$minb RAYBENCH_CUDA_RUNS=21 \
                        render_as "$trav-minb$minb-$blk" /tmp/t.csv $s --accel bvh --block $blk
                done
            done
        done
    done
    for s in dragon arm-reach; do
        for trav in wide ldg; do
            for minb in 1 4; do
                RAYBENCH_CUDA_TRAVERSAL=$trav RAYBENCH_CUDA_MINB=$minb RAYBENCH_CUDA_RUNS=11 render_as "4k-$trav-minb$minb-8x8" /tmp/t.csv $s --accel bvh \
                    --block 8x8 -r 3840x2160
            done
        done
    done
    cat /tmp/t.csv >>$T; rm -f /tmp/t.csv
fi

if has ncu; then
    echo "== ncu: one launch of dragon and arm-reach"
    for s in dragon arm-reach; do
        RAYBENCH_CUDA_RUNS=1 timeout 200 ncu --launch-skip 1 --launch-count 1 --section SpeedOfLight --section Occupancy \
            --section WarpStateStats --section MemoryWorkloadAnalysis --section LaunchStats --section SchedulerStats \
            --section InstructionStats --metrics smsp__inst_executed.sum,smsp__thread_inst_executed.sum,sm__cycles_elapsed.avg,l1tex__t_bytes_pipe_lsu_mem_local_op_ld.sum \
            $RT -q --backend cuda -o /tmp/ncu.ppm "$(scene_path $s)" >>$OUT/ncu.txt 2>&1
    done
    grep -E "Duration|Memory Throughput|Compute \(SM\)|Achieved Occupancy|Theoretical Occupancy|Stall|Issued Warp|No Eligible|L1/TEX Hit|L2 Hit|Warp Cycles Per Issued|inst_executed|cycles_elapsed|mem_local|Registers" $OUT/ncu.txt | head -60
fi

if has ab; then
    echo "== ab: $GPU_AB_OLD against this tree, defaults"
    OLDRT=$GPU_AB_OLD/$B/renderer/raytrace
    (cd "$GPU_AB_OLD" && { [ -f $B/build.ninja ] || meson setup $B -Dharness=false -Dgpu_arch=9.0 -Dpng=auto -Dmpi=disabled; } >/dev/null && ninja -C $B >/dev/null) || { echo "old tree does not build"; exit 1; }
    A=$OUT/ab.csv; header | sed 's/^/variant,/' >$A
    for rep in 1 2 3; do
        for s in $REPORT; do
            RT=$OLDRT render_as before /tmp/a.csv $s
            render_as after /tmp/a.csv $s
        done
    done
    cat /tmp/a.csv >>$A; rm -f /tmp/a.csv
fi
if has vars; then
    echo "== vars: ${GPU_VARIANTS:-base}"
    V=$OUT/vars.csv; header | sed 's/^/variant,/' >$V
    for rep in 1 2; do
        for s in $REPORT; do
            for res in "" 128x96; do
                [ -n "$res" ] && [ "${GPU_VARS_SMALL:-}" != all ] && [ $s != dragon ] && [ $s != arm-reach ] && continue
                for v in ${GPU_VARIANTS:-base}; do
                    render_variant "$v" /tmp/v.csv $s ${res:+-r $res}
                done
            done
        done
    done
    cat /tmp/v.csv >>$V; rm -f /tmp/v.csv
fi

if has timeline; then
    echo "== timeline"
    T=$OUT/timeline.csv; echo "variant,scene,res,chunk,x,y,sm,start_ns,end_ns,steps_max,steps_sum,pairs" >$T
    for s in dragon arm-reach; do
        for res in def 128x96; do
            for v in ${GPU_VARIANTS:-base RAYBENCH_CUDA_SCHED=persistent+BLOCK=4x8}; do
                rm -f /tmp/tl.csv
                r=""; [ $res != def ] && r=$res
                RAYBENCH_CUDA_TIMELINE=/tmp/tl.csv render_variant "$v" /tmp/t.csv $s ${r:+-r $r} &&
                    tail -n +2 /tmp/tl.csv | sed "s/^/$v,$s,$res,/" >>$T
            done
        done
    done
    rm -f /tmp/t.csv
    # per run: chunks, frame span, the last chunk to end, the longest chunk
    awk -F, 'NR > 1 { k = $1 "," $2 "," $3; n[k]++; d = $9 - $8; if ($9 > e[k]) { e[k] = $9; ls[k] = $8; lm[k] = $10 }
                      if (d > md[k]) { md[k] = d; mm[k] = $10 }; if (!(k in s0) || $8 < s0[k]) s0[k] = $8 }
             END { for (k in n) printf "%s: chunks %d, span %.1f us; last ends %.1f us (started %.1f, %d steps); longest %.1f us (%d steps)\n",
                   k, n[k], (e[k] - s0[k]) / 1e3, e[k] / 1e3, ls[k] / 1e3, lm[k], md[k] / 1e3, mm[k] }' $T | sort
fi

if has check; then
    # The same scripts as `meson test --suite gpu` (tests/gpu/meson.build),
    # called directly so that this works before tests/meson.build has subdir('gpu').
    echo "== check: every course scene against serial; compute-sanitizer"
    rm -f $OUT/check.csv
    fails=0
    for f in "$SC"/*/*.txt; do
        g=$(basename "$(dirname "$f")"); n=$(basename "$f" .txt)
        GPU_CHECK_CSV=$OUT/check.csv tests/gpu/gpu_check.sh $RT $B/renderer/imgdiff "$SC" full "$g/$n" \
            >>$OUT/testlog.txt 2>&1; rc=$?
        [ $rc -eq 0 ] || [ $rc -eq 77 ] || { fails=$((fails + 1)); echo "FAIL: $g/$n"; }
    done
    echo "scenes failing: $fails"
    awk -F, 'NR > 1 && $12 != "ok"' $OUT/check.csv
    awk -F, 'NR > 1 { n++; if ($4 != "inf" && (m == "" || $4 + 0 < m)) m = $4 + 0; if ($5 + 0 > o) o = $5 + 0; d = $9 < 0 ? -$9 : $9; if (d > r) r = d }
             END { printf "comparisons %d, lowest PSNR %s dB, most pixels over 2/255 %s%%, largest ray-count gap %s%%\n", n, m, o, r }' $OUT/check.csv
    timeout 400 tests/gpu/gpu_sanitize.sh $RT "$SC" >>$OUT/testlog.txt 2>&1; echo "sanitizer exit $?"
    grep -E "^(memcheck|racecheck)" $OUT/testlog.txt
fi
echo "== done $(date -u +%FT%TZ)"
