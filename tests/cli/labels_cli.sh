#!/usr/bin/env bash
# `run`'s label orders (docs/format.md §3.4): by default (and `--labels bricks`) container
# version 2, the labels in bricks along a space-filling curve; `--labels sorted` version 1. verify finds the output valid on regular, degenerate
# and surface inputs at budgets that force many segments and zones; the bytes do not
# depend on the threads, the segments or standard output; a job killed in its writer
# and resumed ends with the same bytes; and, where mpirun is, two ranks write them too.
# `--labels sorted` writes version 1 with the same tets; --periodic writes version 1 and
# refuses an explicit --labels bricks.
# Usage: bash labels_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: labels_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }

for dist in uniform grid terrain hills; do
  "$T" -q gen --dist "$dist" --n 30000 --seed 5 -o "$dist.f64"
  "$T" -q --threads 2 run "$dist.f64" -o "$dist.tets" --memory 64M --segment-points 4000
  "$T" -q verify "$dist.tets" >out.txt || fail "verify $dist: $(cat out.txt)"
  grep -q "VALID" out.txt || fail "verify $dist: $(cat out.txt)"
  "$T" info "$dist.tets" | grep -q "container 2.0" || fail "$dist: not version 2: $("$T" info "$dist.tets")"
  # Other threads, another plan, standard output: the same bytes.
  "$T" -q --threads 1 run "$dist.f64" -o "$dist-1.tets" --memory 64M --labels bricks
  cmp "$dist.tets" "$dist-1.tets" || fail "$dist: one thread and the budget's plan differ"
  "$T" -q run "$dist.f64" -o - --memory 64M --labels bricks >"$dist-stdout.tets"
  cmp "$dist.tets" "$dist-stdout.tets" || fail "$dist: standard output differs"
done

# --labels sorted: the sort's order, version 1, and the same tets (as sets of points).
"$T" -q run grid.f64 -o grid-sorted.tets --memory 64M --labels sorted
"$T" info grid-sorted.tets | grep -q "container 1.0" || fail "--labels sorted is not version 1"
"$T" -q convert grid.tets grid.node
"$T" -q convert grid-sorted.tets grid-sorted.node
python3 - <<'EOF' || fail "bricks and sorted labels: not the same tets"
def tets(stem):
    ids = {}
    with open(stem + ".node") as f:
        n = int(f.readline().split()[0])
        for _ in range(n):
            parts = f.readline().split()
            ids[parts[0]] = (parts[1], parts[2], parts[3])
    out = set()
    with open(stem + ".ele") as f:
        m = int(f.readline().split()[0])
        for _ in range(m):
            parts = f.readline().split()
            out.add(frozenset(ids[p] for p in parts[1:5]))
    return out
assert tets("grid") == tets("grid-sorted")
EOF

# --periodic: version 1 by default, an explicit --labels bricks refused.
"$T" -q run uniform.f64 -o periodic.tets --memory 64M --periodic 1
"$T" info periodic.tets | grep -q "container 1.0" || fail "--periodic is not version 1"
set +e; msg=$("$T" -q run uniform.f64 -o periodic2.tets --memory 64M --periodic 1 --labels bricks 2>&1); rc=$?; set -e
[ $rc = 2 ] && echo "$msg" | grep -q "labels" || fail "--periodic --labels bricks: exit $rc: $msg"
[ ! -e periodic2.tets ] || fail "--periodic --labels bricks wrote an output"

# Killed by an injected failure in the writer, resumed: the same bytes.
opts=(-q --threads 2 run terrain.f64 -o resumed.tets --memory 64M --segment-points 4000 --labels bricks)
set +e; TETSTREAM_FAULT=write:3 "$T" "${opts[@]}" >/dev/null 2>&1; rc=$?; set -e
[ $rc = 3 ] || fail "injected write:3: exit $rc"
[ -e resumed.tets.ckpt/state.json ] || fail "injected write:3: no checkpoint"
"$T" "${opts[@]}" --resume
cmp terrain.tets resumed.tets || fail "resumed after write:3: output differs"
# A resume with the other label order is refused.
set +e; TETSTREAM_FAULT=write:3 "$T" "${opts[@]}" >/dev/null 2>&1; set -e
set +e; msg=$("$T" -q run terrain.f64 -o resumed.tets --memory 64M --segment-points 4000 --labels sorted --resume 2>&1); rc=$?; set -e
[ $rc = 2 ] && echo "$msg" | grep -q "labels" || fail "a resume with --labels changed: exit $rc: $msg"

# Two ranks, where mpirun is: the same bytes as one process.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none
if command -v mpirun >/dev/null && mpirun -q --oversubscribe -n 2 "$T" --version >/dev/null 2>&1; then
  "$T" -q gen --dist uniform --n 200000 --seed 1 -o big.f64
  "$T" -q run big.f64 -o one.tets --memory 256M --labels bricks
  mpirun -q --oversubscribe -n 2 "$T" -q run big.f64 -o two.tets --memory 256M --labels bricks
  cmp one.tets two.tets || fail "mpirun -n 2 --labels bricks differs from one process"
fi
echo "labels_cli: ok"
