#!/bin/bash
# `harness table`'s default Markdown fits 100 columns (docs/harness-table.md):
#   - every line, for every study CSV under results/, and for a ceiling, a
#     size (maxrss_kib) and a scene name of 60 characters;
#   - the notes' codes are explained under the table when used, and the
#     table says once what only --wide has;
#   - no configuration is lost: as many rows as --format json has;
#   - --wide still has every column and the notes in words; csv and json
#     are not cut.
# usage: test-table-width.sh HARNESS SOURCE_ROOT
set -u
. "$(dirname "$0")/common.sh"
test_setup table-width "$1" "$1"
R=$2/results
[ -d "$R" ] || fail "no results/ under $2"
command -v python3 > /dev/null || fail "python3 missing (scripts/install-deps.sh)"

# widest() FILE: the longest line in bytes (LC_ALL=C: a UTF-8 name counts
# no narrower than it is)
widest() { LC_ALL=C awk '{ if (length($0) > m) m = length($0) } END { print m + 0 }' "$1"; }
fits() { # NAME FILE
    local w
    w=$(widest "$2")
    [ "$w" -le 100 ] || { LC_ALL=C awk 'length($0) > 100' "$2" | head -5; fail "$1: a line of $w columns"; }
}
# rows() FILE: the data rows of the per-configuration tables
rows() {
    awk '/^### / { on = /^### Per configuration/; head = 1; next }
         on && /^\|---/ { head = 0; next }
         on && /^\| / && !head { n++ }
         END { print n + 0 }' "$1"
}
# same_rows NAME MD JSON-ARGS...: the table has every configuration
same_rows() {
    local name=$1 md=$2 want
    shift 2
    # a configuration's object alone has the key "configuration" (a fit's: "series")
    want=$("$H" table --format json "$@" | grep -o '"configuration": ' | wc -l)
    [ "$(rows "$md")" -eq "$want" ] || { cat "$md"; fail "$name: $(rows "$md") rows, json has $want"; }
}

