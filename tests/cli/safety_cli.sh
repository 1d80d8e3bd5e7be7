#!/usr/bin/env bash
# The user's files are sacred (docs/safety.md; issue: nothing lost, nothing wrong).
# Each block is one defect found by an audit, run as a user would, in a scratch tree
# where the user's own files sit next door:
#   1. a checkpoint directory the job did not make is never removed (--checkpoint DIR
#      makes DIR/OUT.ckpt; --force, bad input, --resume without state, --checkpoint .);
#   2. every finite double: far outliers, sets scaled by 2^200..2^1000 give the exact
#      tets (the same as the unscaled set's), and verify judges them right;
#   3. damaged checkpoint files are recomputed or refused, never trusted;
#   4. the output is never the input; 5. one job per output; 6. no links followed,
#      no devices or directories written;
#   7. a budget failure keeps the checkpoint and names a budget that works, which a
#      --resume may then take;
#   9. numeric options that would crash (--threads 65536) are refused; parser errors
#      are one line; SIGHUP stops a job like Ctrl-C; degenerate input names its file;
#      damaged points are refused by cat and found by info --check;
#  10. a killed job's temporary directory is removed by the next run and by `clean`.
# Usage: bash safety_cli.sh /path/to/tetstream [BLOCK...]   (blocks: 1 2 3 4 5 6 7 9 10; default all)
set -euo pipefail
T=$(realpath "${1:?usage: safety_cli.sh /path/to/tetstream [BLOCK...]}")
shift
blocks=" ${*:-1 2 3 4 5 6 7 9 10} "
want() { [[ $blocks == *" $1 "* ]]; }
dir=$(mktemp -d)
trap 'chmod -R u+w "$dir"; rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
# The same tets (the header names the input's path, which may differ).
same_tets() { cmp -s <("$T" -q cat "$1" --format u32) <("$T" -q cat "$2" --format u32); }
flip() { printf '\x5a' | dd of="$1" bs=1 seek="$2" conv=notrunc status=none; }
# expect CODE PATTERN CMD...: exit code CODE and one stderr line matching PATTERN.
expect() {
  local code=$1 pattern=$2
  shift 2
  local rc=0
  "$@" 2>err.txt >/dev/null || rc=$?
  [ "$rc" -eq "$code" ] || fail "exit $rc, not $code: $* ($(cat err.txt))"
  grep -q -- "$pattern" err.txt || fail "no '$pattern' in the error of $*: $(cat err.txt)"
}

"$T" -q gen --dist uniform --n 20000 --seed 5 -o pts.f64
cp pts.f64 pristine.f64
"$T" -q gen --dist uniform --n 300000 --seed 6 -o big.f64  # a job that runs a few seconds
base=(-q run --memory 128M --zone-points 2000)
"$T" "${base[@]}" pts.f64 -o reference.tets --no-checkpoint

# ---- 1. the checkpoint directory ----
if want 1; then
mkdir v
echo "four years of work" >v/thesis.txt
cp pts.f64 v/
"$T" "${base[@]}" v/pts.f64 -o out.tets --checkpoint v || fail "run with --checkpoint v failed"
[ -f v/thesis.txt ] && cmp -s v/pts.f64 pristine.f64 || fail "--checkpoint v removed the user's files"
[ ! -e v/out.tets.ckpt ] || fail "the job's own checkpoint directory was left behind"
same_tets out.tets reference.tets || fail "--checkpoint changed the tets"
"$T" "${base[@]}" v/pts.f64 -o out.tets --checkpoint v --force
"$T" "${base[@]}" v/pts.f64 -o out.tets --checkpoint v --resume 2>/dev/null
[ -f v/thesis.txt ] && [ -f v/pts.f64 ] || fail "--force or --resume removed the user's files"
printf 'nan 0 0\n1 2 3\n' >v/bad.txt
expect 1 "bad.txt" "$T" "${base[@]}" v/bad.txt -o bad.tets --checkpoint v
[ -f v/thesis.txt ] && [ -f v/pts.f64 ] && [ -f v/bad.txt ] || fail "bad input removed the user's files"
# The current directory as the checkpoint's place: the input and outputs stay.
mkdir here && cp pts.f64 here/ && (cd here && "$T" "${base[@]}" pts.f64 -o o.tets --checkpoint .)
[ -f here/pts.f64 ] && [ -f here/o.tets ] || fail "--checkpoint . removed the input or the output"
# A directory by the checkpoint's name that tetstream did not make is refused, untouched.
mkdir out2.tets.ckpt && echo keep >out2.tets.ckpt/notes.txt
expect 2 "not made by tetstream" "$T" "${base[@]}" pts.f64 -o out2.tets
expect 2 "not made by tetstream" "$T" "${base[@]}" pts.f64 -o out2.tets --force
[ -f out2.tets.ckpt/notes.txt ] || fail "a foreign directory by the checkpoint's name was emptied"
# A file the user left inside a real checkpoint survives its removal.
TETSTREAM_FAULT=sort-run:1 "$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out3.tets 2>/dev/null && fail "fault not injected"
echo mine >out3.tets.ckpt/mine.txt
"$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out3.tets --resume
[ -f out3.tets.ckpt/mine.txt ] || fail "a file the job did not write was removed with its checkpoint"
cmp -s out3.tets reference.tets || fail "resumed output differs"

