#!/usr/bin/env bash
# Bad point input through the command line: exit 1 and ONE line naming the file and the
# byte (or line); usage errors exit 2; I/O failures exit 3; no output left looking complete.
# Usage: bash points_bad_input.sh /path/to/tetstream
set -uo pipefail
T=$(realpath "${1:?usage: points_bad_input.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }

# expect CODE PATTERN -- command...: exit status CODE, stderr one line matching PATTERN.
expect() {
  local code=$1 pattern=$2
  shift 3
  "$@" > out.txt 2> err.txt
  local rc=$?
  [ "$rc" = "$code" ] || fail "$* exited $rc, expected $code: $(cat err.txt)"
  [ "$(wc -l < err.txt)" = 1 ] || fail "$*: expected one line, got: $(cat err.txt)"
  grep -Eq -- "$pattern" err.txt || fail "$*: '$(cat err.txt)' does not match '$pattern'"
}

"$T" -q gen --n 10 --seed 1 -o ok.f64
head -c 100 ok.f64 > trunc.f64
expect 1 'trunc.f64: byte 96: truncated' -- "$T" -q info trunc.f64
head -c 100 ok.f64 | { expect 1 '<stdin>: byte 96: truncated' -- "$T" -q info - --format f64; }
printf '1 2 3\n4 5 nan\n' > nan.txt
expect 1 'nan.txt: line 2: non-finite coordinate' -- "$T" -q info nan.txt
printf '1 2 3\n4 5\n' > cols.txt
expect 1 'cols.txt: line 2: expected 3 coordinates' -- "$T" -q info cols.txt
printf 'x y z\n1 2 three\n' > word.csv
expect 1 'word.csv: line 2: not a number' -- "$T" -q info word.csv
printf 'ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty double x\nproperty double y\nproperty double z\nend_header\n' > lie.ply
head -c 240 ok.f64 >> lie.ply
expect 1 'lie.ply: byte [0-9]+: truncated: the header promises 1000 vertices' -- "$T" -q info lie.ply
printf 'not a ply\n' > magic.ply
expect 1 'magic.ply: byte 0: not a PLY file' -- "$T" -q info magic.ply
: > empty.npy
expect 1 'empty.npy: byte 0: empty file' -- "$T" -q info empty.npy
: > empty.txt
expect 1 'empty.txt: line 1: empty file' -- "$T" -q info empty.txt

# Usage errors: exit 2.
expect 2 'unknown distribution' -- "$T" -q gen --dist gaussian --n 10 -o x.f64
expect 2 'cannot tell the output format' -- "$T" -q gen --n 10 -o x.unknown
cp ok.f64 ok.dat
expect 2 'cannot tell the format of ok.dat' -- "$T" -q info ok.dat
expect 2 'duplicates' -- "$T" -q gen --n 10 --duplicates 1.5 -o x.f64
[ ! -e x.f64 ] && [ ! -e x.f64.partial ] || fail "output left after a usage error"

# I/O failures: exit 3.
expect 3 'cannot open' -- "$T" -q info missing.f64
expect 3 'cannot create' -- "$T" -q gen --n 10 -o no/such/dir/x.f64
# A full disk mid-write (a file size limit): no output, no partial file.
( ulimit -f 64; trap '' XFSZ; exec "$T" -q gen --n 1000000 -o big.f64 ) 2> err.txt
rc=$?
[ "$rc" = 3 ] || fail "file size limit: exit $rc: $(cat err.txt)"
[ ! -e big.f64 ] && [ ! -e big.f64.partial ] || fail "output left after a write failure"
echo "points_bad_input: ok"
