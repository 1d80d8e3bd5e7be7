#!/usr/bin/env bash
# LiDAR at read time and data on meshes: --las-classes and --las-returns keep
# the points asked for in every command that reads points (info counts them, run
# triangulates them), are part of the job (a resume with another filter is refused) and
# are refused on other formats; convert --point-data NAME=FILE.npy writes a user's
# per-point array, read back with meshio; convert --las-attributes carries intensity,
# classification, return number and GPS time from the LAS file by original id, and
# refuses a file that is gone or changed.
# Usage: bash las_filters_cli.sh /path/to/tetstream
set -uo pipefail
T=$(realpath "${1:?usage: las_filters_cli.sh /path/to/tetstream}")
# The checks read the meshes back with numpy and meshio: Debian's python3 has them
# (scripts/setup.sh), whatever python3 comes first on PATH.
python3() { "${TETSTREAM_PYTHON:-/usr/bin/python3}" "$@"; }
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
json() { python3 -c "import json, sys; print(json.load(sys.stdin)$1)"; }

# A LAS 1.2 point format 1 tile (with GPS time) of 400 points in general position; each
# point's class, returns, intensity and GPS time follow from its index (tile.py says how),
# so the checks below know which points a filter keeps. kept.py FILTER prints their indices.
cat > tile.py <<'PY'
import random, struct
random.seed(41)
n = 400
h = bytearray(227)
h[0:4] = b"LASF"; h[24] = 1; h[25] = 2
struct.pack_into("<HIIBHI", h, 94, 227, 227, 0, 1, 28, n)
struct.pack_into("<6d", h, 131, 0.01, 0.01, 0.01, 500000.0, 4000000.0, 100.0)
with open("tile.las", "wb") as f:
    f.write(h)
    for i in range(n):
        x, y, z = (random.randrange(0, 100000) for _ in range(3))
        nr = 1 + i % 3; rn = 1 + (i // 3) % nr
        cls = (2, 6, 1, 5)[i % 4]
        f.write(struct.pack("<3iHBBbBHd", x, y, z, 1000 + i, rn | nr << 3, cls, 0, 0, 0, 0.5 * i))
PY
cat > kept.py <<'PY'
import sys
classes = set(map(int, sys.argv[1].split(","))) if sys.argv[1] else None
returns = sys.argv[2]
for i in range(400):
    nr = 1 + i % 3; rn = 1 + (i // 3) % nr; cls = (2, 6, 1, 5)[i % 4]
    if classes is not None and cls not in classes: continue
    if returns == "last" and rn != nr: continue
    if returns == "first" and rn != 1: continue
    print(i)
PY
python3 tile.py || fail "tile.py"
count() { python3 kept.py "$1" "$2" | wc -l; }

# ---- info and run see the filtered points ----
[ "$("$T" -q --json info tile.las | json '["points"]')" = 400 ] || fail "info tile.las"
[ "$("$T" -q --json info tile.las --las-classes 2 | json '["points"]')" = "$(count 2 all)" ] || fail "info --las-classes 2"
[ "$("$T" -q --json info tile.las --las-returns last | json '["points"]')" = "$(count '' last)" ] || fail "info --las-returns last"
[ "$("$T" -q --json info tile.las --las-returns first | json '["points"]')" = "$(count '' first)" ] || fail "info --las-returns first"
"$T" -q info tile.las --las-classes 2,6 --las-returns last > info.txt || fail "info with both filters"
grep -q "las_classes=2,6 las_returns=last: $(count 2,6 last) of 400 points kept" info.txt || fail "info's filter line: $(cat info.txt)"
"$T" -q run tile.las --las-classes 2,6 --las-returns last -o g.tets --no-checkpoint || fail "run with filters"
[ "$("$T" -q --json info g.tets | json '["points"]')" = "$(count 2,6 last)" ] || fail "the container's points"
# The original ids number the kept points; their coordinates are those of kept.py's points.
"$T" -q cat g.tets --points --original-ids > pts.txt || fail "cat --points"
python3 - <<'PY' || fail "the kept points are not the filter's"
import struct, subprocess
data = open("tile.las", "rb").read()
kept = [int(l) for l in subprocess.run(["python3", "kept.py", "2,6", "last"], capture_output=True, text=True).stdout.split()]
seen = 0
for line in open("pts.txt"):
    f = line.split()
    if len(f) < 4: continue
    x, y, z, oid = float(f[0]), float(f[1]), float(f[2]), int(f[3])
    X, Y, Z = struct.unpack_from("<3i", data, 227 + 28 * kept[oid])
    assert abs(x - (X * 0.01 + 500000)) < 1e-6 and abs(z - (Z * 0.01 + 100)) < 1e-6, (line, kept[oid])
    seen += 1
assert seen == len(kept), (seen, len(kept))
PY

# ---- usage errors: one line, exit 2 ----
"$T" -q gen --n 100 --seed 1 -o a.f64
expect 2 'las-classes and --las-returns applies to LAS input only' -- "$T" -q info a.f64 --las-classes 2
expect 2 'las-classes and --las-returns applies to LAS input only' -- "$T" -q run a.f64 -o a.tets --las-returns last
expect 2 "--las-classes: '300' is not a classification code" -- "$T" -q info tile.las --las-classes 2,300
expect 2 "--las-returns: expected last, first or all" -- "$T" -q info tile.las --las-returns second
expect 1 'tile.las: none of its 400 points passes the filter \(las_classes=9\)' -- "$T" -q info tile.las --las-classes 9

# ---- the filters are part of the job: a resume with another filter is refused ----
TETSTREAM_FAULT=segment:0 "$T" -q run tile.las --las-classes 2 -o r.tets 2>/dev/null; rc=$?
[ "$rc" != 0 ] && [ -e r.tets.ckpt/state.json ] || fail "no checkpoint after an injected fault (exit $rc)"
expect 2 "cannot resume .*option 'read' .*las_classes=2.*las_classes=6" -- "$T" -q run tile.las --las-classes 6 -o r.tets --resume
expect 2 "cannot resume .*option 'read'" -- "$T" -q run tile.las -o r.tets --resume
"$T" -q run tile.las --las-classes 2 -o r.tets --resume || fail "resume with the same filter"
[ "$("$T" -q --json info r.tets | json '["points"]')" = "$(count 2 all)" ] || fail "resumed container's points"

# ---- convert --point-data ----
"$T" -q run tile.las -o all.tets --no-checkpoint || fail "run tile.las"
python3 -c "
import numpy as np
n = 400
np.save('h.npy', np.arange(n, dtype=np.float64) * 0.25)
np.save('k.npy', np.arange(n, dtype=np.int32) - 7)
np.save('f.npy', np.linspace(0, 1, n, dtype=np.float32))
np.save('short.npy', np.zeros(n - 1))
np.save('c.npy', np.zeros(n, dtype=np.complex128))
np.save('two.npy', np.zeros((n, 2)))
" || fail "numpy"
for ext in vtu vtk msh xdmf; do
  "$T" -q convert all.tets m.$ext --point-data h=h.npy --point-data k=k.npy --point-data f=f.npy || fail "convert .$ext --point-data"
  python3 - "m.$ext" <<'PY' || fail "meshio reads the point data of m.$ext"
import sys, meshio, numpy as np
m = meshio.read(sys.argv[1])
pd = m.point_data
for name in ("h", "k", "f"):
    assert name in pd, (sys.argv[1], list(pd))
want = {"h": np.arange(400) * 0.25, "k": np.arange(400) - 7.0, "f": np.linspace(0, 1, 400, dtype=np.float32).astype(float)}
for name, v in want.items():
    got = np.asarray(pd[name], dtype=float).reshape(-1)
    assert np.array_equal(got, v), (sys.argv[1], name, got[:5])
assert "original_id" in pd
PY
done
"$T" -q convert all.tets m.vtu --compress --point-data h=h.npy || fail "convert --compress --point-data"
python3 -c "import meshio, numpy as np; m = meshio.read('m.vtu'); assert np.array_equal(m.point_data['h'], np.arange(400) * 0.25)" || fail "compressed .vtu point data"
expect 1 'short.npy: byte [0-9]+: holds 399 values, the container has 400 points' -- "$T" -q convert all.tets s.vtu --point-data s=short.npy
expect 1 "c.npy: byte [0-9]+: dtype '<c16' is not one of" -- "$T" -q convert all.tets s.vtu --point-data s=c.npy
expect 1 'two.npy: byte [0-9]+: a 1-D array is needed' -- "$T" -q convert all.tets s.vtu --point-data s=two.npy
expect 2 'Medit \(.mesh\) has no place for point data' -- "$T" -q convert all.tets s.mesh --point-data h=h.npy
expect 2 'has no place for point data' -- "$T" -q convert all.tets s.node --point-data h=h.npy
expect 2 "--point-data 'h': expected NAME=FILE.npy" -- "$T" -q convert all.tets s.vtu --point-data h
expect 2 "point data name 'a b'" -- "$T" -q convert all.tets s.vtu --point-data "a b=h.npy"
expect 2 "point data name 'h' is given twice" -- "$T" -q convert all.tets s.vtu --point-data h=h.npy --point-data h=f.npy
ls s.* 2>/dev/null && fail "a refused convert left a file"

# ---- convert --las-attributes: by original id, through the container's filters ----
# (.vtu with 122 points: 8 + 8 * 122 bytes an array, a multiple of 3, so meshio's
# rewritten base64 offsets meet the raw ones; the writer's array order keeps it right.)
for ext in vtu vtk; do
"$T" -q convert g.tets g.$ext --las-attributes || fail "convert --las-attributes"
python3 - g.$ext <<'PY' || fail "the LAS attributes of g.$ext"
import subprocess, sys, meshio, numpy as np
kept = [int(l) for l in subprocess.run(["python3", "kept.py", "2,6", "last"], capture_output=True, text=True).stdout.split()]
assert len(kept) == 122
m = meshio.read(sys.argv[1])
pd = {k: np.asarray(v).reshape(-1) for k, v in m.point_data.items()}
orig = pd["original_id"]
i = np.array([kept[o] for o in orig])
assert np.array_equal(pd["intensity"], 1000 + i)
assert np.array_equal(pd["gps_time"], 0.5 * i)
assert np.array_equal(pd["classification"], np.array([(2, 6, 1, 5)[k % 4] for k in i]))
nr = 1 + i % 3
assert np.array_equal(pd["return_number"], 1 + (i // 3) % nr)
assert set(pd["classification"]) <= {2, 6} and np.array_equal(pd["return_number"], nr)
PY
done
python3 -c "import numpy as np; np.save('h2.npy', np.ones($(count 2,6 last)))"
"$T" -q convert g.tets g.xdmf --las-attributes --point-data h2=h2.npy || fail "convert .xdmf --las-attributes --point-data"
python3 -c "
import meshio; pd = meshio.read('g.xdmf').point_data
assert {'intensity', 'classification', 'return_number', 'gps_time', 'h2', 'original_id'} <= set(pd), list(pd)" ||
  fail "g.xdmf's point data"
# A file changed since (one coordinate moved), and one gone, are refused.
cp tile.las saved.las
python3 -c "
b = bytearray(open('tile.las', 'rb').read()); b[227 + 28 * $(python3 kept.py 2,6 last | sed -n 1p)] ^= 1; open('tile.las', 'wb').write(b)"
expect 1 'tile.las: changed since the container was made: point 0 .* is not where the container has it' -- "$T" -q convert g.tets c.vtu --las-attributes
mv saved.las tile.las
head -c $((227 + 28 * 200)) tile.las > short.las && mv tile.las saved.las && mv short.las tile.las
expect 1 'tile.las: ' -- "$T" -q convert g.tets c.vtu --las-attributes
rm tile.las
expect 1 "tile.las: the container's input is gone" -- "$T" -q convert g.tets c.vtu --las-attributes
mv saved.las tile.las
expect 1 'not a LAS file: --las-attributes needs a container made from LAS input' -- bash -c "\"$T\" -q run a.f64 -o b.tets --no-checkpoint && \"$T\" -q convert b.tets c.vtu --las-attributes"
ls c.vtu* 2>/dev/null && fail "a refused convert left a file"
echo "las_filters_cli: ok"
