#!/usr/bin/env bash
# `tetstream run --periodic` as a user runs it (docs/periodic.md): the periodic job, its
# `verify`, `field` (DTFE with no NaN, sums), `convert` (images marked), the same bytes
# on 1 and 2 threads, a point outside the box wrapped or refused, `info` and `cat` of
# it, a stream reader's refusal, bad options.
# Usage: bash periodic_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: periodic_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }

"$T" -q gen --dist uniform --n 5000 --seed 4 -o u.f64
"$T" -q --threads 1 run u.f64 -o one.tets --periodic 1 --segment-points 500
"$T" -q --threads 2 run u.f64 -o two.tets --periodic 1 --segment-points 500
cmp -s one.tets two.tets || fail "1 and 2 threads differ"
"$T" -q verify one.tets > v.txt || fail "verify: $(cat v.txt)"
grep -q "periodic, .* V-E+F-T = .* = 0, .*: OK" v.txt || fail "verify summary: $(cat v.txt)"
[ "$(ls -A | grep -c tetstream-)" = 0 ] || fail "work files left: $(ls)"

# The fields: every point a density, none NaN, the sums.
j=$("$T" -q --json field one.tets -o f --density dtfe --voronoi-volume --grid 16)
[ "$(echo "$j" | json "d['nan_points'], d['nan_cells'], abs(d['mass_check'] - 5000) < 1e-12 * 5000, abs(d['voronoi_sum'] - 1) < 1e-9")" = \
  "0 0 True True" ] || fail "field: $j"
