#!/usr/bin/env bash
# `tetstream field` as a user runs it: the output files appear (and nothing else), --json
# summarises, --mass scales the density, --dtype float32 halves the files, --memory and
# --threads do not change a byte; bad options exit 2, a missing file 3, a damaged
# container or mass file 1, each with a one-line error and no output file left.
# Usage: bash field_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: field_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }
expect_exit() {  # CODE CMD...: runs CMD, checks its exit status and a one-line error
  local code=$1; shift
  set +e; "$@" > out.txt 2> err.txt; local rc=$?; set -e
  [ "$rc" = "$code" ] || fail "$* exited $rc, expected $code: $(cat err.txt)"
  [ "$(grep -c . err.txt)" = 1 ] || fail "$*: not a one-line error: $(cat err.txt)"
}

"$T" -q gen --dist clusters --n 20000 --seed 5 -o c.f64
"$T" -q run c.f64 -o c.tets --no-checkpoint

# All outputs, with --json: the files exist, the summary says what was done.
j=$("$T" -q --json field c.tets -o f --density dtfe --voronoi-volume --neighbours --grid 16,8,4)
# The job's work directory (and the grid's scratch file in it) is gone afterwards.
ls -d tetstream-field-* 2>/dev/null && fail "field left its work directory: $(ls tetstream-field-*)"
for f in f.density.npy f.voronoi.npy f.neighbours.offsets.npy f.neighbours.indices.npy f.grid.npy; do
  [ -s "$f" ] || fail "$f not written"
done
[ -z "$(ls | grep partial || true)" ] || fail "partial files left: $(ls)"
[ "$(echo "$j" | json "d['command'], d['points'], d['tets'] > 0, d['grid_points'], 0 < d['grid_inside'] <= 512")" = \
  "field 20000 True 512 True" ] || fail "--json: $j"
# Every tet's Voronoi pieces tile it: the pieces of all points add up to the hull's volume.
echo "$j" | json "abs(d['voronoi_total_with_hull_pieces'] - d['hull_volume']) <= 1e-9 * d['hull_volume']" | grep -q True \
  || fail "Voronoi pieces do not add up to the hull volume: $j"
