#!/usr/bin/env bash
# `run --periodic` killed with SIGKILL and resumed (docs/periodic.md, "Resume and
# mpirun"): at random moments, inside the padded job (its checkpoint nested in the
# periodic job's, the keep's record in it: the output written so far, the tets waiting,
# the deferred ones), at its end (the keep finishing), each resumed with --resume, ends
# with the bytes of an uninterrupted run; a checkpoint is
# refused without --resume or --force, and with other periodic options; --force starts
# over; another --memory resumes (its frames are the first budget's); a job that needs a
# second margin resumes too; `clean --checkpoints` removes both checkpoints; nothing is
# left behind.
# Usage: bash periodic_resume_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: periodic_resume_cli.sh /path/to/tetstream}")
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
ckpt=out.tets.ckpt
nested=$ckpt/periodic-padded.tets.ckpt

# 2*10^4 points (and 10,260 images at this size), 38 segments of the padded job.
"$T" -q gen --dist uniform --n 20000 --seed 7 -o u.f64
opts=(-q run u.f64 -o out.tets --periodic 1 --memory 64M --segment-points 800)
"$T" --threads 1 "${opts[@]}" --no-checkpoint
mv out.tets reference.tets

kills=0
source "$here/lib/kill_when.sh"
# Inside the padded job, in three of its segments (a worker triangulating it), on 1
# and 2 threads; then at the end: every segment in, the keep finishing (the deferred
# tets sorted, the offsets and the index left), when the kill lands there (a short
# phase); then at random moments (seeded, drawn here: a subshell would draw its own).
for target in 5 19 33; do
  kill_at segment:$target $((1 + target % 2))
done
kill_when 'grep -q "\"finishing\":true" $nested/state.json 2>/dev/null' 2
RANDOM=20261128
for _ in 1 2 3; do
  pause=$(printf '0.%02d' $((RANDOM % 40 + 2)))
  kill_when "sleep $pause; true" 2
done
if [ -e $ckpt ]; then "$T" "${opts[@]}" --resume; fi
cmp reference.tets out.tets || fail "resumed output differs from the uninterrupted run's after $kills + $random_kills kills"
[ ! -e $ckpt ] || fail "checkpoint left after the job finished: $(ls -R $ckpt)"
[ "$(ls -A | sort | tr '\n' ' ')" = "out.tets reference.tets u.f64 " ] || fail "files left: $(ls -A)"
echo "kill -9 at $kills chosen and $random_kills other moments: resumed output identical"
rm out.tets

# A checkpoint is refused without --resume (exit 2), and with other periodic options.
kill_at segment:5 1
[ -e $nested/state.json ] || fail "no nested checkpoint after a kill"
set +e
"$T" "${opts[@]}" 2>err.txt; rc=$?
set -e
[ $rc = 2 ] && grep -q -- "--resume" err.txt || fail "an existing checkpoint was not refused: rc $rc $(cat err.txt)"
set +e
"$T" -q run u.f64 -o out.tets --periodic 2 --memory 64M --segment-points 800 --resume 2>err.txt; rc=$?
set -e
[ $rc = 2 ] && grep -q "periodic options" err.txt || fail "other periodic options resumed: rc $rc $(cat err.txt)"
# --force discards both checkpoints and starts over: the same bytes.
"$T" "${opts[@]}" --force
cmp reference.tets out.tets || fail "--force: output differs"
[ ! -e $ckpt ] || fail "checkpoint left after --force"
rm out.tets

# Another --memory may resume the job (the header and the frames keep the first's).
kill_at segment:5 2
[ -e $nested/state.json ] || fail "no nested checkpoint after a kill"
"$T" -q run u.f64 -o out.tets --periodic 1 --memory 256M --segment-points 800 --resume
cmp reference.tets out.tets || fail "resumed with another --memory: output differs"
rm out.tets

# A job that needs a second margin (the first, 0.5 spacings, leaves balls outside the
# padded box), killed in its second attempt and resumed: the same bytes.
mopts=(-q run u.f64 -o out.tets --periodic 1 --memory 64M --segment-points 800 --periodic-margin 0.5)
"$T" "${mopts[@]}" --no-checkpoint --json > m.json
python3 -c "import json; a = json.load(open('m.json'))['periodic']['attempts']; assert a >= 2, a" ||
  fail "the small margin did not need a second attempt: $(cat m.json)"
cmp reference.tets out.tets || fail "a second attempt's output differs"
rm out.tets
"$T" "${mopts[@]}" 2>/dev/null &
pid=$!
for _ in $(seq 1 3000); do
  if ! kill -0 $pid 2>/dev/null; then break; fi
  if python3 -c "import json,sys; sys.exit(0 if json.load(open('$ckpt/state.json'))['attempts'] >= 2 and json.load(open('$nested/state.json'))['keep']['segments'] >= 3 else 1)" 2>/dev/null; then
    kill -9 $pid && kills=$((kills + 1)); break
  fi
  sleep 0.005
done
wait $pid 2>/dev/null || true
[ -e $ckpt ] && "$T" "${mopts[@]}" --resume
cmp reference.tets out.tets || fail "resumed in the second attempt: output differs"
[ ! -e $ckpt ] || fail "checkpoint left"
# `clean --checkpoints` removes a killed periodic job's checkpoint, the nested one in it,
# and its partial output (the keep's, written as the segments finish).
rm out.tets
kill_at segment:5 1
[ -e $nested/state.json ] || fail "no nested checkpoint after a kill"
"$T" -q clean --checkpoints .
[ ! -e $ckpt ] && [ ! -e out.tets.partial ] || fail "clean --checkpoints left: $(ls -A . $ckpt 2>&1)"
echo "periodic_resume_cli: ok ($kills kills)"