fi

# ---- 2. the whole exponent range (tests/unit/exponent_range_test.cpp goes further) ----
if want 2; then
python3 - <<'PY'
import array, math
a = array.array('d')
with open('pts.f64', 'rb') as f:
    a.frombytes(f.read())
far = array.array('d', a)
far.extend([0.5, 4e38, 0.5])  # above FLT_MAX: the index's float boxes overflowed
with open('far.f64', 'wb') as f:
    far.tofile(f)
for k in (200, 600, 1000):  # exact scalings: the same triangulation
    with open('scaled%d.f64' % k, 'wb') as f:
        array.array('d', [math.ldexp(x, k) for x in a]).tofile(f)
with open('e103.f64', 'wb') as f:  # verify's volumes were NaN from about 1e103
    array.array('d', [x * 1e103 for x in a]).tofile(f)
PY
"$T" "${base[@]}" far.f64 -o far.tets --no-checkpoint || fail "the 4e38 outlier failed"
"$T" -q verify far.tets >/dev/null 2>err.txt || fail "the 4e38 outlier gave an invalid triangulation: $(cat err.txt)"
for k in 200 600 1000; do
  "$T" "${base[@]}" scaled$k.f64 -o scaled$k.tets --no-checkpoint || fail "scaled by 2^$k failed"
  same_tets scaled$k.tets reference.tets || fail "scaling by 2^$k changed the tets"
  "$T" -q verify scaled$k.tets >/dev/null 2>err.txt || fail "verify rejected the set scaled by 2^$k: $(cat err.txt)"
done
"$T" "${base[@]}" e103.f64 -o e103.tets --no-checkpoint
"$T" -q verify e103.tets >/dev/null 2>err.txt || fail "verify rejected coordinates of 1e103: $(cat err.txt)"
rm -f far.* scaled* e103.*
fi

# ---- 3. damaged checkpoint files: recomputed where possible, else refused ----
if want 3; then
ck=out4.tets.ckpt
fresh_checkpoint() {  # stops the job with an injected fault at $1
  rm -rf "$ck" out4.tets out4.tets.partial
  TETSTREAM_FAULT=$1 "$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out4.tets 2>/dev/null && fail "no fault at $1"
  [ -e "$ck/state.json" ] || fail "no checkpoint after the fault at $1"
}
resumes_to_reference() {
  "$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out4.tets --resume 2>err.txt || fail "$1: resume failed: $(cat err.txt)"
  cmp -s out4.tets reference.tets || fail "$1: a damaged checkpoint gave other bytes"
}
fresh_checkpoint sort-run:3
truncate -s -24 "$ck/points-1.run"
resumes_to_reference "a run cut by 24 bytes"
fresh_checkpoint sort-run:3
flip "$ck/points-0.run" 1000
resumes_to_reference "a flipped byte in a run"
fresh_checkpoint sort-run:3
rm "$ck/points-2.run"
resumes_to_reference "a missing run"
fresh_checkpoint sort-run:3
flip "$ck/points-1.run.hull" 3
resumes_to_reference "a flipped byte in a run's hull candidates"
fresh_checkpoint write:4
# The sorted points are the output's points section (no file of their own): damaged,
# they are sorted again from the input, into the same place, to the same bytes.
flip out4.tets.partial 5000
resumes_to_reference "a flipped byte in the sorted points (the partial output's points section)"
fresh_checkpoint write:4
pending=$(ls "$ck"/pending-*.tets | head -1)
flip "$pending" 100
expect 1 "damaged checkpoint" "$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out4.tets --resume
[ -e "$ck/state.json" ] || fail "a damaged checkpoint was removed"
fresh_checkpoint write:4
committed=$(python3 -c "import json; print(json.load(open('$ck/state.json'))['output']['committed'])")
# The last committed byte: the last frame's checksum, or the points' when no frame is
# committed yet (20000 points make less than a frame).
python3 -c "f = open('out4.tets.partial', 'r+b'); f.seek($committed - 1); b = f.read(1)[0]; f.seek(-1, 1); f.write(bytes([b ^ 0xff]))"
expect 1 "damaged checkpoint" "$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out4.tets --resume
fresh_checkpoint write:4
flip out4.tets.partial 20  # in the header
expect 1 "damaged checkpoint" "$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out4.tets --resume
"$T" "${base[@]}" --sort-run-points 5000 pts.f64 -o out4.tets --force
cmp -s out4.tets reference.tets || fail "--force after damage"

