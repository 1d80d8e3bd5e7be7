#!/usr/bin/env bash
# `tetstream verify` as a user runs it: valid outputs of `run` pass (exit 0) on regular
# and degenerate inputs, --json and --sample, a damaged file and a container whose
# points do not match its tets fail with exit status 1, bad options with 2.
# Usage: bash verify_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: verify_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }

# Valid outputs pass, including a degenerate grid and cospherical points.
for dist in uniform grid sphere clusters; do
  "$T" -q gen --dist "$dist" --n 20000 --seed 4 -o "$dist.f64"
  "$T" -q run "$dist.f64" -o "$dist.tets"
  "$T" -q verify "$dist.tets" > out.txt || fail "verify $dist: $(cat out.txt)"
  grep -q "VALID: .* are the Delaunay triangulation of the points" out.txt || fail "verify $dist summary: $(cat out.txt)"
done

# --json: a summary object on stdout, nothing else.
j=$("$T" -q --json verify uniform.tets)
[ "$(echo "$j" | json "d['valid'], d['violations'], d['euler'], d['hull']['euler'], d['tets'] > 0")" = \
  "True 0 1 2 True" ] || fail "verify --json: $j"

# --sample: a quick look, seeded.
s1=$("$T" -q --json verify uniform.tets --sample 0.1 --seed 3)
s2=$("$T" -q --json verify uniform.tets --sample 0.1 --seed 3)
[ "$(echo "$s1" | json "d['valid'], d['sampled'], 0.05 < d['checked']['tets'] / d['tets'] < 0.15")" = "True True True" ] \
  || fail "verify --sample: $s1"
[ "$(echo "$s1" | json "d['checked']")" = "$(echo "$s2" | json "d['checked']")" ] || fail "sample not reproducible"

# A small budget and an explicit tmpdir: same answer, no temporary files left.
mkdir tmp
"$T" -q --json verify clusters.tets --memory 16M --tmpdir tmp > small.json || fail "verify --memory 16M"
[ "$(json "d['valid']" < small.json)" = "True" ] || fail "small budget: $(cat small.json)"
[ -z "$(ls -A tmp)" ] || fail "temporary files left in tmp: $(ls tmp)"

# --memory is verify's ceiling: 10^6 points written in small frames (run at 48M), so
# that the points, not one frame's records, are most of the plan; at 80M the peak
# resident set (getrusage of the child) stays under it. Before the points' checksum
# handed its pages back and the points were loaded in small chunks, this peaked at
# 87 MiB: the mapped section and two 24 MiB chunks beside the 23 MiB coordinates.
"$T" -q gen --dist uniform --n 1000000 --seed 4 -o million.f64
"$T" -q run million.f64 -o million.tets --memory 48M --no-checkpoint
python3 - "$T" <<'PY' || fail "verify at --memory 80M"
import json, resource, subprocess, sys
run = subprocess.run([sys.argv[1], "-q", "--json", "verify", "million.tets", "--memory", "80M"],
                     capture_output=True, text=True)
assert run.returncode == 0 and json.loads(run.stdout)["valid"], run.stdout + run.stderr
assert run.stderr == "", run.stderr  # no warning: the plan fits
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
assert peak <= 80 << 20, f"peak {peak / 2**20:.1f} MiB over --memory 80M"
print(f"verify_cli: at --memory 80M the peak is {peak / 2**20:.1f} MiB")
PY
rm million.f64 million.tets

# A damaged file: exit 1 and a one-line error naming the file.
cp uniform.tets damaged.tets
python3 - <<'EOF'
import os
p = "damaged.tets"
size = os.path.getsize(p)
with open(p, "r+b") as f:
    f.seek(size // 2)
    b = f.read(1)
    f.seek(size // 2)
    f.write(bytes([b[0] ^ 0x55]))
EOF
set +e
"$T" -q verify damaged.tets > /dev/null 2> err.txt
rc=$?
set -e
[ "$rc" = 1 ] || fail "damaged file: exit $rc, expected 1"
grep -q "damaged.tets" err.txt || fail "damaged file message: $(cat err.txt)"

# Well-formed but wrong: the tets of one point set with the points of another (same
# count; PNTS spliced in byte for byte, its CRC with it). Violations, exit 1.
"$T" -q gen --dist uniform --n 20000 --seed 5 -o other.f64
"$T" -q run other.f64 -o other.tets
python3 - <<'EOF'
import struct
a = bytearray(open("uniform.tets", "rb").read())
b = open("other.tets", "rb").read()
def pnts(buf):
    head_len = struct.unpack_from("<Q", buf, 16 + 8)[0]
    at = 16 + 16 + head_len + 4
    assert buf[at:at + 4] == b"PNTS"
    return at, 16 + struct.unpack_from("<Q", buf, at + 8)[0] + 4
ia, la = pnts(a)
ib, lb = pnts(b)
assert la == lb
a[ia:ia + la] = b[ib:ib + lb]
open("mixed.tets", "wb").write(a)
EOF
set +e
"$T" -q verify mixed.tets > mixed.txt 2> mixed_err.txt
rc=$?
j=$("$T" -q --json verify mixed.tets 2> /dev/null)
set -e
[ "$rc" = 1 ] || fail "mismatched points: exit $rc, expected 1: $(cat mixed.txt mixed_err.txt)"
grep -q "INVALID" mixed.txt || fail "mismatched points summary: $(cat mixed.txt)"
grep -q "verification failed" mixed_err.txt || fail "mismatched points error line: $(cat mixed_err.txt)"
[ "$(echo "$j" | json "d['valid'], d['violation_counts']['orientation'] > 0, len(d['listed']) > 0")" = "False True True" ] \
  || fail "mismatched points --json: $j"

# Usage errors: exit 2.
set +e
"$T" -q verify uniform.tets --sample 0 2> /dev/null; rc1=$?
"$T" -q verify uniform.tets --memory 12Q 2> /dev/null; rc2=$?
set -e
[ "$rc1" = 2 ] || fail "--sample 0: exit $rc1, expected 2"
[ "$rc2" = 2 ] || fail "--memory 12Q: exit $rc2, expected 2"

echo "verify_cli: ok"
