#!/usr/bin/env bash
# `mpirun -n K tetstream run` (issue #20): K = 1, 2, 3 ranks on this machine write the
# bytes of one process with the same --memory, on uniform (float64 and float32),
# clustered and degenerate (grid) points with several blocks a rank, inputs with exact
# duplicates, a text input, and LAS, HDF5 and several-file inputs (which a rank seeks
# in to reach its range); the points are sorted by every rank together (each
# reads, sends and writes its part); a failing rank
# stops the job with one error line and the single process's exit code; a failed or
# killed job resumed on the same ranks ends with the same bytes; `run --periodic` on 2
# ranks, and killed and resumed, writes one process's bytes; `verify` on 1, 2 and 3
# ranks reports what one process reports, on good and damaged containers; `info`, not
# distributed, is refused with one line.
#
# Needs mpirun and a tetstream built with MPI. Without them the test reports itself
# skipped (exit 77), unless TETSTREAM_REQUIRE_MPI=1 (scripts/test.sh sets it, after
# scripts/setup.sh installed OpenMPI): then it fails.
# Usage: bash mpi_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: mpi_cli.sh /path/to/tetstream}")
fail() { echo "FAIL: $*" >&2; exit 1; }
skip() {
  [ "${TETSTREAM_REQUIRE_MPI:-}" = 1 ] && fail "$* (TETSTREAM_REQUIRE_MPI=1)"
  echo "mpi_cli: skipped: $*"
  exit 77
}
command -v mpirun >/dev/null || skip "no mpirun (Debian: openmpi-bin)"

# OpenMPI refuses root unless told; CI runs as root. Shared memory between ranks
# without the ptrace-based single copy, which containers often forbid.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none
mpi() { local n=$1; shift; mpirun -q --oversubscribe -n "$n" "$@"; }

dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
if ! mpi 2 "$T" --version >version.out 2>version.err; then
  grep -q "built without MPI" version.err && skip "this tetstream was built without MPI"
  cat version.err >&2
  fail "mpirun -n 2 tetstream --version failed"
fi

"$T" -q gen --dist uniform --n 200000 --seed 1 -o uniform.f64
"$T" -q gen --dist uniform --n 150000 --seed 2 -o uniform.f32
"$T" -q gen --dist clusters --n 200000 --seed 3 -o clusters.f64
"$T" -q gen --dist grid --n 125000 -o grid.f64  # 50^3: cospherical everywhere