python3 - <<'PY' || fail "field arrays"
import math, struct
def load(path):  # a little-endian float64 .npy, without numpy
    b = open(path, 'rb').read()
    hl = b[8] | b[9] << 8
    data = b[10 + hl:]
    return struct.unpack('<%dd' % (len(data) // 8), data)
r, g, v = load('f.density.npy'), load('f.grid.npy'), load('f.voronoi.npy')
assert len(r) == 5000 and all(math.isfinite(x) and x > 0 for x in r)
assert len(g) == 16 ** 3 and all(math.isfinite(x) for x in g)
assert abs(math.fsum(v) - 1) < 1e-9, math.fsum(v)
PY

# convert: the tets unwrapped, the images marked.
"$T" -q convert one.tets one.vtu
grep -q 'Name="image"' one.vtu || fail "convert: no image field"

# Outside the box: wrapped by default, refused on request.
python3 - <<'PY'
import struct
p = list(struct.unpack('<15000d', open('u.f64', 'rb').read()))
for i in range(0, 5000, 7):
    p[3 * i] += 1.0
for i in range(1, 5000, 7):
    p[3 * i + 1] -= 3.0
open('shifted.f64', 'wb').write(struct.pack('<15000d', *p))
PY
"$T" -q run shifted.f64 -o w.tets --periodic 1 || fail "wrap"
"$T" -q verify w.tets > /dev/null || fail "verify wrapped"
set +e
"$T" -q run shifted.f64 -o r.tets --periodic 1 --periodic-outside refuse 2> err.txt; rc=$?
set -e
[ $rc = 1 ] && grep -q "shifted.f64: byte .*: x = .* lies outside \[0, 1)" err.txt || fail "refuse: rc $rc $(cat err.txt)"
[ ! -e r.tets ] && [ ! -e r.tets.partial ] || fail "a refused job left files"

# info and cat read a periodic container: its box, and each tet with its offsets.
"$T" -q --json info --check one.tets > info.json
[ "$(json "d['periodic']['period'], d['tets']" < info.json)" = "[1.0, 1.0, 1.0] $(json "d['tets']" < info.json)" ] ||
  fail "info: $(cat info.json)"
"$T" info one.tets | grep -q "^periodic: the flat torus \[0, 1) x \[0, 1) x \[0, 1)" || fail "info text: $("$T" info one.tets)"
"$T" cat one.tets > cat.txt
python3 - "$(json "d['tets']" < info.json)" <<'PY' || fail "cat of a periodic file"
import sys
rows = [list(map(int, l.split())) for l in open('cat.txt')]
assert len(rows) == int(sys.argv[1]), (len(rows), sys.argv[1])
assert all(len(r) == 13 and r[0] < min(r[1:4]) for r in rows), rows[:3]  # stored: smallest label first
assert all(o in (-1, 0, 1) for r in rows for o in r[4:])
assert any(o != 0 for r in rows for o in r[4:])  # some tets cross a face
assert len({tuple(r) for r in rows}) == len(rows)
PY
set +e
"$T" -q cat --format u32 one.tets > /dev/null 2> err.txt; rc=$?
set -e
[ $rc = 2 ] && grep -q "periodic" err.txt || fail "cat --format u32 of a periodic file: rc $rc $(cat err.txt)"
# A reader that does not know periodic containers (a stream, `cat -`) refuses in one line.
set +e
"$T" -q cat - < one.tets > /dev/null 2> err.txt; rc=$?
set -e
[ $rc = 1 ] && grep -q "critical section PBOX" err.txt || fail "cat - of a periodic file: rc $rc $(cat err.txt)"

# Bad options: exit 2.
set +e
"$T" -q run u.f64 -o x.tets --periodic 0 2> err.txt; rc=$?
set -e
[ $rc = 2 ] || fail "--periodic 0: rc $rc $(cat err.txt)"

# A budget the padded job cannot hold: the refusal names the user's --memory (not the
# share the padded job plans in beside the keep's tables), asks for more than it, and
# says once where the work is kept (the job's checkpoint, not the one nested in it).
"$T" -q gen --dist uniform --n 1000000 --seed 4 -o big.f64
set +e
"$T" -q run big.f64 -o small.tets --periodic 1 --memory 50M 2> err.txt; rc=$?
set -e
[ $rc = 2 ] && grep -q "^tetstream: error: --memory 50.0 MiB is too small for this input (1000000 points and [0-9]* images)" err.txt ||
  fail "a small budget: rc $rc $(cat err.txt)"
need=$(sed -n 's/.*use --memory \([0-9]*\)M or more.*/\1/p' err.txt)
[ -n "$need" ] && [ "$need" -gt 50 ] || fail "the budget asked for: $(cat err.txt)"
[ "$(grep -o "the work so far is kept in [^:]*" err.txt)" = "the work so far is kept in ./small.tets.ckpt" ] ||
  fail "where the work is kept: $(cat err.txt)"
[ "$(wc -l < err.txt)" = 1 ] || fail "more than the error line: $(cat err.txt)"
[ ! -e small.tets ] && [ ! -e small.tets.partial ] || fail "a refused job left an output: $(ls)"

# Above the budget it asks for, the job runs and --memory is its ceiling: each phase of
# the ledger within it, the padded job's writer share holding the keep's frames, and the
# peak resident set under it. At 68M the keep's frames (those of the user's budget) are
# twice the size the padded job's smaller budget gives: there the share was planned for
# the smaller ones and the peak went 2% over, which the share's check catches whatever
# the machine's page cache does to the peak.
[ "$need" -le 68 ] || fail "the budget asked for grew past 68M: $need"
python3 - "$T" 68 <<'PY' || fail "the job at --memory 68M"
import json, resource, subprocess, sys
t, budget = sys.argv[1], int(sys.argv[2])
run = subprocess.run([t, "-q", "--json", "run", "big.f64", "-o", "fit.tets", "--periodic", "1",
                      "--memory", f"{budget}M", "--no-checkpoint"], capture_output=True, text=True)
assert run.returncode == 0, run.stderr
s = json.loads(run.stdout)
plan = s["memory_planned"]
ceiling = plan["ceiling"]
assert ceiling == budget << 20, plan
for phase in ("sort", "triangulate", "keep"):
    assert sum(plan[phase].values()) <= ceiling, (phase, plan[phase])
frame_tets = 4096  # MemoryBudget::frame_tets_for the user's budget
while frame_tets < 1 << 18 and 2 * frame_tets <= ceiling // 1024:
    frame_tets *= 2
# One encoder: three frames alive (filled, queued, encoded) of 32 bytes a tet, and the
# encoder's scratch of 40 (MemoryBudget::writer_bytes_for, less its 5% and the file buffer).
frames = (3 * 32 + 40) * frame_tets
assert plan["triangulate"]["writer"] >= frames, (plan["triangulate"], frame_tets)
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
assert peak <= ceiling, f"peak {peak} over --memory {ceiling}"
print(f"periodic_cli: at --memory {budget}M the peak is {peak / 2**20:.1f} MiB")
PY
rm -f fit.tets
echo "periodic_cli: ok"
