#!/bin/bash
# The default scene cache folder of `harness run` (docs/harness.md, "Scene
# cache"), as the renderer receives it (--cache DIR, recorded by a wrapper):
#   - $XDG_CACHE_HOME/raybench, both made private (0700) when missing;
#   - a relative $XDG_CACHE_HOME is ignored: $HOME/.cache/raybench (0700);
#   - neither set: ~/.cache/raybench with ~ from the password database;
#   - no home at all (nobody, home /nonexistent): a new private folder
#     raybench-cache-XXXXXX beside the study's CSV, owned by the user, and
#     never the fixed /tmp/raybench-cache-UID another user could plant.
# The last case switches to nobody with setpriv, so it needs root: without
# root the test says so and exits 77.
# usage: test-cachedir.sh HARNESS FAKE_RAYTRACE
set -u
. "$(dirname "$0")/common.sh"
test_setup cachedir "$1" "$2"
chmod 755 "$T"
echo "# dummy" > oka.txt
# the wrapper appends its --cache argument to cache.log; it runs a copy of
# the fake renderer that nobody can execute too (the checkout may lie under
# a home of mode 0700)
cp "$FAKE" fake.sh && chmod 755 fake.sh
printf '#!/bin/sh\nprev=\nfor a; do [ "$prev" = --cache ] && echo "$a" >> %s/cache.log; prev=$a; done\nexec %s/fake.sh "$@"\n' \
    "$T" "$T" > rec.sh
chmod 755 rec.sh
printf 'study: cd\nscene_dir: %s\nscenes: oka\nrepeats: 1\npin: none\nraytrace: %s/rec.sh\n' "$T" "$T" > cd.conf
# runs the study under env ARGS; sets GOT to the --cache DIR of its run
study() {
    rm -f cache.log out.csv
    env "$@" "$H" run cd.conf -o out.csv --overwrite -q 2> run.err || { cat run.err; fail "run under env $*"; }
    GOT=$(cat cache.log)
}
mode() { stat -c %a "$1"; }

mkdir home
study -u XDG_CACHE_HOME XDG_CACHE_HOME="$T/xdg" HOME="$T/home"
[ "$GOT" = "$T/xdg/raybench" ] || fail "XDG_CACHE_HOME: cache '$GOT'"
[ "$(mode xdg)" = 700 ] && [ "$(mode xdg/raybench)" = 700 ] ||
    fail "XDG_CACHE_HOME: modes $(mode xdg) $(mode xdg/raybench), expected 700"

study XDG_CACHE_HOME=rel HOME="$T/home"
[ "$GOT" = "$T/home/.cache/raybench" ] || fail "HOME: cache '$GOT'"
[ "$(mode home/.cache)" = 700 ] && [ "$(mode home/.cache/raybench)" = 700 ] || fail "HOME: modes not 700"
[ ! -e rel ] || fail "a relative XDG_CACHE_HOME was used"

# the password database's home (the real one: what was not there before is
# removed again)
pwhome=$(getent passwd "$(id -u)" | cut -d: -f6)
[ -d "$pwhome" ] || fail "the home of uid $(id -u) in the password database, '$pwhome', is no folder"
had_cache=0 had_rb=0
[ -e "$pwhome/.cache" ] && had_cache=1
[ -e "$pwhome/.cache/raybench" ] && had_rb=1
study -u XDG_CACHE_HOME -u HOME
[ $had_rb = 1 ] || rmdir "$pwhome/.cache/raybench" 2> /dev/null
[ $had_cache = 1 ] || rmdir "$pwhome/.cache" 2> /dev/null
[ "$GOT" = "$pwhome/.cache/raybench" ] || fail "no HOME: cache '$GOT', expected $pwhome/.cache/raybench"

# no home at all: nobody
if [ "$(id -u)" -ne 0 ]; then
    echo "SKIP: not root: the case without a home runs as nobody (setpriv)"; exit 77
fi
command -v setpriv > /dev/null || fail "setpriv missing (util-linux)"
nhome=$(getent passwd nobody | cut -d: -f6)
[ -n "$nhome" ] && [ ! -e "$nhome" ] || fail "nobody's home '$nhome' exists: this case needs a user without one"
nuid=$(id -u nobody)
mkdir out && chown nobody out && chmod 777 .
# (a copy nobody can run: the build folder may lie under a home of mode 0700)
cp "$H" harness-nobody && chmod 755 harness-nobody
[ -e "/tmp/raybench-cache-$nuid" ] && had_tmp=1 || had_tmp=0
rm -f cache.log
setpriv --reuid=nobody --regid=nogroup --clear-groups env -u XDG_CACHE_HOME -u HOME \
    "$T/harness-nobody" run cd.conf -o out/out.csv -q 2> run.err || { cat run.err; fail "run as nobody"; }
GOT=$(cat cache.log)
case $GOT in
    "$T/out/raybench-cache-"??????) ;;
    *) fail "no home: cache '$GOT', expected $T/out/raybench-cache-XXXXXX" ;;
esac
[ "$(stat -c '%u %a' "$GOT")" = "$nuid 700" ] || fail "no home: $GOT: owner and mode $(stat -c '%u %a' "$GOT")"
[ $had_tmp = 1 ] || [ ! -e "/tmp/raybench-cache-$nuid" ] || fail "/tmp/raybench-cache-$nuid was made"
echo "cache folder test passed"
