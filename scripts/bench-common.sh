# bench-common.sh - sourced by scripts/bench-embree.sh: its options, scene
# lookup and interleaved table (raytrace builds: harness ab --config).
#
# bench_opts ARG...: takes --rounds N and --cpu C (into $rounds and $cpu,
# whose defaults the caller sets) from anywhere in the arguments and leaves
# the others, in order, in the array $args.
bench_opts() {
    args=()
    while [ $# -gt 0 ]; do
        case $1 in
        --rounds) rounds=$2; shift 2 ;;
        --cpu) cpu=$2; shift 2 ;;
        *) args+=("$1"); shift ;;
        esac
    done
}

# course_scene NAME: the path of a course scene (RAYBENCH_COURSE_DIR, default
# ../shared/scenes/course) by its name, or a path given as it is; nothing
# when there is no such scene.
course_scene() {
    if [ -f "$1" ]; then
        echo "$1"
    else
        find "${RAYBENCH_COURSE_DIR:-../shared/scenes/course}" -name "$1.txt" | head -n 1
    fi
}

# interleave FN_A FN_B SCENE: $rounds rounds of `FN_A SCENE` then `FN_B
# SCENE` (each prints one time in ms), alternating so a slow spell of the
# machine falls on both; prints the best time of each: "A B".
interleave() {
    local a=() b=() r
    for r in $(seq "$rounds"); do
        a+=("$("$1" "$3")")
        b+=("$("$2" "$3")")
    done
    echo "$(printf '%s\n' "${a[@]}" | sort -g | head -n 1) $(printf '%s\n' "${b[@]}" | sort -g | head -n 1)"
}

# ab_table WHO HEAD_A HEAD_B RATIO FN_A FN_B SCENE...: the Markdown table
# of interleave per scene, with the ratio RATIO ("a/b" or "b/a") to three
# places; WHO names the script in its errors.
ab_table() {
    local who=$1 ha=$2 hb=$3 ratio=$4 fa=$5 fb=$6 s f a b
    shift 6
    echo "| scene | $ha | $hb | $([ "$ratio" = a/b ] && echo "$ha / $hb" || echo "$hb / $ha") |"
    echo "|---|---|---|---|"
    for s in "$@"; do
        f=$(course_scene "$s")
        [ -n "$f" ] || { echo "$who: no scene $s (RAYBENCH_COURSE_DIR or ../shared/scenes/course)" >&2; return 1; }
        read -r a b <<< "$(interleave "$fa" "$fb" "$f")"
        echo "| $(basename "$f" .txt) | $a | $b | $(awk -v a="$a" -v b="$b" -v r="$ratio" \
            'BEGIN { printf "%.3f", r == "a/b" ? a / b : b / a }') |"
    done
}
