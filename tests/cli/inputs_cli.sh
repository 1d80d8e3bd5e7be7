#!/usr/bin/env bash
# Inputs as users have them, through the command line: LAS (scale and offset; with three
# equal power-of-two scales the triangulation is exactly that of the integer points),
# LAZ refused with advice, wider text and npy (--columns), PLY X/Y/Z, several files as
# one input; and the safety fixes of issue #16: data after a header's count and a
# malformed first text line are errors (never dropped), an --offset that wraps is refused.
# Usage: bash inputs_cli.sh /path/to/tetstream
set -uo pipefail
T=$(realpath "${1:?usage: inputs_cli.sh /path/to/tetstream}")
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
# Tets as sorted vertex lists (original ids), one per line, sorted: comparable across runs.
tets() { "$T" -q cat "$1" --original-ids | perl -lane 'print join " ", sort { $a <=> $b } @F' | sort; }

# ---- LAS: a format-0 LAS 1.2 file of integer lattice points, written here ----
# las.py OUT SCALE OFFX OFFY OFFZ < "X Y Z" lines
cat > las.py <<'EOF'
import struct, sys
out, scale, ox, oy, oz = sys.argv[1], float(sys.argv[2]), *map(float, sys.argv[3:6])
pts = [tuple(map(int, l.split())) for l in sys.stdin if l.strip()]
h = bytearray(227)
h[0:4] = b"LASF"; h[24] = 1; h[25] = 2
struct.pack_into("<HIIBHI", h, 94, 227, 227, 0, 0, 20, len(pts))
struct.pack_into("<6d", h, 131, scale, scale, scale, ox, oy, oz)
with open(out, "wb") as f:
    f.write(h)
    for p in pts:
        f.write(struct.pack("<3i8s", *p, b"\xab" * 8))
EOF
# A 6x6x6 grid: every cube's 8 corners are cospherical, so the triangulation rests on the
# symbolic perturbation, and any rounding of the coordinates could change it.
for x in 0 1 2 3 4 5; do for y in 0 1 2 3 4 5; do for z in 0 1 2 3 4 5; do
  echo "$((x * 7 - 20)) $((y * 7 + 3)) $((z * 7))"; done; done; done > lattice.txt
python3 las.py exact.las 0.25 1000 -3.5 7 < lattice.txt || fail "las.py"
"$T" -q info exact.las > info.txt || fail "info exact.las: $(cat info.txt)"
grep -q '^format:  las 1.2 point format 0$' info.txt || fail "LAS format name: $(cat info.txt)"
grep -q '^points:  216$' info.txt || fail "LAS count: $(cat info.txt)"
grep -q '^x:       \[995, 1003.75\]$' info.txt || fail "LAS x = X * 0.25 + 1000: $(cat info.txt)"
grep -q '^exact:   yes' info.txt || fail "LAS exactness: $(cat info.txt)"
"$T" -q run exact.las -o las.tets --no-checkpoint || fail "run exact.las"
"$T" -q run lattice.txt -o int.tets --no-checkpoint || fail "run lattice.txt"
"$T" -q verify las.tets > /dev/null || fail "verify las.tets"
[ "$(tets las.tets | md5sum)" = "$(tets int.tets | md5sum)" ] || fail "LAS with exact scale 0.25: not the integer lattice's triangulation"
python3 las.py inexact.las 0.01 0.3 0 0 < lattice.txt
"$T" -q info inexact.las | grep -q '^exact:   no (' || fail "LAS with scale 0.01: conversion should be reported as rounded"

# LAZ: one line, exit 1, with the way out.
cp exact.las c.laz
expect 1 'c.laz: LAZ \(compressed LAS\) needs LASzip, which Debian does not ship: decompress it first' -- "$T" -q info c.laz
python3 - <<'EOF'
b = bytearray(open("exact.las", "rb").read()); b[104] |= 0x80; open("c.las", "wb").write(b)
EOF
expect 1 'c.las: byte 104: LAZ' -- "$T" -q run c.las -o c.tets
[ ! -e c.tets ] || fail "output left after a LAZ error"