# float64 arrays of 20000 points: 8 bytes each after a 128-byte header; the neighbour
# arrays int32 (every offset and index fits), offsets N+1 of them.
[ "$(stat -c %s f.density.npy)" = $((128 + 8 * 20000)) ] || fail "density size $(stat -c %s f.density.npy)"
[ "$(stat -c %s f.neighbours.offsets.npy)" = $((128 + 4 * 20001)) ] || fail "offsets size"
[ "$(stat -c %s f.grid.npy)" = $((128 + 8 * 512)) ] || fail "grid size"
entries=$(echo "$j" | json "d['neighbour_entries']")
[ "$(stat -c %s f.neighbours.indices.npy)" = $((128 + 4 * entries)) ] || fail "indices size"
[ "$(echo "$j" | json "d['neighbour_dtype']")" = int32 ] || fail "neighbour_dtype: $j"
grep -q "'descr': '<i4'" f.neighbours.indices.npy || fail "indices are not <i4"
# --index-dtype int64: int64 arrays of the same values; anything else is refused.
j64=$("$T" -q --json field c.tets -o w --neighbours --index-dtype int64)
[ "$(echo "$j64" | json "d['neighbour_dtype']")" = int64 ] || fail "--index-dtype int64: $j64"
[ "$(stat -c %s w.neighbours.indices.npy)" = $((128 + 8 * entries)) ] || fail "int64 indices size"
python3 - <<'PY' || fail "int32 and int64 neighbour arrays differ"
import struct
def load(path):
    b = open(path, 'rb').read()
    hl = b[8] | b[9] << 8
    code = 'i' if "'<i4'" in b[10:10 + hl].decode() else 'q'
    data = b[10 + hl:]
    return list(struct.unpack('<%d%s' % (len(data) // struct.calcsize(code), code), data))
for w in ('offsets', 'indices'):
    assert load('f.neighbours.%s.npy' % w) == load('w.neighbours.%s.npy' % w), w
PY
"$T" -q field c.tets -o x --neighbours --index-dtype int16 2> err.txt && fail "--index-dtype int16 accepted"
grep -q "index-dtype" err.txt || fail "--index-dtype int16: $(cat err.txt)"

# Without --json: the paths written, one a line.
"$T" -q field c.tets -o g --density dtfe > paths.txt
[ "$(cat paths.txt)" = "g.density.npy" ] || fail "plain output: $(cat paths.txt)"

# --memory and --threads change no byte.
"$T" -q --threads 1 field c.tets -o m1 --density dtfe --voronoi-volume --neighbours --grid 16 --memory 128M > /dev/null
"$T" -q --threads 2 field c.tets -o m2 --density dtfe --voronoi-volume --neighbours --grid 16 --memory 2G > /dev/null
for w in density voronoi neighbours.offsets neighbours.indices grid; do
  cmp -s "m1.$w.npy" "m2.$w.npy" || fail "$w differs between --memory 128M --threads 1 and 2G --threads 2"
done

# The same points in container version 1 (`run --labels sorted`; c.tets is version 2):
# the same fields by original index, to rounding (the sums run in other orders), the
# grid's NaN (outside the hull) at the same places, the same neighbours. The grid's
# planes retire brick by brick in version 2: 300,000 points at --memory 64M are read in
# 8 batches.
"$T" -q gen --dist clusters --n 300000 --seed 5 -o big.f64
"$T" -q run big.f64 -o v2.tets --no-checkpoint
"$T" -q run big.f64 -o v1.tets --no-checkpoint --labels sorted
"$T" info v1.tets | grep -q "container 1.0" || fail "v1.tets is not version 1"
"$T" info v2.tets | grep -q "container 2.0" || fail "v2.tets is not version 2"
for v in v1 v2; do
  b=$("$T" -q --json field $v.tets -o $v --density dtfe --neighbours --grid 32,24,16 --memory 64M | json "d['batches']")
  [ "$b" -ge 4 ] || fail "$v: the grid in $b batches"
done
python3 - <<'PY' || fail "versions 1 and 2 give other fields"
import math, struct
def load(path):
    b = open(path, 'rb').read()
    hl = b[8] | b[9] << 8
    code = {"'<f8'": 'd', "'<i4'": 'i', "'<i8'": 'q'}[[c for c in ("'<f8'", "'<i4'", "'<i8'") if c in b[10:10 + hl].decode()][0]]
    data = b[10 + hl:]
    return list(struct.unpack('<%d%s' % (len(data) // struct.calcsize(code), code), data))
for w in ('density', 'grid'):
    a, b = load('v1.%s.npy' % w), load('v2.%s.npy' % w)
    assert len(a) == len(b), w
    for x, y in zip(a, b):
        assert (math.isnan(x) and math.isnan(y)) or abs(x - y) <= 1e-9 * max(abs(x), abs(y)), (w, x, y)
    assert sum(not math.isnan(x) for x in a) > 0, w
def rows(stem):
    o, i = load(stem + '.neighbours.offsets.npy'), load(stem + '.neighbours.indices.npy')
    return [sorted(i[o[k]:o[k + 1]]) for k in range(len(o) - 1)]
assert rows('v1') == rows('v2'), 'neighbours'
PY

# --mass (raw float64, 2 everywhere) doubles the density; --dtype float32 halves the file.
python3 -c "import struct; open('mass.f64','wb').write(struct.pack('<20000d', *([2.0]*20000)))"
"$T" -q field c.tets -o h --density dtfe --mass mass.f64 --hull open > /dev/null
"$T" -q field c.tets -o o --density dtfe --hull open > /dev/null
python3 - <<'PY' || fail "--mass 2 does not double the density"
import struct
def load(p):
    b = open(p, 'rb').read()
    return struct.unpack('<%dd' % ((len(b) - 128) // 8), b[128:])
h, o = load('h.density.npy'), load('o.density.npy')
assert len(h) == 20000 and all(a == 2 * b for a, b in zip(h, o)), (h[:3], o[:3])
PY
"$T" -q field c.tets -o s --density dtfe --dtype float32 > /dev/null
[ "$(stat -c %s s.density.npy)" = $((128 + 4 * 20000)) ] || fail "float32 size $(stat -c %s s.density.npy)"

# Bad options: exit 2.
expect_exit 2 "$T" -q field c.tets -o x
expect_exit 2 "$T" -q field c.tets -o x --density sph
expect_exit 2 "$T" -q field c.tets -o x --grid 0
expect_exit 2 "$T" -q field c.tets -o x --grid 4,4
expect_exit 2 "$T" -q field c.tets -o x --grid 8 --box 0,0,0,1,1
expect_exit 2 "$T" -q field c.tets -o x --grid 8 --box 0,0,0,1,0,1
expect_exit 2 "$T" -q field c.tets -o x --density dtfe --hull closed
expect_exit 2 "$T" -q field c.tets -o x --density dtfe --dtype int8
expect_exit 2 "$T" -q field c.tets -o x --density dtfe --memory 1M
# A missing container: exit 3 (cannot open), naming it.
expect_exit 3 "$T" -q field nothere.tets -o x --density dtfe
grep -q "nothere.tets" err.txt || fail "missing file not named: $(cat err.txt)"
# A damaged container: exit 1, naming the file.
head -c 200000 c.tets > cut.tets
expect_exit 1 "$T" -q field cut.tets -o x --density dtfe
grep -q "cut.tets" err.txt || fail "damaged file not named: $(cat err.txt)"
# A mass file of the wrong length, or with a negative mass: exit 1, no output left.
head -c 800 mass.f64 > short.f64
expect_exit 1 "$T" -q field c.tets -o x --density dtfe --mass short.f64
python3 -c "import struct; open('neg.f64','wb').write(struct.pack('<20000d', *([1.0]*19999 + [-1.0])))"
expect_exit 1 "$T" -q field c.tets -o x --density dtfe --mass neg.f64
grep -q "neg.f64: byte 159992" err.txt || fail "bad mass not located: $(cat err.txt)"
[ -z "$(ls x.* 2>/dev/null || true)" ] || fail "output left after a failure: $(ls x.*)"
echo "field CLI OK"