# ---- every study CSV checked in (the others are not harness CSVs)
n=0
for f in "$R"/*.csv; do
    "$H" table "$f" > t.md 2> /dev/null || continue
    n=$((n + 1))
    fits "$(basename "$f")" t.md
    same_rows "$(basename "$f")" t.md "$f"
    [ "$(grep -c '^(--wide for' t.md)" -ge 1 ] || fail "$(basename "$f"): no '(--wide for ...)'"
done
[ "$n" -ge 10 ] || fail "only $n study CSVs under results/"
echo "ok: $n study CSVs fit 100 columns"

# ---- a scaling study: outliers coded and explained, the label key shortened
"$H" table "$R/cpu-h200host-openmp-bvh.csv" > cpu.md || fail "table cpu"
fits cpu cpu.md
grep -q '| O1 |' cpu.md && grep -q '^Notes: .*On = n outliers' cpu.md || { cat cpu.md; fail "cpu: no outlier code or legend"; }
grep -q '^Label keys: sched = schedule' cpu.md && grep -q '| openmp/bvh T=16 sched=tiles |' cpu.md ||
    fail "cpu: label keys"
[ "$(grep -c '^(--wide for' cpu.md)" -eq 1 ] || fail "cpu: '(--wide for ...)' not said once"
"$H" table --wide "$R/cpu-h200host-openmp-bvh.csv" > cpu-wide.md || fail "table --wide cpu"
for h in workers Karp-Flatt 'efficiency (b)' 'speedup (b)' 'base (b)' 'T(1) ms' 'IQR ms' 'outliers 1'; do
    grep -q "$h" cpu-wide.md || fail "--wide lacks '$h'"
done
grep -q '| openmp/bvh T=16 schedule=tiles |' cpu-wide.md || fail "--wide: labels not whole"
[ "$(widest cpu-wide.md)" -gt 100 ] || fail "--wide is no wider than the default"

# ---- many configurations and scenes: the cross table in blocks or transposed
"$H" table "$R/gpu-blocks-harness.csv" > gpu.md || fail "table gpu"
fits gpu gpu.md
grep -q '^### Scenes x configurations' gpu.md || fail "gpu: no cross table"
for l in 'serial/bvh' 'cuda/bvh B=8x4' 'cuda/bvh B=1024x1' 'cuda/bvh B=13x7'; do
    [ "$(grep -c "| $l |" gpu.md)" -ge 6 ] || fail "gpu: '$l' missing from a table"
done

# ---- hybrid: failures, oversubscription and fit codes explained
"$H" table "$R/cpu-h200host-hybrid.csv" > hyb.md || fail "table hybrid"
fits hybrid hyb.md
grep -q '| refused:3 OS |' hyb.md && grep -q '^Notes: STATUS:n = ' hyb.md && grep -q 'OS = oversubscribed' hyb.md ||
    { cat hyb.md; fail "hybrid: notes"; }
grep -q '| U |' hyb.md && grep -q '^Notes: U = uncertain' hyb.md || fail "hybrid: fit notes"
"$H" table --wide "$R/cpu-h200host-hybrid.csv" | grep -q 'refused 3, oversubscribed' || fail "hybrid --wide notes"

# ---- the machine's ceiling
"$H" table "$R/cpu-h100host-openmp-bvh-1024-ceiling.csv" --ceiling "$R/ceiling-h100host.csv" > ceil.md ||
    fail "table ceiling"
fits ceiling ceil.md
grep -q '| [0-9.]* ([0-9.]* of [0-9.]*) |' ceil.md || { cat ceil.md; fail "ceiling: no efficiency against it"; }
awk '/^\(--wide for/ { on = 1 } on { s = s " " $0 } END { print s }' ceil.md | grep -q 'S(b))' ||
    fail "ceiling: what is left for --wide is not said"
"$H" table --wide "$R/cpu-h100host-openmp-bvh-1024-ceiling.csv" --ceiling "$R/ceiling-h100host.csv" |
    grep -q '| speedup (b) |' || fail "ceiling: --wide lacks speedup (b)"

# ---- a size
size=$R/xz-h100host.csv
[ -f "$size" ] || size=$(grep -l maxrss_kib "$R"/*.csv | head -1)
"$H" table "$size" --metric maxrss_kib > size.md || fail "table size"
fits size size.md
grep -q '| x 1 worker |' size.md && grep -q '^No Amdahl fit' size.md || { cat size.md; fail "size table"; }
same_rows size size.md "$size" --metric maxrss_kib
"$H" table --wide "$size" --metric maxrss_kib | grep -q '| workers | n | median KiB \[CI\] | min KiB |' ||
    fail "size: --wide lacks its columns"

# ---- a scene name of 60 characters
long=a_scene_whose_name_is_sixty_characters_long_0123456789_abcde
[ ${#long} -eq 60 ] || fail "the long name is ${#long} characters"
for src in gpu-blocks-harness cpu-h200host-openmp-bvh; do
    python3 - "$R/$src.csv" "$long-$src.csv" "$long" <<'PY' || fail "long: writing the CSV"
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1], newline="")))
with open(sys.argv[2], "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=rows[0].keys())
    w.writeheader()
    for r in rows:
        r["scene"] = sys.argv[3] if r["scene"] == "dragon" else r["scene"]
        w.writerow(r)
PY
    "$H" table "$long-$src.csv" > long.md || fail "table long ($src)"
    fits "long ($src)" long.md
    same_rows "long ($src)" long.md "$long-$src.csv"
    grep -q "$long" long.md || fail "long ($src): the scene's name is not said"
    "$H" table --wide "$long-$src.csv" | grep -q "^| $long | serial/bvh |" || fail "long ($src): --wide"
done

# ---- csv and json: not cut
"$H" table --format csv "$R/gpu-blocks-harness.csv" > g.csv || fail "csv"
grep -q '^scene,configuration,n,' g.csv && [ "$(widest g.csv)" -gt 100 ] || fail "csv form"
"$H" table --format json "$R/gpu-blocks-harness.csv" | python3 -c 'import json,sys; json.load(sys.stdin)' ||
    fail "json form"
echo "table width test passed"