# ---- wider text and npy, PLY X/Y/Z ----
awk '{ print NR ",pt" NR "," $1 "," $2 "," $3 ",0.5" }' lattice.txt | sed '1i id,name,x,y,z,i' > wide.csv
"$T" -q run wide.csv --columns 3,4,5 -o wide.tets --no-checkpoint || fail "run --columns"
[ "$(tets wide.tets | md5sum)" = "$(tets int.tets | md5sum)" ] || fail "--columns 3,4,5 read other points"
expect 1 'wide.csv: line 2: not a number' -- "$T" -q info wide.csv
expect 2 'columns' -- "$T" -q info wide.csv --columns 3,4
expect 2 '--columns applies to text and npy' -- "$T" -q info exact.las --columns 1,2,3
python3 -c "
import numpy as np
a = np.loadtxt('lattice.txt'); np.save('wide.npy', np.c_[np.zeros(len(a)), a, np.ones(len(a))])" \
  2>/dev/null || /usr/bin/python3 -c "
import numpy as np
a = np.loadtxt('lattice.txt'); np.save('wide.npy', np.c_[np.zeros(len(a)), a, np.ones(len(a))])"
"$T" -q info wide.npy --columns 2,3,4 | grep -q '^points:  216$' || fail "npy --columns"
expect 1 'wide.npy: byte 10: shape \(216, 5\) is not \(N, 3\) \(choose three columns with --columns\)' -- "$T" -q info wide.npy
{ printf 'ply\nformat ascii 1.0\nelement vertex 216\nproperty float X\nproperty float Y\nproperty float Z\nend_header\n'
  cat lattice.txt; } > upper.ply
"$T" -q info upper.ply | grep -q '^points:  216$' || fail "PLY with X/Y/Z"
"$T" -q info upper.ply --properties Z,Y,X | grep -q '^x:       \[0, 35\]$' || fail "--properties Z,Y,X"

# ---- several files are one input, in the order given ----
head -100 lattice.txt > a.txt; tail -n +101 lattice.txt > b.txt
"$T" -q run a.txt b.txt -o ab.tets --no-checkpoint || fail "run a.txt b.txt"
[ "$("$T" -q cat ab.tets --original-ids | md5sum)" = "$("$T" -q cat int.tets --original-ids | md5sum)" ] \
  || fail "two files are not the same input as their concatenation"
expect 3 'cannot open nothing\*.txt: no file matches' -- "$T" -q info 'nothing*.txt'

# ---- issue #16 defect 8: nothing after a header's count is dropped silently ----
"$T" -q gen --n 10 --seed 1 -o ten.f64
printf 'ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty double x\nproperty double y\nproperty double z\nend_header\n' > eight.ply
hdr=$(stat -c %s eight.ply)
cat ten.f64 >> eight.ply
expect 1 "eight.ply: byte $((hdr + 192)): 48 bytes of trailing data after the 8 vertices the header declares" -- "$T" -q info eight.ply
cat eight.ply | { expect 1 "<stdin>: byte $((hdr + 192)): trailing data after the 8 vertices" -- "$T" -q info -; }
expect 1 'eight.ply: byte' -- "$T" -q run eight.ply -o e.tets
[ ! -e e.tets ] || fail "output left after trailing data"
for bad in 1e5x 1.2.3 12abc --1 1e 0x1p0; do
  printf '%s 2 3\n4 5 6\n7 8 9\n1 1 1\n' "$bad" > first.txt
  expect 1 "first.txt: line 1: not a number: '$bad'" -- "$T" -q info first.txt
done
printf 'x y z\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n' > header.txt
"$T" -q info header.txt | grep -q '^points:  4$' || fail "a header of names is still skipped"

# ---- issue #16 defect 9: reader options validated without wrapping ----
expect 2 '--offset 18446744073709551608 \+ 3 coordinates of 8 bytes do not fit in a record of --stride 24' -- \
  "$T" -q info ten.f64 --stride 24 --offset 18446744073709551608
expect 2 'do not fit' -- "$T" -q run ten.f64 -o w.tets --stride 24 --offset 18446744073709551608
expect 2 'do not fit' -- "$T" -q info ten.f64 --offset 18446744073709551608
expect 2 'larger than the largest record' -- "$T" -q info - --format f64 --stride 18446744073709551615 < ten.f64
[ ! -e w.tets ] || fail "output left after a usage error"
echo "inputs_cli: ok"
