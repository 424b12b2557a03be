#!/bin/sh
# Nothing read from a config, a CSV or a path reaches a shell or gnuplot's
# command line:
#   - a scene named to break out of a gnuplot string (quote, backquote,
#     @macro) is plotted as text, and runs nothing;
#   - a --raytrace folder with a quote in it (the fingerprint's git calls) runs
#     nothing;
#   - harness slurm refuses a config path or study name with a newline;
#   - a study name with a '/' is refused (it names results/STUDY.csv);
#   - config lines with control characters are refused, a byte-order mark is
#     accepted, and a '|' in a scene name stays inside its Markdown cell.
# usage: test-security.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup security "$1" "$2"
unset OMP_NUM_THREADS OMP_PLACES OMP_PROC_BIND

# ---- a scene whose name would run commands in gnuplot, unquoted
mkdir scenes
# (gnuplot runs in the plot's folder: the commands would touch files there)
evil1="ok';system('touch\${IFS}PWNED1');print'"
evil2="ok\`touch\${IFS}PWNED2\`"
evil3="ok@x|y"
for e in "$evil1" "$evil2" "$evil3"; do echo "# dummy" > "scenes/$e.txt"; done
cat > evil.conf <<CONF
study: evil
scene_dir: scenes
scenes: $evil1 $evil2 $evil3
backend: serial openmp
threads: 1 2
repeats: 1
pin: none
oversubscribe: allow
raytrace: $FAKE
CONF
"$H" run evil.conf -o evil.csv -q 2> run.err || { cat run.err; fail "the study failed"; }
[ "$(($(wc -l < evil.csv) - 1))" -eq 9 ] || fail "expected 9 rows: $(cat evil.csv)"
"$H" table evil.csv > table.md || fail "table failed"
grep -q 'ok@x\\|y' table.md || { cat table.md; fail "'|' in a scene name not escaped in the Markdown table"; }
command -v gnuplot > /dev/null || fail "gnuplot missing (scripts/install-deps.sh installs gnuplot-nox)"
mkdir plots
"$H" plot evil.csv -o plots/evil > plot.out 2>&1 || { cat plot.out; fail "plot failed"; }
[ -s plots/evil-speedup.png ] && [ -s plots/evil-scenes.png ] || fail "no plots"
"$H" plot evil.csv -o "$(printf 'plots/x\nsystem("touch PWNED3")\n#')" > /dev/null 2>&1 &&
    fail "plot took a prefix with a newline"
grep -q "touch" plots/evil-speedup.gp || fail "the scene names are not in the speedup plot's titles"
found=$(ls PWNED* plots/PWNED* 2> /dev/null)
[ -z "$found" ] || fail "a scene name ran a command through gnuplot: $found"

# ---- a raytrace path with a quote: the fingerprint's git calls take it as it is
d="$T/bin'; touch $T/PWNED3; echo '"
mkdir -p "$d" && ln -s "$FAKE" "$d/raytrace"
cat > fp.conf <<CONF
study: fp
scene_dir: scenes
scenes: $evil3
repeats: 1
pin: none
CONF
"$H" run fp.conf --raytrace "$d/raytrace" -o fp.csv -q 2> fp.err || { cat fp.err; fail "run with a quoted --raytrace failed"; }
[ ! -e PWNED3 ] || fail "a --raytrace path ran a command"

# ---- harness slurm: no newline into the script
nl="$T/x
touch $T/PWNED4
.conf"
cp fp.conf "$nl"
"$H" slurm "$nl" -o s.sbatch > /dev/null 2> slurm.err && fail "slurm accepted a config path with a newline"
grep -q "control character" slurm.err || fail "slurm's message: $(cat slurm.err)"
[ ! -e s.sbatch ] || fail "slurm wrote a script"

# ---- config lines: control characters refused (file and line named), a BOM accepted
printf 'study: a\033b\nscenes: x\n' > ctrl.conf
"$H" run ctrl.conf --dry-run > /dev/null 2> ctrl.err && fail "a control character in a config was accepted"
grep -q "ctrl.conf:1: control character" ctrl.err || fail "control character message: $(cat ctrl.err)"
printf '\357\273\277study: bom\nscene_dir: scenes\nscenes: %s\nrepeats: 1\n' "$evil3" > bom.conf
"$H" run bom.conf --dry-run --raytrace "$FAKE" > bom.out 2> bom.err || { cat bom.err; fail "a config with a byte-order mark was refused"; }
# ---- a study name is a name: with a '/' it would put results/STUDY.csv elsewhere
printf 'study: ../../escaped\nscene_dir: scenes\nscenes: %s\nrepeats: 1\npin: none\nraytrace: %s\n' "$evil3" "$FAKE" > esc.conf
mkdir -p sub/results && (cd sub && "$H" run ../esc.conf -q > /dev/null 2> ../esc.err) && fail "a study name with '/' was accepted"
[ "$(wc -l < esc.err)" -eq 1 ] && grep -q "esc.conf:1: study: a name, not a path" esc.err || fail "study name: $(cat esc.err)"
[ ! -e escaped.csv ] && [ ! -e "$T/../escaped.csv" ] || fail "a study name wrote outside results/"
echo "security test passed"
