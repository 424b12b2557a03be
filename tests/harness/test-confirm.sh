#!/bin/bash
# harness ab --config and history check --confirm, with the real renderer:
#   - ab --config runs each configuration with two raytrace builds,
#     interleaved: the same build is never a regression, a build with four times
#     the pixels is (exit 1); a command study or a missing build is one line
#     and exit 1;
#   - a step stored in history that the code did not make (the same build
#     measured 1.5x slower from the fifth commit on, as on a busy machine) is
#     re-measured, reported unconfirmed, and the check passes;
#   - a step the build made (the builds from the fifth commit on are
#     slower) is CONFIRMED, bisected to the fifth commit, and fails the
#     check;
#   - a commit that cannot be built leaves the step unconfirmed, naming it;
#     a config whose settings are not the series' is not used to confirm.
# The builder here maps commits to builds (scripts/build-commit.sh builds
# real commits: docs/harness-history.md, "History").
# usage: test-confirm.sh HARNESS RAYTRACE SOURCE_ROOT
set -u
. "$(dirname "$0")/common.sh"
RT=$(realpath "$2") SRC=$(realpath "$3")
test_setup confirm "$1" "$1"
if "$H" history show --db none.db 2>&1 | grep -q "no SQLite"; then
    fail "this harness was built without SQLite (scripts/install-deps.sh installs libsqlite3-dev)"
fi
cp "$SRC/scenes/glass.txt" .
printf 'study: c\nscene_dir: .\nscenes: glass\nbackend: serial\nresolution: 96x72\nrepeats: 3\npin: close\nraytrace: %s\n' \
    "$RT" > c.conf
# the slower build: the same renderer, four times the pixels (the last -r counts)
printf '#!/bin/sh\nexec "%s" "$@" -r 192x144\n' "$RT" > slow.sh
chmod +x slow.sh

"$H" ab --config c.conf "$RT" "$RT" --rounds 10 > same.out || { cat same.out; fail "ab --config: the same build flagged"; }
grep -Eq '^(no change|INCONCLUSIVE) scene=glass backend=serial resolution=96x72 pin=close: median' same.out ||
    { cat same.out; fail "ab --config: no verdict line for the configuration"; }
grep -q "^harness ab: 1 configuration(s): 0 regression(s)" same.out || { cat same.out; fail "ab --config: summary"; }
"$H" ab --config c.conf "$RT" ./slow.sh --rounds 10 > slow.out && { cat slow.out; fail "ab --config: 4x slower passed"; }
grep -q '^REGRESSION scene=glass .*ratio [2-9]\.' slow.out || { cat slow.out; fail "ab --config: no REGRESSION"; }
printf 'study: p\ncommand: true\n' > prog.conf
"$H" ab --config prog.conf "$RT" "$RT" > /dev/null 2> prog.err && fail "ab --config of a command study"
grep -q "prog.conf: a command study" prog.err || { cat prog.err; fail "command study: message"; }
"$H" ab --config c.conf "$RT" ./nothere > /dev/null 2> miss.err && fail "ab --config with a missing build"
[ "$(wc -l < miss.err)" -eq 1 ] && grep -q "raytrace B: './nothere' not found" miss.err ||
    { cat miss.err; fail "missing build: not one line"; }

# eight commits of the same build; from the fifth on stored 1.5x slower.
# The stored times are set, not measured: what is tested is the check on
# the history, which a busy machine's repeats must not decide.
"$H" run c.conf -o one.csv -q 2> /dev/null || fail "the study"
for k in $(seq 1 8); do
    awk -F, -v OFS=, -v k="$k" '
        NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; print; next }
        { $c["render_ms"] = sprintf("%.4f", (10 + (NR % 3) * 0.1) * (k >= 5 ? 1.5 : 1.0))
          $c["git_commit"] = sprintf("c0ffee%02d", k)
          $c["utc"] = sprintf("2026-11-%02dT10:00:00Z", k); print }' one.csv > "c$k.csv"
done
"$H" history add --db h.db c{1..8}.csv > /dev/null || fail "history add"
"$H" history check --db h.db --window 4 > plain.out && { cat plain.out; fail "the stored step passed without --confirm"; }
grep -q "^STEP scene=glass .* at commit c0ffee05 (after c0ffee04)" plain.out || { cat plain.out; fail "no stored step"; }

# the builder: BUILDER COMMIT DIR prints the build's raytrace
cat > builder.sh << EOF
#!/bin/sh
mkdir -p "\$2" || exit 1
case \$1 in c0ffee0[5-8]) [ -e slow-from-5 ] && { echo "$PWD/slow.sh"; exit 0; } ;; esac
echo "$RT"
EOF
chmod +x builder.sh
confirm=(history check --db h.db --window 4 --confirm c.conf --builder ./builder.sh --build-dir bd --rounds 10)
"$H" "${confirm[@]}" > machine.out || { cat machine.out; fail "a step the build did not make failed the check"; }
# on a busy machine the same builds may measure as inconclusive: unconfirmed either way
grep -qE "^  unconfirmed: re-measured interleaved, c0ffee08 against c0ffee01 \(the windows' ends\) shows (no change|nothing conclusive)" machine.out ||
    { cat machine.out; fail "no 'unconfirmed' line"; }
grep -q "0 confirmed slowdown step(s)" machine.out && grep -q "1 step(s) unconfirmed" machine.out ||
    { cat machine.out; fail "unconfirmed: summary"; }
touch slow-from-5
"$H" "${confirm[@]}" > code.out && { cat code.out; fail "a step the build made passed the check"; }
# the windows' ends (1 and 8), then bisected: 1-4 no change, 1-6 and 1-5 slower
grep -q "^  CONFIRMED: a slowdown of [0-9.]*x at commit c0ffee05 (after c0ffee04), 4 interleaved re-measurement(s)" code.out ||
    { cat code.out; fail "not CONFIRMED at c0ffee05"; }
grep -q "1 confirmed slowdown step(s)" code.out || { cat code.out; fail "confirmed: summary"; }

"$H" history check --db h.db --window 4 --confirm c.conf --builder false > nobuild.out 2> nobuild.err ||
    { cat nobuild.out nobuild.err; fail "an unbuildable commit failed the check"; }
grep -q "^  unconfirmed: commit c0ffee01 could not be built" nobuild.out || { cat nobuild.out; fail "unbuildable: line"; }
sed 's/^repeats: 3/repeats: 3\nextra_args: --max-depth 2/' c.conf > other.conf
"$H" history check --db h.db --window 4 --confirm other.conf --builder ./builder.sh > other.out ||
    { cat other.out; fail "another config's settings failed the check"; }
grep -q "^  unconfirmed: other.conf's settings (config_hash .*) are not the series'" other.out ||
    { cat other.out; fail "other settings: line"; }
echo "ok"