fi

# ---- 4. the output is never the input ----
if want 4; then
for o in pts.f64 ./pts.f64 "$dir/pts.f64"; do
  expect 2 "is the input" "$T" "${base[@]}" pts.f64 -o "$o"
done
ln pts.f64 hardlink.f64
expect 2 "is the input" "$T" "${base[@]}" pts.f64 -o hardlink.f64
cmp -s pts.f64 pristine.f64 || fail "the input was written over"

fi

# ---- 5. one job per output at a time ----
if want 5; then
"$T" --threads 1 -q run big.f64 -o shared.tets --memory 256M --zone-points 20000 &
first=$!
for _ in $(seq 1 500); do [ -e shared.tets.partial ] && break; sleep 0.01; done
[ -e shared.tets.partial ] || fail "the first job made no partial output"
expect 2 "being written by another" "$T" "${base[@]}" pts.f64 -o shared.tets --no-checkpoint
expect 2 "being written by another" "$T" "${base[@]}" pts.f64 -o shared.tets --checkpoint v
wait $first || fail "the first job failed when a second one tried its output"
"$T" -q verify shared.tets >/dev/null || fail "the first job's output is not valid"

fi

# ---- 6. links, devices and directories ----
if want 6; then
echo precious >victim
ln -s victim o6.tets.partial
expect 2 "symbolic link" "$T" "${base[@]}" pts.f64 -o o6.tets --no-checkpoint
[ "$(cat victim)" = precious ] || fail "a planted link to the partial output was followed"
rm o6.tets.partial
mkdir elsewhere
ln -s elsewhere o7.tets.ckpt
expect 2 "symbolic link" "$T" "${base[@]}" pts.f64 -o o7.tets
[ -z "$(ls -A elsewhere)" ] || fail "a planted link to the checkpoint was followed"
ln -s victim link.tets
expect 2 "symbolic link" "$T" "${base[@]}" pts.f64 -o link.tets --no-checkpoint
[ -L link.tets ] && [ "$(cat victim)" = precious ] || fail "an output that is a link was replaced or followed"
mkdir isdir.tets
expect 2 "is a directory" "$T" "${base[@]}" pts.f64 -o isdir.tets
mkfifo fifo.tets
expect 2 "not a regular file" "$T" "${base[@]}" pts.f64 -o fifo.tets --no-checkpoint
[ -p fifo.tets ] || fail "a fifo output was replaced"
if [ "$(id -u)" -eq 0 ] && [ -c /dev/null ]; then
  expect 2 "not a regular file" "$T" "${base[@]}" pts.f64 -o /dev/null --no-checkpoint
  [ -c /dev/null ] || fail "/dev/null was replaced"
fi

fi

# ---- 7. budgets: a failure keeps the checkpoint and names a budget that works ----
if want 7; then
"$T" -q gen --dist uniform --n 200000 --seed 7 -o b.f64
# Far too small: refused after the first pass (count and box), before the sort writes
# anything, naming a budget; nothing is left behind. (4 million points at 32M: 200,000
# now nearly fit in 32M, and are refused after the sort, needing 34M.)
"$T" -q gen --dist uniform --n 4000000 --seed 7 -o toomany.f64
expect 2 "use --memory [0-9]*M or more (refused before the sort)" "$T" -q run toomany.f64 -o b.tets --memory 32M
[ ! -e b.tets.ckpt ] && [ ! -e b.tets.partial ] || fail "a refusal before the sort left files"
grep -q -- "--resume" err.txt && fail "a refusal before the sort advises a --resume"
rm toomany.f64
# Too small only for this input's real windows (thick buffers): refused after the
# sort, whose work is kept for a --resume with the budget named.
expect 2 "use --memory [0-9]*M or more" "$T" -q run b.f64 -o b.tets --memory 80M --buffer 20
grep -o "use --memory [0-9]*M" err.txt | head -1 >need.txt
need=$(sed 's/use --memory //' need.txt)
[ -e b.tets.ckpt/state.json ] || fail "a budget failure removed the checkpoint"
grep -q -- "--resume" err.txt || fail "the budget failure does not say how to continue"
"$T" -q run b.f64 -o b.tets --memory "$need" --buffer 20 --resume || fail "--resume with the named budget $need failed"
"$T" -q run b.f64 -o b2.tets --memory "$need" --buffer 20 --no-checkpoint
cmp -s b.tets b2.tets || fail "a resume with a new budget differs from a run with that budget"
"$T" -q run pts.f64 -o huge.tets --memory 1T --zone-points 2000 2>err.txt || fail "--memory 1T failed: $(cat err.txt)"
grep -q "capped" err.txt || fail "--memory 1T was not capped with a warning"
# The disk is planned from the input's size before any work: a (sparse) 1 TB input needs
# more than this disk has, and is refused at once with the figures, leaving nothing.
truncate -s 1099511627760 huge.f64  # 45,812,984,490 records of 24 bytes
expect 3 "not enough disk for this job: needs .* free" "$T" -q run huge.f64 -o huge.tets --memory 128M
[ ! -e huge.tets.ckpt ] && [ ! -e huge.tets.partial ] || fail "a refused disk plan left files"
expect 3 "not enough disk" "$T" -q run huge.f64 -o huge.tets --memory 128M --no-checkpoint
ls -d tetstream-run-* 2>/dev/null && fail "a refused disk plan left a temporary directory"
rm huge.f64

