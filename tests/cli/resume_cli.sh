#!/usr/bin/env bash
# Checkpoints and --resume (issue: resumable jobs): a job killed with SIGKILL at many
# moments (in the sort's runs, at the merge, while writing the points, between and
# inside segments), resumed each time, ends with the bytes of an uninterrupted run;
# so does one that failed on a full disk (an injected write failure, and a real one
# from a file-size limit). A damaged checkpoint, a changed input and changed options
# are refused with a message that says how to start over; an existing checkpoint is
# never overwritten without --resume or --force.
# Usage: bash resume_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: resume_cli.sh /path/to/tetstream}")
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }

# 10^5 points; the sort writes 4 runs (--sort-run-points, a testing option) and the
# job has 40 segments.
"$T" -q gen --dist mixed --n 100000 --seed 11 -o points.f64
opts=(-q run points.f64 -o out.tets --memory 64M --sort-run-points 25000 --zone-points 2500)
"$T" "${opts[@]}" --no-checkpoint
mv out.tets reference.tets
"$T" -q verify reference.tets >/dev/null || fail "reference output invalid"

kills=0
source "$here/lib/kill_when.sh"
# At chosen moments, along the job (each one ahead of where the last kill left it):
# in the sort's runs (pass 2, after runs 0 and 2), before the merge (run 3, the last,
# sorted), while the points are written, and in the segments (the writer taking
# segment N's tets), on 1 and 2 threads.
kill_at sort-run:0 2
kill_at sort-run:2 1
kill_at sort-run:3 2
kill_when 'grep -q "\"sorted\"" out.tets.ckpt/state.json 2>/dev/null' 2  # writing the points
for target in 3 11 12 29 36; do
  kill_at write:$target $((1 + target % 2))
done
"$T" "${opts[@]}" --resume
cmp reference.tets out.tets || fail "resumed output differs from the uninterrupted run's after $kills kills"
[ ! -e out.tets.ckpt ] || fail "checkpoint left after the job finished"
echo "kill -9 at $kills chosen moments: resumed output identical"
# Then at random moments of a fresh job (its last resume may find it done, or start it
# again: --resume without a checkpoint runs the job).
# (Seeded, so that a failure can be replayed; drawn here, not in a subshell, which
# would draw its own.)
rm out.tets
RANDOM=20261121
for _ in 1 2 3 4; do
  pause=$(printf '0.%02d' $((RANDOM % 60 + 5)))
  kill_when "sleep $pause; true" 2
done
# Finish the job (a kill may also have landed between the output's rename and the
# checkpoint's removal: --resume then finds the output complete).
if [ -e out.tets.ckpt ]; then "$T" "${opts[@]}" --resume; fi
cmp reference.tets out.tets || fail "resumed output differs from the uninterrupted run's after $random_kills random kills"
[ ! -e out.tets.ckpt ] || fail "checkpoint left after the job finished"
echo "kill -9 at $random_kills random moments: resumed output identical"
rm out.tets

# A checkpoint is not overwritten by accident.
expect_refusal() {  # expected exit code, message pattern, command...
  local want=$1 pattern=$2; shift 2
  set +e; msg=$("$@" 2>&1); rc=$?; set -e
  [ $rc = "$want" ] || fail "expected exit $want, got $rc: $msg"
  echo "$msg" | grep -q -- "$pattern" || fail "message lacks '$pattern': $msg"
  [ -e out.tets.ckpt/state.json ] || fail "a refusal removed the checkpoint: $msg"
}
kill_at write:5 2
[ -e out.tets.ckpt/state.json ] || fail "no checkpoint after a kill"
expect_refusal 2 "--resume" "$T" "${opts[@]}"
# Two processes on one job: the second is refused while the first holds the lock
# (stalled in segment 6, so that it cannot finish in between).
TETSTREAM_STALL=write:6 "$T" "${opts[@]}" --resume 2>first.err &
first=$!
until grep -qF "stalled at write:6 " first.err; do
  kill -0 $first 2>/dev/null || fail "the first process ended without reaching segment 6: $(cat first.err)"
  sleep 0.005
done
rm first.err
# (Refused at the output's lock, taken before the checkpoint's: the message says so.)
set +e; msg=$("$T" "${opts[@]}" --resume 2>&1); rc=$?; set -e
kill -9 $first; wait $first 2>/dev/null || true
[ $rc = 2 ] && echo "$msg" | grep -q "being written by another" || fail "a second process on a running job: $rc $msg"
[ -e out.tets.ckpt/state.json ] || fail "the second process removed the checkpoint"
# Another budget may resume the job: the frames do not depend on it, and the header
# keeps the budget the output was started with, so the bytes are the original's.
"$T" -q run points.f64 -o out.tets --memory 96M --sort-run-points 25000 --zone-points 2500 --resume
cmp reference.tets out.tets || fail "resumed with another --memory, the output differs"
rm out.tets
kill_at write:5 2
expect_refusal 2 "option 'buffer_spacings'" "$T" "${opts[@]}" --buffer 3 --resume
# A changed input (same size, other contents) is noticed.
cp points.f64 saved.f64
"$T" -q gen --dist mixed --n 500000 --seed 12 -o points.f64
expect_refusal 2 "changed" "$T" "${opts[@]}" --resume
mv saved.f64 points.f64
touch -r reference.tets points.f64  # another modification time: still refused
expect_refusal 2 "changed" "$T" "${opts[@]}" --resume
# --force starts over and ends with the same bytes.
"$T" "${opts[@]}" --force
cmp reference.tets out.tets || fail "--force output differs"
rm out.tets

