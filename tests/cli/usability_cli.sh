#!/usr/bin/env bash
# What new users met at the command line (issue 41): `run -o out.vtu` writes a VTU (a
# .tets name, or -, a container); `info` knows a container by its magic number, whatever
# its name; a reader that closes the pipe (`| head`) ends `cat` and `run -o -` quietly
# with exit 0; `info` on a LAS file with a decimal scale says the rounding is the file's
# own quantisation; `field -o f.npy` writes f.density.npy, not f.npy.density.npy.
# Usage: bash usability_cli.sh /path/to/tetstream
set -uo pipefail
T=$(realpath "${1:?usage: usability_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }

"$T" -q gen --n 20000 --seed 4 -o p.f64 || fail "gen"
"$T" -q run p.f64 -o p.tets --no-checkpoint || fail "run p.tets"
tets=$("$T" -q --json info p.tets | json "d['tets']")

# ---- run -o NAME: the format the name asks for ----
j=$("$T" -q --json run p.f64 -o out.vtu --no-checkpoint) || fail "run -o out.vtu"
head -c 200 out.vtu | grep -q '<VTKFile type="UnstructuredGrid"' || fail "out.vtu is not a VTU: $(head -c 40 out.vtu | od -c | head -2)"
[ "$(echo "$j" | json "d['tets'], d['mesh']")" = "$tets out.vtu" ] || fail "--json of run -o out.vtu: $j"
[ "$(ls)" = "$(printf 'out.vtu\np.f64\np.tets')" ] || fail "run -o out.vtu left files: $(ls)"
# Its container's name is the job's own: a file of the user's already there is refused,
# neither replaced nor removed.
echo "the user's" >mine.vtu.tets
"$T" -q run p.f64 -o mine.vtu --no-checkpoint 2>refused.txt && fail "run -o mine.vtu replaced mine.vtu.tets"
[ "$(cat mine.vtu.tets)" = "the user's" ] || fail "mine.vtu.tets was overwritten"
grep -q "mine.vtu.tets exists" refused.txt || fail "the refusal does not name the file: $(cat refused.txt)"
[ ! -e mine.vtu ] || fail "a refused run wrote mine.vtu"
rm -f mine.vtu.tets refused.txt
if /usr/bin/python3 -c "import meshio" 2>/dev/null; then
  /usr/bin/python3 -c "import meshio, sys; m = meshio.read('out.vtu'); assert len(m.cells_dict['tetra']) == $tets, m" ||
    fail "meshio cannot read out.vtu"
fi
"$T" -q run p.f64 -o out.mesh --no-checkpoint || fail "run -o out.mesh"
head -1 out.mesh | grep -q MeshVersionFormatted || fail "out.mesh is not Medit"
# a .tets name and other names stay containers
"$T" -q run p.f64 -o other.dat --no-checkpoint || fail "run -o other.dat"
[ "$(head -c 5 other.dat | tail -c 4)" = TETS ] || fail "other.dat is not a container"
"$T" -q run p.f64 -o - --no-checkpoint > piped.tets || fail "run -o -"
cmp -s piped.tets p.tets || fail "run -o - differs from run -o p.tets"

# ---- info: a container by its magic, not its name ----
"$T" -q info other.dat > info.txt 2> err.txt || fail "info other.dat: $(cat err.txt)"
grep -q "^tets: *$tets" info.txt || fail "info other.dat: $(cat info.txt)"
cp p.tets noext
[ "$("$T" -q --json info noext | json "d['tets']")" = "$tets" ] || fail "info on a container without extension"
# a point file named .tets is still read as points
cp p.f64 fake.tets
"$T" -q info fake.tets --format f64 | grep -q '^points: *20000' || fail "info fake.tets --format f64"

# ---- a closed pipe ends a filter quietly, exit 0 ----
set -o pipefail
"$T" -q cat p.tets 2> err.txt | head -1 > /dev/null
rc=$?
[ "$rc" = 0 ] || fail "cat | head -1: exit $rc: $(cat err.txt)"
[ ! -s err.txt ] || fail "cat | head -1 printed: $(cat err.txt)"
"$T" -q cat p.tets --format u64 2> err.txt | head -c 10 > /dev/null || fail "cat --format u64 | head -c: $(cat err.txt)"
[ ! -s err.txt ] || fail "cat --format u64 | head -c printed: $(cat err.txt)"
"$T" -q cat p.tets --points 2> err.txt | head -2 > /dev/null || fail "cat --points | head: $(cat err.txt)"
"$T" -q run p.f64 -o - --no-checkpoint 2> err.txt | head -c 100 > /dev/null
rc=$?
[ "$rc" = 0 ] || fail "run -o - | head -c 100: exit $rc: $(cat err.txt)"
[ ! -s err.txt ] || fail "run -o - | head -c 100 printed: $(cat err.txt)"
[ -z "$(ls | grep -e partial -e ckpt -e '^tetstream-' || true)" ] || fail "files left behind: $(ls)"
set +o pipefail

# ---- info on a LAS tile with scale 0.01: the file's own quantisation, not an alarm ----
/usr/bin/python3 - <<'EOF' || fail "writing tile.las"
import struct
pts = [(i * 37 % 1000, i * 91 % 1000, i * 13 % 500) for i in range(3000)]
h = bytearray(227)
h[0:4] = b"LASF"; h[24] = 1; h[25] = 2
struct.pack_into("<HIIBHI", h, 94, 227, 227, 0, 0, 20, len(pts))
struct.pack_into("<6d", h, 131, 0.01, 0.01, 0.01, 500000.0, 4000000.0, 100.0)
with open("tile.las", "wb") as f:
    f.write(h)
    for p in pts:
        f.write(struct.pack("<3i8s", *p, b"\0" * 8))
EOF
"$T" -q info tile.las > info.txt || fail "info tile.las"
grep -q "^exact:" info.txt || fail "info tile.las: no exact line: $(cat info.txt)"
grep "^exact:" info.txt | grep -q "the file's own quantisation" || fail "info tile.las does not say why: $(cat info.txt)"
grep "^exact:" info.txt | grep -q "not damage" || fail "info tile.las reads as an alarm: $(cat info.txt)"

# ---- field -o f.npy: PREFIX without the extension ----
"$T" -q field p.tets -o f.npy --density dtfe --grid 4 > out.txt || fail "field -o f.npy"
[ -s f.density.npy ] && [ -s f.grid.npy ] || fail "field -o f.npy wrote: $(ls)"
ls | grep -q 'f\.npy\.' && fail "field -o f.npy wrote f.npy.*: $(ls)"
"$T" -q field p.tets -o g.density.npy --density dtfe > out.txt || fail "field -o g.density.npy"
[ -s g.density.npy ] && ! ls | grep -q 'g\.density\.density' || fail "field -o g.density.npy wrote: $(ls)"
echo "usability_cli: passed"