fi

# ---- 9. numbers and signals: no crash, one line ----
if want 9; then
expect 2 "not in range" "$T" --threads 65536 run pts.f64 -o t.tets
expect 2 "not in range" "$T" --threads 65536 verify reference.tets
[ "$(wc -l <err.txt)" = 1 ] || fail "a parser error took more than one line: $(cat err.txt)"
expect 2 "did you mean 'run'" "$T" runn pts.f64
[ "$(wc -l <err.txt)" = 1 ] || fail "an unknown subcommand took more than one line"
expect 2 "^tetstream: error: " "$T" run
# A closed terminal ends a job like Ctrl-C: exit 130, the checkpoint kept, no output.
"$T" --threads 1 -q run big.f64 -o hup.tets --memory 256M --zone-points 20000 &
job=$!
for _ in $(seq 1 500); do [ -e hup.tets.ckpt/state.json ] && break; sleep 0.01; done
kill -HUP $job
rc=0; wait $job || rc=$?
[ $rc = 130 ] || fail "SIGHUP: exit $rc, not 130"
[ -e hup.tets.ckpt/state.json ] && [ ! -e hup.tets ] || fail "SIGHUP: checkpoint not kept, or an output left"
# Degenerate input: the message names the file.
printf '0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 3 0\n' >flat.txt
expect 1 "flat.txt: .*affinely independent" "$T" -q run flat.txt -o flat.tets
# Damaged points: cat --points and --original-ids refuse; info --check finds it.
cp reference.tets dmg.tets
flip dmg.tets 3000
expect 1 "points: checksum mismatch" "$T" -q cat dmg.tets --points
expect 1 "points: checksum mismatch" "$T" -q cat dmg.tets --original-ids
"$T" -q info dmg.tets >/dev/null || fail "info without --check reads only the header: it should pass"
expect 1 "checksum mismatch" "$T" -q info dmg.tets --check
"$T" -q info reference.tets --check >/dev/null || fail "info --check rejected a valid container"
fi

# ---- 10. a killed job's temporary directory ----
if want 10; then
mkdir spool && cd spool
{ cat ../big.f64; sleep 30; } | "$T" -q run - --type f64 -o s.tets --memory 256M &
job=$!
for _ in $(seq 1 500); do ls -d tetstream-run-* >/dev/null 2>&1 && [ -s tetstream-run-*/stdin.f64 ] && break; sleep 0.01; done
kill -9 $job 2>/dev/null || true
wait $job 2>/dev/null || true
pkill -f "sleep 30" 2>/dev/null || true
ls -d tetstream-run-* >/dev/null 2>&1 || fail "the killed stdin job left no spool (test did not reach it)"
echo "user data" >tetstream-run-lookalike  # a file, not a work directory: never touched
"$T" -q clean --dry-run . >/dev/null
ls -d tetstream-run-*/ >/dev/null 2>&1 || fail "clean --dry-run removed something"
"$T" -q run ../pts.f64 -o again.tets --memory 128M --no-checkpoint
ls -d tetstream-run-*/ >/dev/null 2>&1 && fail "the next run left the dead job's spool"
[ -f tetstream-run-lookalike ] || fail "a user file with a work directory's name was removed"
cd ..
fi
echo "safety_cli: blocks${blocks% } passed"