# --memory 32M: frames of 32768 tets, blocks of 32768 labels: 4 to 7 blocks an input,
# so 2 and 3 ranks each take some. One thread a rank (two cores here).
for input in uniform.f64 uniform.f32 clusters.f64 grid.f64; do
  base=${input%.*}-${input#*.}
  "$T" -q --threads 1 run "$input" -o "$base-1p.tets" --memory 32M --no-checkpoint
  for n in 1 2 3; do
    mpi "$n" "$T" -q --threads 1 --json run "$input" -o "$base-$n.tets" --memory 32M >"$base-$n.json"
    cmp "$base-1p.tets" "$base-$n.tets" || fail "$input: $n ranks wrote other bytes than one process"
    if [ "$n" -gt 1 ]; then
      python3 - "$base-$n.json" "$n" <<'PY' || fail "$input: $n ranks: the summary's ranks"
import json, sys
s = json.load(open(sys.argv[1])); n = int(sys.argv[2])
ranks = s["ranks"]
assert len(ranks) == n, ranks
assert all(r["tets"] > 0 for r in ranks), ranks  # every rank wrote some
assert sum(r["tets"] for r in ranks) == s["tets"], (ranks, s["tets"])
assert ranks[0]["labels"][0] == 0 and ranks[-1]["labels"][1] == s["points"]
assert all(a["labels"][1] == b["labels"][0] for a, b in zip(ranks, ranks[1:])), ranks
# Ranks hand each other the points of the sort's exchange (at most their own range of
# the input, in the container's records: 16 bytes a float32 point, 28 a float64 one,
# less what stays on the rank), their hull candidates'
# labels (8 bytes, at most one a point) and summaries (the tets go through files);
# rank 0 also the sorted file's description, whose hull labels (decimal text) grow
# with the hull.
assert s["seconds"]["index"] == max(r["seconds"]["index"] for r in ranks), s["seconds"]
sent = [r["message_bytes"] for r in ranks]
share = (s["input_points"] + n - 1) // n
assert all(0 < b < 64 * 1024 + 40 * share for b in sent[1:]), (sent, share)
assert 0 < sent[0] < 64 * 1024 + 40 * share + 24 * s["hull_vertices"], (sent, s["hull_vertices"])
# The points went through the exchange, not through rank 0: about (n - 1) / n of a
# rank's records belong to other ranks' ranges (the inputs are in random or grid
# order); at least half of that is asked. And no more than a record a point
# (with the hull labels and the summaries): the exchange sends the input's precision.
record = 16 if sys.argv[1].startswith("uniform-f32") else 28
assert all(b > record // 2 * share * (n - 1) // n for b in sent), (sent, share)
assert all(b < 64 * 1024 + (record + 2) * share for b in sent[1:]), (sent, share, record)
PY
    fi
  done
  ls | grep -q '^tetstream-run-' && fail "$input: a work directory was left behind"
done
"$T" -q verify clusters-f64-3.tets || fail "verify of the 3-rank output"

# Inputs a rank reaches its range of by seeking (each rank reads only its own records):
# LAS (fixed-length records after a header), several files (whole files passed by
# their header's count, then a seek inside one) and HDF5 datasets (a hyperslab from
# any row). The same bytes as one process. (Debian's python3, with numpy and h5py from
# scripts/setup.sh, when another python3 comes first on the PATH.)
PY3=$(command -v /usr/bin/python3 || command -v python3)
"$PY3" - <<'PY'
import struct, random
import numpy as np
rng = random.Random(7)
n = 60000
scale, offset = (0.001, 0.001, 0.001), (500000.0, 4000000.0, 100.0)
pts = [(rng.randrange(10**6), rng.randrange(10**6), rng.randrange(10**6)) for _ in range(n)]
real = [[p[k] * scale[k] + offset[k] for p in pts] for k in range(3)]
h = bytearray(227)
h[0:4] = b"LASF"; h[24] = 1; h[25] = 2
struct.pack_into("<HIIBHI", h, 94, 227, 227, 0, 0, 20, n)
struct.pack_into("<12d", h, 131, *scale, *offset, max(real[0]), min(real[0]), max(real[1]), min(real[1]),
                 max(real[2]), min(real[2]))
with open("lidar.las", "wb") as f:
    f.write(h)
    for p in pts:
        f.write(struct.pack("<3iHBBbBH", *p, 0, 0, 0, 0, 0, 0))
u = np.fromfile("uniform.f64", dtype="<f8").reshape(-1, 3)
u[:70000].tofile("part-a.f64"); np.save("part-b.npy", u[70000:120000]); u[120000:].tofile("part-c.f64")
try:
    import h5py
    with h5py.File("snap.hdf5", "w") as f:
        f["PartType0/Coordinates"] = u[:45000]
        f["PartType1/Coordinates"] = u[45000:100000].astype("<f4")  # a float32 dataset after a float64 one
except ImportError:
    pass
PY
seek_inputs=("lidar.las" "part-a.f64 part-b.npy part-c.f64")
if [ -f snap.hdf5 ]; then
  if "$T" -q info snap.hdf5 --dataset /PartType0/Coordinates >/dev/null 2>h5.err; then
    seek_inputs+=("snap.hdf5 --dataset /PartType0/Coordinates --dataset /PartType1/Coordinates")
  else
    grep -q "without HDF5" h5.err || { cat h5.err >&2; fail "info snap.hdf5"; }
    echo "mpi_cli: this tetstream reads no HDF5: its seek is not run"
  fi
fi
for input in "${seek_inputs[@]}"; do
  base=seek-$(echo "$input" | cut -c1-6 | tr -c 'a-z0-9\n' _)
  # shellcheck disable=SC2086
  "$T" -q --threads 1 run $input -o "$base-1p.tets" --memory 32M --no-checkpoint
  for n in 2 3; do
    # shellcheck disable=SC2086
    mpi "$n" "$T" -q --threads 1 run $input -o "$base-$n.tets" --memory 32M
    cmp "$base-1p.tets" "$base-$n.tets" || fail "$input: $n ranks wrote other bytes than one process"
  done
done

# A rank that fails (rank 1 only, by fault injection) stops every rank: exit 3, one
# error line (rank 1's), no output under its final name, the checkpoint kept (rank 0's
# state and rank 1's record). run3 / run2: the job on 3 / 2 ranks, rank 1 failing at
# $FAULT1, into ${OUT3:-failed.tets}; rank1_fails NAME FAULT RUNNER [run options] runs one
# and checks all of that.
run3() {
  local out=${OUT3:-failed.tets}
  mpirun -q --oversubscribe -n 1 "$T" -q --threads 1 run uniform.f64 -o "$out" --memory 32M "$@" \
    : -n 1 -x TETSTREAM_FAULT="${FAULT1:-}" "$T" -q --threads 1 run uniform.f64 -o "$out" --memory 32M "$@" \
    : -n 1 "$T" -q --threads 1 run uniform.f64 -o "$out" --memory 32M "$@"
}
run2() {
  local out=${OUT3:-failed.tets}
  mpirun -q --oversubscribe -n 1 "$T" -q --threads 1 run uniform.f64 -o "$out" --memory 32M "$@" \
    : -n 1 -x TETSTREAM_FAULT="${FAULT1:-}" "$T" -q --threads 1 run uniform.f64 -o "$out" --memory 32M "$@"
}
rank1_fails() {
  local name=$1 fault=$2 runner=$3 rc
  shift 3
  set +e
  OUT3=$name.tets FAULT1=$fault "$runner" "$@" 2>"$name.err"
  rc=$?
  set -e
  [ "$rc" = 3 ] || { cat "$name.err" >&2; fail "$name: rank 1 failing at $fault: exit $rc, expected 3"; }
  [ "$(grep -c 'tetstream: error:' "$name.err")" = 1 ] || { cat "$name.err" >&2; fail "$name: not one error line"; }
  grep -q "injected failure at $fault" "$name.err" || { cat "$name.err" >&2; fail "$name: not rank 1's error"; }
  [ ! -e "$name.tets" ] || fail "$name: a failing rank left an output under its final name"
  [ -f "$name.tets.ckpt/state.json" ] && [ -f "$name.tets.ckpt/rank-1.json" ] || fail "$name: no checkpoint kept"
}

# Rank 1 fails at its third segment (a full disk). Resumed on 2 ranks: the sort and
# rank 0's frames are kept, ranks 1 and 2's labels triangulated again by rank 1: the
# same bytes, and their files gone.
rank1_fails failed segment:2 run3
mpi 2 "$T" --log-level warn --threads 1 run uniform.f64 -o failed.tets --memory 32M --resume 2>other.err ||
  { cat other.err >&2; fail "a 3-rank job resumed on 2 ranks failed"; }
grep -q "started on 3 ranks and goes on on 2" other.err || { cat other.err >&2; fail "no word of the new number of ranks"; }
cmp uniform-f64-1p.tets failed.tets || fail "resumed on 2 ranks after a failing rank: other bytes than one process"
[ ! -e failed.tets.ckpt ] || fail "the checkpoint is left after the resumed job succeeded"

# A 2-rank job whose rank 1 fails: rank 0 has written its half (more than a third)
# before the job stops. Resumed on 3 ranks, rank 0's range reaches the end of its
# frames and ranks 1 and 2 share the rest: the same bytes.
rank1_fails grown segment:1 run2
mpi 3 "$T" -q --threads 1 run uniform.f64 -o grown.tets --memory 32M --resume ||
  fail "a 2-rank job resumed on 3 ranks failed"
cmp uniform-f64-1p.tets grown.tets || fail "resumed on 3 ranks: other bytes than one process"
[ ! -e grown.tets.ckpt ] || fail "the checkpoint is left after the job resumed on 3 ranks"

# The same failure resumed by one process (no mpirun): the same bytes, and every
# rank's files removed with the checkpoint.
rank1_fails alone segment:1 run2
"$T" -q --threads 1 run uniform.f64 -o alone.tets --memory 32M --resume || fail "one process resuming a 2-rank job failed"
cmp uniform-f64-1p.tets alone.tets || fail "one process resuming a 2-rank job: other bytes"
[ ! -e alone.tets.ckpt ] || fail "the checkpoint is left after one process resumed a 2-rank job"

# Rank 1 fails as it copies its frames into the output (every rank has triangulated;
# ranks 1 and 2 write theirs side by side); --resume places the frames again from the
# kept fragments.
rank1_fails placed place:0 run3
OUT3=placed.tets run3 --resume
cmp uniform-f64-1p.tets placed.tets || fail "resumed after a failed placement: other bytes than one process"
[ ! -e placed.tets.ckpt ] || fail "the checkpoint is left after the resumed placement"

# Rank 1 fails in the sort every rank takes part in (its first sorted run, --sort-run-points
# forcing several); --resume sorts again and ends with the same bytes.
"$T" -q --threads 1 run uniform.f64 -o sorted-1p.tets --memory 32M --sort-run-points 20000 --no-checkpoint
cmp uniform-f64-1p.tets sorted-1p.tets || fail "--sort-run-points changed the bytes"
rank1_fails sortfail sort-run:0 run3 --sort-run-points 20000
OUT3=sortfail.tets run3 --sort-run-points 20000 --resume
cmp uniform-f64-1p.tets sortfail.tets || fail "resumed after a failed sort: other bytes than one process"
[ ! -e sortfail.tets.ckpt ] || fail "the checkpoint is left after the resumed sort"

# Exact duplicates, many of them and across the ranks' ranges (their first copies
# kept, the ranks' parts moved into place), and a text input (no count up front: rank 0
# sorts it alone): the bytes of one process.
"$T" -q gen --dist uniform --n 60000 --seed 5 --duplicates 0.3 -o dups.f64
"$T" -q gen --dist uniform --n 20000 --seed 6 -o small.xyz
for input in dups.f64 small.xyz; do
  "$T" -q --threads 1 run "$input" -o "$input-1p.tets" --memory 32M --sort-run-points 9000 --no-checkpoint
  for n in 2 3; do
    mpi "$n" "$T" -q --threads 1 run "$input" -o "$input-$n.tets" --memory 32M --sort-run-points 9000 --no-checkpoint
    cmp "$input-1p.tets" "$input-$n.tets" || fail "$input: $n ranks wrote other bytes than one process"
  done
done

# One progress line for the job (rank 0's, not -q): it counts every rank's labels, out
# of all of them (200.00 k), not rank 0's third; the other ranks print nothing.
mpi 3 "$T" --threads 1 run uniform.f64 -o progress.tets --memory 32M --no-checkpoint 2>progress.err
grep -q "triangulating: .* / 200.00 k points" progress.err || { cat progress.err >&2; fail "no progress line counting the whole job"; }
[ "$(grep -c 'triangulating: .*, [0-9.]*s$' progress.err)" = 1 ] || { cat progress.err >&2; fail "not one final progress line"; }
cmp uniform-f64-1p.tets progress.tets || fail "progress: other bytes than one process"
ls progress.tets.* tetstream-run-* 2>/dev/null && fail "a progress file or work directory was left behind"

# A rank killed with -9 mid-run (rank 2, once its checkpoint records a segment): mpirun
# stops the others; --resume with the same ranks ends with the same bytes.
rank_pid() {  # the pid of rank $1 of this test's job writing $2
  local p
  for p in $(pgrep -f -- "$T -q --threads 1 run [a-z.0-9]* -o $2" || true); do
    tr '\0' '\n' <"/proc/$p/environ" 2>/dev/null | grep -qx "OMPI_COMM_WORLD_RANK=$1" && { echo "$p"; return; }
  done
}
# kill_rank_and_resume RANKS RANK OUT RANK_JSON INPUT ARGS...: runs `run INPUT -o OUT ARGS` on RANKS
# ranks, SIGKILLs rank RANK once RANK_JSON (its checkpoint record) counts 2 segments,
# checks that the job stopped without an output, and resumes it on the same ranks.
kill_rank_and_resume() {
  local ranks=$1 rank=$2 out=$3 record=$4
  shift 4
  mpi "$ranks" "$T" -q --threads 1 run "$1" -o "$out" "${@:2}" 2>"$out.err" &
  local job=$!
  for _ in $(seq 600); do
    python3 -c "import json,sys; sys.exit(0 if json.load(open('$record'))['output']['segments'] >= 2 else 1)" \
      2>/dev/null && break
    sleep 0.05
  done
  local pid
  pid=$(rank_pid "$rank" "$out")
  [ -n "$pid" ] || fail "$out: rank $rank not found (the job ended before it could be killed?)"
  kill -9 "$pid"
  wait "$job" && fail "$out: the job went on after a rank was killed"
  [ ! -e "$out" ] || fail "$out: a killed job left an output under its final name"
  mpi "$ranks" "$T" -q --threads 1 run "$1" -o "$out" "${@:2}" --resume
}
kill_rank_and_resume 3 2 killed.tets killed.tets.ckpt/rank-2.json uniform.f64 --memory 32M --segment-points 4000
cmp uniform-f64-1p.tets killed.tets || fail "resumed after rank 2 was killed: other bytes than one process"
[ ! -e killed.tets.ckpt ] || fail "the checkpoint is left after the resumed job succeeded"
ls | grep -q '^tetstream-run-' && fail "a work directory was left behind"

# Bad input found by the last rank as it reads its range: the line one process
# prints (the first bad point in input order), exit 1, no output.
cp uniform.f64 nan.f64
printf '\x00\x00\x00\x00\x00\x00\xf8\x7f' | dd of=nan.f64 bs=1 seek=$((24 * 190000 + 8)) conv=notrunc status=none
set +e
"$T" -q run nan.f64 -o nan-1p.tets --memory 32M 2>nan-1p.err
rc1=$?
mpi 3 "$T" -q run nan.f64 -o nan.tets --memory 32M 2>nan.err
rc=$?
set -e
[ "$rc1" = 1 ] && [ "$rc" = 1 ] || fail "a NaN: exit $rc1 (one process), $rc (3 ranks), expected 1"
grep 'tetstream: error:' nan-1p.err >nan-1p.line
grep 'tetstream: error:' nan.err >nan.line
cmp nan-1p.line nan.line || { cat nan-1p.err nan.err >&2; fail "a NaN: 3 ranks report another line than one process"; }
grep -q "byte $((24 * 190000 + 8))" nan.line || fail "a NaN: the line does not name its byte"
[ ! -e nan.tets ] && [ ! -e nan.tets.partial ] || fail "a NaN left an output"
# Bad input leaves nothing to resume, on any rank it is found.
[ ! -e nan.tets.ckpt ] || fail "a NaN found by the last rank left a checkpoint (one process leaves none)"
grep -q "progress is kept" nan.err && fail "a NaN: rank 0 says the job can be resumed"

# Bad input (every rank sees it at the start): exit 1, one line naming the file and the offset.
head -c 1000 uniform.f64 >truncated.f64
set +e
mpi 3 "$T" -q run truncated.f64 -o bad.tets --memory 32M 2>bad.err
rc=$?
set -e
[ "$rc" = 1 ] || { cat bad.err >&2; fail "bad input: exit $rc, expected 1"; }
[ "$(grep -c 'tetstream: error:' bad.err)" = 1 ] && grep -q "truncated.f64" bad.err || { cat bad.err >&2; fail "bad input: not one line naming the file"; }
[ ! -e bad.tets ] && [ ! -e bad.tets.partial ] || fail "bad input left an output"

# verify on K = 2, 3 ranks (each checks the frames of its label range; the records of
# its tets keyed in later ranks' labels are handed over): the report of one process,
# --json field by field but for timings and resources, on the outputs above (several
# frames a rank, 32M) and on damaged containers, with the same exit code.
same_report() {  # same_report A.json B.json WHAT
  python3 - "$1" "$2" <<'PY' || fail "$3: the reports differ"
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
resources = {"seconds", "peak_open_facets", "peak_open_edges", "spilled_records", "spill_bytes", "memory_planned"}
diff = [k for k in sorted(set(a) | set(b)) if k not in resources and a.get(k) != b.get(k)]
assert not diff, [(k, a.get(k), b.get(k)) for k in diff]
PY
}
verify_ranks() {  # verify_ranks NAME.tets EXPECTED_EXIT: one process (no mpirun), then K = 2, 3
  local f=$1 want=$2 n rc
  for n in 1 2 3; do
    set +e
    if [ "$n" = 1 ]; then
      "$T" -q --threads 1 --json verify "$f" >"$f-v$n.json" 2>"$f-v$n.err"
    else
      mpirun -q --bind-to none --oversubscribe -n "$n" "$T" -q --threads 1 --json verify "$f" >"$f-v$n.json" 2>"$f-v$n.err"
    fi
    rc=$?
    set -e
    [ "$rc" = "$want" ] || { cat "$f-v$n.err" >&2; fail "verify $f on $n ranks: exit $rc, expected $want"; }
    if [ "$want" = 0 ] || [ "$want" = 1 ] && [ -s "$f-v$n.json" ]; then
      [ "$n" = 1 ] || same_report "$f-v1.json" "$f-v$n.json" "verify $f on $n ranks"
    fi
    grep 'tetstream: error:' "$f-v$n.err" >"$f-v$n.line" || true
    [ "$(wc -l <"$f-v$n.line")" = "$([ "$want" = 0 ] && echo 0 || echo 1)" ] || { cat "$f-v$n.err" >&2; fail "verify $f on $n ranks: not one error line"; }
    cmp -s "$f-v1.line" "$f-v$n.line" || fail "verify $f on $n ranks: another error line than one rank's"
  done
}
for base in uniform-f64 clusters-f64 grid-f64; do
  verify_ranks "$base-1p.tets" 0
  [ "$(python3 -c "import json; print(json.load(open('$base-1p.tets-v3.json'))['valid'])")" = True ] || fail "$base: not valid"
done
# One rank under mpirun agrees too.
mpi 1 "$T" -q --threads 1 --json verify grid-f64-1p.tets >grid-rank.json
same_report grid-f64-1p.tets-v1.json grid-rank.json "verify on 1 rank"

# Damaged, checksums valid (tets_edit: the first tet of the first frame of rank 1 of
# K flipped, dropped or doubled, where records are handed over): the same violations,
# listed alike, exit 1. A frame's byte flipped (its CRC fails): one error line, the
# same, exit 1.
edit=${TETSTREAM_TETS_EDIT:-$(dirname "$T")/../tests/tets_edit}
[ -x "$edit" ] || fail "no tets_edit ($edit); set TETSTREAM_TETS_EDIT"
for e in "uniform-f64 flip 2" "grid-f64 drop 3" "clusters-f64 dup 3"; do
  read -r base kind k <<<"$e"
  "$edit" "$base-1p.tets" "$kind-$k.tets" "$kind" "$k" 1 >/dev/null
  verify_ranks "$kind-$k.tets" 1
  python3 - "$kind-$k.tets-v1.json" "$kind" <<'PY' || fail "$kind: not the violations expected"
import json, sys
d = json.load(open(sys.argv[1]))
want = {"flip": "orientation", "drop": "hull_convex", "dup": "duplicate_tet"}[sys.argv[2]]
assert not d["valid"] and d["violation_counts"][want] > 0 and d["listed"], d
PY
done
cp uniform-f64-1p.tets crc.tets
python3 - <<'PY'
import struct
b = bytearray(open("crc.tets", "rb").read())
idx = struct.unpack_from("<Q", b, len(b) - 48)[0]
p = idx + 16
p += 4 + 24 * struct.unpack_from("<I", b, p)[0]
frames = struct.unpack_from("<Q", b, p)[0]
off, _, _, length = struct.unpack_from("<QQII", b, p + 8 + 40 * (frames * 2 // 3))  # a frame of the last rank of 3
b[off + 16 + length // 2] ^= 0x20
open("crc.tets", "wb").write(b)
PY
verify_ranks crc.tets 1
grep -q "crc.tets" crc.tets-v3.line || fail "a bad checksum: the line does not name the file"

# --periodic (docs/periodic.md): rank 0 pads, every rank runs the padded job, rank 0
# keeps: 2 ranks write the bytes of one process; rank 1 killed with -9 inside
# the padded job (its record in the nested checkpoint), resumed on 2 ranks: the same.
"$T" -q gen --dist uniform --n 60000 --seed 5 -o box.f64
"$T" -q --threads 1 run box.f64 -o box-1p.tets --periodic 1 --memory 32M --segment-points 4000 --no-checkpoint
mpi 2 "$T" -q --threads 1 run box.f64 -o box-2.tets --periodic 1 --memory 32M --segment-points 4000
cmp box-1p.tets box-2.tets || fail "--periodic: 2 ranks wrote other bytes than one process"
kill_rank_and_resume 2 1 boxk.tets boxk.tets.ckpt/periodic-padded.tets.ckpt/rank-1.json box.f64 --periodic 1 \
  --memory 32M --segment-points 4000
cmp box-1p.tets boxk.tets || fail "--periodic: resumed after rank 1 was killed: other bytes than one process"
[ ! -e boxk.tets.ckpt ] || fail "--periodic: the checkpoint is left after the resumed job succeeded"

# Not distributed, refused with one line and exit 2: info.
set +e
mpi 2 "$T" -q info uniform-f64-1p.tets 2>refused.err
rc=$?
set -e
[ "$rc" = 2 ] && [ "$(grep -c 'tetstream: error:' refused.err)" = 1 ] || { cat refused.err >&2; fail "'info' under mpirun: exit $rc"; }

# A rank left on one core of several by mpirun's binding says so, once; unbound, or
# with as many ranks as cores, it does not (2 cores or more; OpenMPI binds one or two
# ranks to a core each by default).
if [ "$(nproc)" -ge 2 ] && [ "$(nproc)" -le 64 ]; then
  mpirun -q -n 1 "$T" -q run grid.f64 -o bound.tets --memory 48M --no-checkpoint 2>bound.err
  grep -q "each rank may use 1 of this node's" bound.err || { cat bound.err >&2; fail "no warning for a rank bound to one core"; }
  mpirun -q --bind-to none -n 1 "$T" -q run grid.f64 -o unbound.tets --memory 48M --no-checkpoint 2>unbound.err
  [ ! -s unbound.err ] || { cat unbound.err >&2; fail "a warning for an unbound rank"; }
  cmp bound.tets unbound.tets || fail "a bound rank wrote other bytes"
fi
echo "mpi_cli: OK"