# A damaged checkpoint is refused (exit 1) and left in place; undamaged, it resumes.
# Killed late enough that frames are committed past the points section: version 2 holds
# a brick of tets (8,192 labels here) and frames of 2^18 tets (~40,000 labels) are cut after it.
kill_at write:36 2
cp out.tets.ckpt/state.json saved.json
sed -i 's/"committed": \([0-9]\)/"committed": 9\1/' out.tets.ckpt/state.json
expect_refusal 1 "damaged checkpoint" "$T" "${opts[@]}" --resume
cp saved.json out.tets.ckpt/state.json
# A partial output shorter than the checkpoint's committed bytes is damage too. (Bytes
# past the committed ones are the frames in flight at the kill, which --resume drops:
# cutting only those would not be damage, so the cut goes below the committed end.)
committed=$(python3 -c "import json; print(json.load(open('out.tets.ckpt/state.json'))['output']['committed'])")
# The cut must fall among the frames: below, it damages the points, which a resume sorts
# again (not a refusal). 100,000 points of 28 bytes and a header of a few KiB.
((committed - 100 > 100000 * 28 + 65536)) || fail "no frame committed at write:36 ($committed bytes)"
cp out.tets.partial saved.partial
truncate -s $((committed - 100)) out.tets.partial
expect_refusal 1 "damaged checkpoint" "$T" "${opts[@]}" --resume
mv saved.partial out.tets.partial
"$T" "${opts[@]}" --resume
cmp reference.tets out.tets || fail "output resumed after the damage was undone differs"
rm out.tets

# The point index on disk (--index disk: index.shared in the checkpoint, rebuilt on a
# resume, never trusted): a job killed mid-triangulation and resumed, in memory or on
# disk, ends with the same bytes; the file goes with the checkpoint.
saved_opts=("${opts[@]}")
opts+=(--index disk)
kill_at write:9 2
opts=("${saved_opts[@]}")
[ -e out.tets.ckpt/index.shared ] || fail "--index disk: no index file in the checkpoint"
"$T" "${opts[@]}" --resume
cmp reference.tets out.tets || fail "a job resumed after a kill with --index disk differs"
[ ! -e out.tets.ckpt ] || fail "--index disk: the checkpoint (and its index file) left behind"
rm out.tets

# Disk full: an injected failure (the error a full disk gives) in the sort, in a
# segment and in the writer: exit 3, the checkpoint kept, and --resume (with space
# again) ends with the same bytes.
for fault in sort-run:1 segment:17 write:23; do
  set +e; msg=$(TETSTREAM_FAULT=$fault "$T" "${opts[@]}" 2>&1); rc=$?; set -e
  [ $rc = 3 ] || fail "injected $fault: exit $rc: $msg"
  echo "$msg" | grep -q "No space left" || fail "injected $fault: message: $msg"
  [ "$(echo "$msg" | grep -c "error")" = 1 ] || fail "injected $fault: the error is not reported once: $msg"
  [ -e out.tets.ckpt/state.json ] && [ ! -e out.tets ] || fail "injected $fault: checkpoint not kept, or output left"
  "$T" "${opts[@]}" --resume
  cmp reference.tets out.tets || fail "resumed after injected $fault: output differs"
  rm out.tets
done
# A real write failure: a file-size limit (ulimit -f, in 1 KiB blocks) that the
# output reaches while the tets are written.
# The limit lies between the points section (28 bytes per point, written by the
# merge into the partial output) and the finished output.
limit=$(( ($(stat -c %s reference.tets) - 200000) / 1024 ))
[ $((limit * 1024)) -gt $((100000 * 32 + 100000)) ] || fail "test setup: the limit would stop the sort"
set +e; msg=$(ulimit -f $limit; "$T" "${opts[@]}" 2>&1); rc=$?; set -e
[ $rc = 3 ] || fail "file-size limit: exit $rc: $msg"
[ -e out.tets.ckpt/state.json ] && [ -e out.tets.partial ] || fail "file-size limit: checkpoint or partial output not kept"
"$T" "${opts[@]}" --resume
cmp reference.tets out.tets || fail "resumed after a write failure: output differs"
echo "resume_cli: all checks passed"
