#!/usr/bin/env bash
# `tetstream gen` and `tetstream info` as a user runs them: the README spellings, every
# output format read back, stdin, --json, and output independent of threads and chunks.
# Usage: bash point_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: point_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }

# The contract spellings.
"$T" -q gen --dist uniform --n 100000 --seed 7 -o points.f64
[ "$(stat -c %s points.f64)" = 2400000 ] || fail "points.f64 size"
[ ! -e points.f64.partial ] || fail "partial file left behind"
"$T" info points.f64 > info.txt 2>/dev/null
grep -q '^points:  100000$' info.txt || fail "info count: $(cat info.txt)"
grep -q '^format:  raw f64 little-endian$' info.txt || fail "info format"
grep -q '^x: *\[' info.txt || fail "info bbox"

# --json summaries.
g=$("$T" -q --json gen --dist ball --n 5000 --seed 3 -o ball.ply)
[ "$(echo "$g" | json "d['points'], d['format'], d['bytes'] > 0, 'seconds' in d")" = "5000 ply binary_little_endian True True" ] \
  || fail "gen --json: $g"
i=$("$T" -q info ball.ply --json)
[ "$(echo "$i" | json "d['points'], d['format'], all(-1 <= v <= 1 for v in d['bbox']['min'] + d['bbox']['max'])")" = \
  "5000 ply binary_little_endian True" ] || fail "info --json: $i"

# Same points whatever the threads and chunk size.
"$T" -q --threads 1 gen --dist mixed --n 30000 --seed 9 --chunk 777 -o a.f64
"$T" -q --threads 2 gen --dist mixed --n 30000 --seed 9 -o b.f64
cmp -s a.f64 b.f64 || fail "output depends on threads or chunking"
"$T" -q gen --dist mixed --n 30000 --seed 10 -o c.f64
! cmp -s a.f64 c.f64 || fail "seed ignored"

# Every distribution and output format reads back with the same count and bounding box
# (printed with the shortest round-trip digits, so equal text means equal doubles).
for dist in uniform ball ellipsoid-shell mixed clusters grid sphere; do
  ref=""
  for out in p.f64 p.ply p.npy p.txt p.csv p.xyz; do
    "$T" -q gen --dist "$dist" --n 1000 --seed 5 --duplicates 0.1 -o "$out"
    s=$("$T" -q info "$out" | grep -E '^(points|x|y|z):')
    [ -z "$ref" ] && ref=$s
    [ "$s" = "$ref" ] || fail "$dist $out: $s vs $ref"
  done
  "$T" -q gen --dist "$dist" --n 1000 --seed 5 --duplicates 0.1 --ascii -o q.ply
  [ "$("$T" -q info q.ply | grep -E '^(points|x|y|z):')" = "$ref" ] || fail "$dist ascii ply"
done
"$T" -q gen --dist grid --n 1100 -o g.f64
[ "$("$T" -q --json info g.f64 | json "d['points']")" = 1000 ] || fail "grid rounds to k^3"

# Big-endian and float32 outputs, read with the raw options.
"$T" -q gen --n 1000 --seed 1 -o be.f64 --byte-order big
"$T" -q gen --n 1000 --seed 1 -o le.f64
"$T" -q gen --n 1000 --seed 1 -o le.f32
[ "$("$T" -q --json info be.f64 --byte-order big | json "d['bbox']")" = "$("$T" -q --json info le.f64 | json "d['bbox']")" ] \
  || fail "big-endian raw"
[ "$("$T" -q --json info le.f32 | json "d['points'], d['format']")" = "1000 raw f32 little-endian" ] || fail "f32"

# stdin: raw needs --format, PLY/npy/text are recognised.
[ "$(cat points.f64 | "$T" -q --json info - --format f64 | json "d['points'], d['file']")" = "100000 <stdin>" ] \
  || fail "raw stdin"
for f in ball.ply p.npy p.txt; do
  [ "$(cat "$f" | "$T" -q --json info - | json "d['points'] > 0")" = True ] || fail "stdin $f"
done
# gen to stdout, piped into info.
[ "$("$T" -q gen --n 5000 --seed 7 --format f64 -o - | "$T" -q --json info - --format f64 | json "d['points']")" = 5000 ] \
  || fail "gen | info"
"$T" -q gen --n 5000 --seed 7 --format ply -o - > piped.ply
"$T" -q gen --n 5000 --seed 7 -o file.ply
cmp -s piped.ply file.ply || fail "stdout PLY differs from file PLY"

# Unrecognised bytes on stdin: refused without a format, raw with a named type.
"$T" -q gen --dist uniform --n 100 --seed 3 -o raw100.f64
"$T" -q run - -o nofmt.tets --no-checkpoint <raw100.f64 2>err.txt && fail "raw stdin without --format or --type was accepted"
grep -q "cannot tell the format" err.txt || fail "raw stdin without a format: $(cat err.txt)"
"$T" -q run - --type f64 -o typed.tets --no-checkpoint <raw100.f64 || fail "raw stdin with --type f64 refused"
"$T" -q run raw100.f64 -o file.tets --no-checkpoint
cmp -s <("$T" -q cat typed.tets) <("$T" -q cat file.tets) || fail "stdin --type f64 gives other tets than the file"

# Help documents the distributions and the exit codes.
# (Captured first: `grep -q` may close the pipe before a long help is written, and
# the tool then dies of SIGPIPE like any other, which pipefail reports.)
"$T" gen --help >help.txt && grep -q 'ellipsoid-shell  area-uniform' help.txt || fail "gen --help"
grep -q 'terrain          (alias lidar)' help.txt || fail "gen --help lacks terrain"
"$T" --help >help.txt && grep -q '1  bad input' help.txt || fail "exit codes in --help"
echo "point_cli: ok"
