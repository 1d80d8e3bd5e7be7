#!/usr/bin/env bash
# `tetstream run` as a user runs it: every input format, stdin, the README spelling,
# verify on the result, --json, and the failure modes (bad input, bad options, I/O):
# the right exit code, one line naming the problem, no output left looking complete,
# no temporary files left behind.
# Usage: bash run_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: run_cli.sh /path/to/tetstream}")
scripts=$(realpath "$(dirname "$0")/../../scripts")
dir=$(mktemp -d)
trap 'chmod -R u+w "$dir" 2>/dev/null; rm -rf "$dir"' EXIT
cd "$dir"
mkdir tmp
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }
no_leftovers() {
  [ -z "$(ls -A tmp)" ] || fail "temporary files left in tmp: $(ls tmp)"
  ls ./*.partial >/dev/null 2>&1 && fail "partial output left: $(ls ./*.partial)"
  return 0
}

# The README spelling, then verify; the same tets from every input format and stdin.
"$T" -q gen --dist ellipsoid-shell --n 20000 --seed 7 -o points.f64
s=$("$T" -q --json run points.f64 -o out.tets --memory 64M --tmpdir tmp --zone-points 2000)
[ "$(echo "$s" | json "d['points'], d['segments'] >= 10, d['tets'] > 100000")" = "20000 True True" ] || fail "run --json: $s"
"$T" -q verify out.tets >/dev/null || fail "verify rejected the output of run"
no_leftovers
# --segment-points is the option's name; --zone-points its old one: the same job.
"$T" -q run points.f64 -o seg.tets --memory 64M --tmpdir tmp --segment-points 2000
cmp -s out.tets seg.tets || fail "--segment-points and --zone-points differ"
# The point index in a file of the work directory (--index disk): the same bytes as in
# memory, on a surface and clustered points (whose queries reach far), at a plan of many
# segments and zones, on 1 and 2 threads; the file goes with the work directory.
for dist in ellipsoid-shell hills clusters; do
  "$T" -q gen --dist $dist --n 20000 --seed 3 -o ix.f64
  "$T" -q run ix.f64 -o ix-memory.tets --memory 64M --tmpdir tmp --segment-points 2500 --zones 3 --index memory
  for threads in 1 2; do
    "$T" -q run ix.f64 -o ix-disk.tets --memory 64M --tmpdir tmp --segment-points 2500 --zones 3 --index disk \
      --threads $threads
    cmp -s ix-memory.tets ix-disk.tets || fail "$dist: --index disk on $threads threads differs from --index memory"
    no_leftovers
  done
done
"$T" -q verify ix-disk.tets >/dev/null || fail "verify rejected the --index disk output"
# auto puts it on disk when it would take more than an eighth of --memory: not at 64M
# for 20,000 points (150 KB); the debug log says which.
"$T" run ix.f64 -o ix-auto.tets --memory 64M --tmpdir tmp --log-level debug 2> ix.log
grep -q "point index: in memory" ix.log || fail "--index auto: $(grep 'point index' ix.log)"
rm -f ix.f64 ix-*.tets ix.log
# The ledger's shares in --json, each phase within the budget.
[ "$(echo "$s" | json "all(sum(d['memory_planned'][p].values()) <= d['memory_planned']['ceiling'] for p in ('sort', 'triangulate'))")" = "True" ] \
  || fail "memory_planned over the ceiling or missing: $s"
# The resident peak the kernel counted (VmHWM): present, and at least the process itself.
[ "$(echo "$s" | json "d['memory_peak_bytes'] > 8 << 20")" = "True" ] || fail "memory_peak_bytes missing or small: $s"
# A plan the options fix past the budget passes it, and the job says so, once, after
# the segment (docs/memory.md); one within it says nothing.
"$T" -q gen --n 200000 --seed 2 -o big.f64
"$T" -q --json run big.f64 -o big.tets --memory 32M --tmpdir tmp --segment-points 200000 >big.json 2>big.err
[ "$(grep -c 'the resident set reached' big.err)" = 1 ] || fail "no warning of the resident set past 32M: $(cat big.err)"
[ "$(json "d['memory_peak_bytes'] > 32 << 20" <big.json)" = "True" ] || fail "memory_peak_bytes: $(cat big.json)"
"$T" -q run big.f64 -o big.tets --memory 256M --tmpdir tmp --force 2>big.err
[ ! -s big.err ] || fail "a job within its budget warned: $(cat big.err)"
rm -f big.f64 big.tets big.json big.err
for f in points.ply points.npy points.txt; do
  "$T" -q gen --dist ellipsoid-shell --n 20000 --seed 7 -o "$f"
  "$T" -q run "$f" -o "out-${f#points.}.tets" --memory 64M --tmpdir tmp --zone-points 2000
  cmp -s <("$T" -q cat out.tets --original-ids) <("$T" -q cat "out-${f#points.}.tets" --original-ids) \
    || fail "$f gives other tets than points.f64"
done
"$T" -q run - --format f64 -o stdin.tets --memory 64M --tmpdir tmp --zone-points 2000 < points.f64
cmp -s <("$T" -q cat out.tets) <("$T" -q cat stdin.tets) || fail "stdin gives other tets"
no_leftovers

# The debug log's check rounds (scripts/plot-rounds reads them): a first round for
# every zone, and the rounds' queries add up to --json's.
s=$("$T" --log-level debug --json run points.f64 -o dbg.tets --memory 64M --tmpdir tmp --zone-points 2000 2> debug.log)
cmp -s out.tets dbg.tets || fail "--log-level debug changed the output"
zones=$(echo "$s" | json "d['zones']")
[ "$(grep -c ' round 1: ' debug.log)" = "$zones" ] || fail "debug log: $(grep -c ' round 1: ' debug.log) first rounds for $zones zones"
queries=$(echo "$s" | json "d['queries']")
sum=$(grep ' round [0-9]*: ' debug.log | grep -o ' [0-9]* queries (' | awk '{s += $1} END {print s}')
[ "$sum" = "$queries" ] || fail "debug log: the rounds' queries add up to $sum, --json says $queries"
"$scripts/plot-rounds" -o rounds.png debug.log:shell > rounds.txt || fail "plot-rounds: $(cat rounds.txt)"
grep -q "all: $queries queries" rounds.txt || fail "plot-rounds' total: $(grep 'all:' rounds.txt)"
[ -s rounds.png ] || fail "plot-rounds drew nothing"
no_leftovers

# Bad input: one line naming the file and offset, exit 1, nothing left behind.
python3 -c "
import struct
open('nan.f64','wb').write(struct.pack('<9d', 0,0,0, 1,0,0, float('nan'),1,0))"
set +e
msg=$("$T" -q run nan.f64 -o bad.tets --tmpdir tmp 2>&1); rc=$?
set -e
[ $rc = 1 ] || fail "NaN input: exit $rc"
[ "$(echo "$msg" | wc -l)" = 1 ] || fail "NaN input: more than one line: $msg"
echo "$msg" | grep -q "nan.f64: byte 48" || fail "NaN input message: $msg"
[ ! -e bad.tets ] || fail "NaN input left bad.tets"
no_leftovers

head -c 100 points.f64 > truncated.f64
set +e; msg=$("$T" -q run truncated.f64 -o bad.tets --tmpdir tmp 2>&1); rc=$?; set -e
[ $rc = 1 ] || fail "truncated input: exit $rc ($msg)"
echo "$msg" | grep -q "truncated.f64" || fail "truncated message: $msg"
no_leftovers

python3 -c "
import struct
open('flat.f64','wb').write(b''.join(struct.pack('<3d', i % 7, i // 7, 0) for i in range(49)))"
set +e; msg=$("$T" -q run flat.f64 -o bad.tets --tmpdir tmp 2>&1); rc=$?; set -e
[ $rc = 1 ] || fail "coplanar input: exit $rc ($msg)"
echo "$msg" | grep -q "affinely independent" || fail "coplanar message: $msg"
[ ! -e bad.tets ] && [ ! -e bad.tets.partial ] || fail "coplanar input left output"
no_leftovers

# Usage errors: exit 2.
set +e
"$T" -q run points.f64 -o bad.tets --memory 12Q >/dev/null 2>&1; rc1=$?
"$T" -q run points.f64 -o bad.tets --memory 1M >/dev/null 2>&1; rc2=$?
"$T" -q run points.f64 >/dev/null 2>&1; rc3=$?
set -e
[ "$rc1 $rc2 $rc3" = "2 2 2" ] || fail "usage errors exit $rc1 $rc2 $rc3"

# An I/O failure exits 3; a work directory that does not exist is the user's to make
# (a usage error, exit 2, that says so).
set +e
"$T" -q run does-not-exist.f64 -o bad.tets --tmpdir tmp >/dev/null 2>&1; rc1=$?
"$T" -q run points.f64 -o bad.tets --tmpdir /nonexistent/dir >/dev/null 2>missing-dir.txt; rc2=$?
set -e
[ "$rc1 $rc2" = "3 2" ] || fail "I/O errors exit $rc1 $rc2"
grep -q "must exist" missing-dir.txt || fail "a missing --tmpdir is not named: $(cat missing-dir.txt)"
rm -f missing-dir.txt
no_leftovers
# A failing stage (an injected disk-full error in the sort, in a segment's worker, in
# the writer) cancels the job cleanly at any thread count: exit 3, the error reported
# once, no hang, nothing left behind.
for fault in sort-run:0 segment:3 write:5; do
  for threads in 1 3 8; do
    set +e
    msg=$(TETSTREAM_FAULT=$fault timeout 120 "$T" -q --threads $threads run points.f64 -o bad.tets --memory 64M \
          --tmpdir tmp --zone-points 2000 --no-checkpoint 2>&1)
    rc=$?
    set -e
    [ $rc = 3 ] || fail "injected $fault, $threads threads: exit $rc ($msg)"
    [ "$(echo "$msg" | grep -c "error:")" = 1 ] || fail "injected $fault, $threads threads: not one error line: $msg"
    [ ! -e bad.tets ] || fail "injected $fault left output"
    no_leftovers
  done
done

# Ctrl-C: exit 130 and no output under the final name. interrupt_run OUT [options]
# starts a run into OUT, sends SIGINT after 0.7 s and checks that.
"$T" -q gen --n 1000000 --seed 3 -o big.f64
interrupt_run() {
  local out=$1; shift
  "$T" -q run big.f64 -o "$out" --tmpdir tmp --memory 256M "$@" 2>err.txt &
  local pid=$!
  sleep 0.7
  kill -INT $pid
  set +e; wait $pid; local rc=$?; set -e
  [ $rc = 130 ] || fail "interrupted run $*: exit $rc"
  [ ! -e "$out" ] || fail "interrupted run $* left $out"
}
# The checkpoint (and the partial output) are kept, and --resume finishes the job.
interrupt_run big.tets
[ -e tmp/big.tets.ckpt/state.json ] || fail "interrupted run kept no checkpoint"
grep -q -- "--resume" err.txt || fail "interrupted run did not say how to resume: $(cat err.txt)"
"$T" -q run big.f64 -o big.tets --tmpdir tmp --memory 256M --resume
"$T" -q verify big.tets >/dev/null || fail "verify rejected the resumed output"
no_leftovers
# Without a checkpoint, Ctrl-C leaves nothing behind.
interrupt_run big2.tets --no-checkpoint
no_leftovers
# SIGTERM at an external sort's merge of its spilled runs (the sort of 10^6 points at
# 40M spills; TETSTREAM_STALL holds the job where the merge starts): exit 130, no
# output, the checkpoint kept, and --resume finishes (at 48M: past the sort, the plan
# of the zones asks for 47M at least, and says so). That the merge itself polls
# between its batches: ExternalSort.MergeStopsWhenInterrupted (verify_test).
TETSTREAM_STALL=merge:0 "$T" -q run big.f64 -o merged.tets --tmpdir tmp --memory 40M 2>stall.err &
pid=$!
for _ in $(seq 1 6000); do
  if grep -q "stalled at merge:0" stall.err || ! kill -0 $pid 2>/dev/null; then break; fi
  sleep 0.01
done
grep -q "stalled at merge:0" stall.err || fail "the run did not reach its sort's merge: $(cat stall.err)"
kill -TERM $pid
set +e; wait $pid; rc=$?; set -e
[ $rc = 130 ] || fail "SIGTERM at the sort's merge: exit $rc ($(cat stall.err))"
[ ! -e merged.tets ] || fail "SIGTERM at the sort's merge left merged.tets"
[ -e tmp/merged.tets.ckpt/state.json ] || fail "SIGTERM at the sort's merge kept no checkpoint"
"$T" -q run big.f64 -o merged.tets --tmpdir tmp --memory 48M --resume
"$T" -q verify merged.tets >/dev/null || fail "verify rejected the output resumed after the merge"
no_leftovers
# More threads than the cores the process may use (as under mpirun's default binding):
# one warning that says so and how to fix it; the job goes on.
if command -v taskset >/dev/null; then
  taskset -c 0 "$T" -q --threads 2 run points.f64 -o bound.tets --memory 64M --no-checkpoint 2>bound.err ||
    fail "a run bound to one core: exit $?"
  grep -q "may run on 1 core" bound.err || fail "no warning for --threads 2 on one core: $(cat bound.err)"
  "$T" -q --threads 1 run points.f64 -o unbound.tets --memory 64M --no-checkpoint 2>unbound.err
  [ ! -s unbound.err ] || fail "a warning for --threads 1: $(cat unbound.err)"
  cmp bound.tets unbound.tets || fail "one core and two threads wrote other bytes"
fi
# A budget whose windows no segment cut fits (a slab through dense clusters is mostly
# buffers): one warning before the zones, shown under -q, saying by how much the job
# may pass it; the job goes on and its output verifies. Uniform points at the same
# budget fit and say nothing.
"$T" -q gen --dist clusters --n 200000 --seed 4 -o dense.f64
"$T" -q run dense.f64 -o dense.tets --memory 40M --no-checkpoint 2>dense.err || fail "clusters at 40M: exit $?"
[ "$(grep -c 'over their share of the budget' dense.err)" = 1 ] || fail "clusters at 40M: not one budget warning: $(cat dense.err)"
grep -q "this job may take up to .* more than its budget" dense.err || fail "the warning does not say by how much"
"$T" -q verify dense.tets >/dev/null || fail "clusters at 40M: the output does not verify"
"$T" -q gen --dist uniform --n 200000 --seed 3 -o even.f64
"$T" -q run even.f64 -o even.tets --memory 40M --no-checkpoint 2>even.err || fail "uniform at 40M: exit $?"
[ ! -s even.err ] || fail "uniform at 40M: a warning: $(cat even.err)"
echo "run_cli: all checks passed"
