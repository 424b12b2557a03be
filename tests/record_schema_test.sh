#!/bin/sh
# record_schema_test.sh CC RAYTRACE SRCDIR - the record line's keys are
# declared once, in include/raybench/record_schema.h; this checks the two
# copies that cannot include it:
#   - docs/record.md's key table: the header's rows, byte for byte and in
#     order (a failure prints the expected table, to paste in);
#   - raytrace's actual line on scenes/demo.txt (serial, and --calibrate):
#     no key that is not declared, every MAIN key, declaration order.
set -u
cc=$1 rt=$2 src=$3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

# the schema, through the C preprocessor: the table rows and "key who" lines
cat > "$tmp/schema.c" <<'C'
#include <stdio.h>
#include <string.h>
#include "raybench/record_schema.h"
#define ROW(key, type, unit, col_kind, column, who, doc) \
    printf("| `%s` | %s | %s | `%s` | %s |\n", #key, #type, unit, column, doc);
#define KEY(key, type, unit, col_kind, column, who, doc) printf("%s %s\n", #key, #who);
int main(int argc, char **argv)
{
    if (argc > 1 && strcmp(argv[1], "table") == 0) {
        RT_RECORD_KEYS(ROW)
    } else {
        RT_RECORD_KEYS(KEY)
    }
    return 0;
}
C
if ! "$cc" -std=c11 -pedantic-errors -Wall -Wextra -Werror -I"$src/include" "$tmp/schema.c" -o "$tmp/schema"; then
    echo "FAIL: include/raybench/record_schema.h does not compile"
    exit 1
fi
"$tmp/schema" table > "$tmp/table.want"
"$tmp/schema" keys > "$tmp/keys"
cut -d' ' -f1 "$tmp/keys" > "$tmp/keys.h"

# --- docs/record.md: the rows under its "| key | type | ..." header
awk 'on && !/^\|/ { exit } on && !/^\|---/ { print } /^\| key \| type \|/ { on = 1 }' \
    "$src/docs/record.md" > "$tmp/table.doc"
sed -n 's/^| `\([^`]*\)`.*/\1/p' "$tmp/table.doc" > "$tmp/keys.doc"
for k in $(cat "$tmp/keys.h"); do
    grep -qx "$k" "$tmp/keys.doc" || fail "key $k is declared in the header but not in docs/record.md's table"
done
for k in $(cat "$tmp/keys.doc"); do
    grep -qx "$k" "$tmp/keys.h" || fail "docs/record.md's table has $k, which the header does not declare"
done
if ! cmp -s "$tmp/table.want" "$tmp/table.doc"; then
    sort "$tmp/keys.h" > "$tmp/sorted.h"
    sort "$tmp/keys.doc" > "$tmp/sorted.doc"
    if cmp -s "$tmp/sorted.h" "$tmp/sorted.doc" && ! cmp -s "$tmp/keys.h" "$tmp/keys.doc"; then
        fail "docs/record.md's table has the keys in another order than the header"
    fi
    fail "docs/record.md's table differs from the header (- docs, + header):"
    diff -u "$tmp/table.doc" "$tmp/table.want" | sed -n '3,$p'
    echo "the header's table:"
    cat "$tmp/table.want"
fi

# --- raytrace's record line against the declared keys (serial adds none
# of its own)
check_record() { # NAME ARGS...: the record of raytrace ARGS
    name=$1
    shift
    if ! line=$("$rt" -q -b serial -o "$tmp/demo.png" "$@" "$src/scenes/demo.txt"); then
        fail "$name: raytrace failed"
        return
    fi
    case $line in "record: "*) ;; *) fail "$name: no record line: $line"; return ;; esac
    echo "$line" | tr ' ' '\n' | sed -n 's/=.*//p' > "$tmp/keys.rec"
    for k in $(cat "$tmp/keys.rec"); do
        grep -qx "$k" "$tmp/keys.h" || fail "$name: raytrace prints key $k, which the header does not declare"
    done
    for k in $(sed -n 's/ MAIN$//p' "$tmp/keys"); do
        grep -qx "$k" "$tmp/keys.rec" || fail "$name: raytrace does not print $k, declared MAIN (every record)"
    done
    grep -Fxf "$tmp/keys.h" "$tmp/keys.rec" > "$tmp/keys.declared"
    grep -Fxf "$tmp/keys.rec" "$tmp/keys.h" > "$tmp/keys.order"
    cmp -s "$tmp/keys.order" "$tmp/keys.declared" ||
        fail "$name: raytrace prints its keys in another order than declared: $line"
}
check_record serial
check_record serial-calibrate --calibrate
[ "$(tail -n 1 "$tmp/keys.rec")" = calib_ms ] ||
    fail "serial-calibrate: calib_ms (LAST) is not the last key with --calibrate"

echo "record_schema_test: $fails failures"
[ $fails -eq 0 ]
