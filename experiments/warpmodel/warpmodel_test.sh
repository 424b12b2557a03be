#!/bin/sh
# warpmodel_test.sh WARPMODEL RAYTRACE SRCDIR - the warp model on the shipped
# demo scene: it must trace exactly the renderer's rays (the record's rays=),
# its table must keep the bounds that hold by construction (no lane is
# busier than its warp's phases; two shadow rays in one lane for free are
# never slower than one after the other; lane use is a share), and bad
# input must get a one-line error and a non-zero exit.
WM=$1
RT=$2
SRC=$3
SCENE="$SRC/scenes/demo.txt"
fail=0
TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT

"$WM" -r 64x48 -b 8x8 "$SCENE" >"$TMP/out" 2>"$TMP/err"
rc=$?
[ $rc -eq 0 ] || { echo "FAIL: warpmodel exit $rc: $(cat "$TMP/err")"; exit 1; }
cat "$TMP/out"
want=$("$RT" -q --backend serial --accel bvh -r 64x48 -o "$TMP/x.ppm" "$SCENE" | tr ' ' '\n' | sed -n 's/^rays=//p')
got=$(sed -n '1s/.* rays=\([0-9]*\) .*/\1/p' "$TMP/out")
[ -n "$want" ] && [ "$want" = "$got" ] || { echo "FAIL: the model traced $got rays, the renderer $want"; fail=1; }
warps=$(sed -n '1s/.* warps=\([0-9]*\) .*/\1/p' "$TMP/out")
# 64x48 in 8x8 blocks: 8 x 6 blocks of two warps
[ "$warps" = 96 ] || { echo "FAIL: $warps warps, expected 96"; fail=1; }
awk -v f="$TMP/bad" '
    /^phased/ { p = $3; ps = $5 }
    /^busiest lane/ { if (!($3 <= p) || !($5 <= ps)) print "busiest lane " $3 "/" $5 " above phased " p "/" ps > f }
    /^pairs f=0 / { if (!($3 <= p)) print "free pairs " $3 " above phased " p > f }
    NR > 2 { n = NF; if (!($n > 0 && $n <= 1)) print "lane use " $n " out of (0, 1]: " $0 > f; rows++ }
    END { if (rows != 12) print rows " model rows, expected 12" > f; if (!(p > 0)) print "no phased row" > f }
' "$TMP/out"
[ -s "$TMP/bad" ] && { sed 's/^/FAIL: /' "$TMP/bad"; fail=1; }

# bad input: the file or the option named on one line, non-zero exit
"$WM" "$TMP/none.txt" >/dev/null 2>"$TMP/err"
rc=$?
{ [ $rc -eq 1 ] && [ "$(wc -l <"$TMP/err")" -eq 1 ] && grep -q "none.txt" "$TMP/err"; } ||
    { echo "FAIL: missing scene: exit $rc, $(cat "$TMP/err")"; fail=1; }
printf 'camera_pos: 0 0 0\nsphere: oops\n' >"$TMP/bad.txt"
"$WM" "$TMP/bad.txt" >/dev/null 2>"$TMP/err"
rc=$?
{ [ $rc -eq 1 ] && [ "$(wc -l <"$TMP/err")" -eq 1 ] && grep -q "bad.txt:2" "$TMP/err"; } ||
    { echo "FAIL: bad scene: exit $rc, $(cat "$TMP/err")"; fail=1; }
for args in "-b 5x5" "-b 64x32" "-r 0x10" "-w x" "-c -1" ""; do
    # shellcheck disable=SC2086
    "$WM" $args "$SCENE" extra >/dev/null 2>"$TMP/err" && { echo "FAIL: '$args ... extra' was accepted"; fail=1; }
    # shellcheck disable=SC2086
    "$WM" $args >/dev/null 2>"$TMP/err"
    rc=$?
    case "$args" in
        "") want="expected one scene file" ;;
        *) want="${args%% *} ${args#* }" ;;
    esac
    { [ $rc -eq 2 ] && head -1 "$TMP/err" | grep -q -- "$want"; } ||
        { echo "FAIL: warpmodel $args: exit $rc, $(head -1 "$TMP/err")"; fail=1; }
done
[ $fail -eq 0 ] && echo "warpmodel: all checks passed"
exit $fail
