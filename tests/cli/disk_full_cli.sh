#!/usr/bin/env bash
# A filesystem that fills while a job runs (issue #19): another process takes the last
# free bytes after the job's disk plan has passed. The job must stop with exit 3 and
# one error line, keep its checkpoint and leave no file that looks like a finished
# output; `--resume` on the still-full filesystem fails the same way without harming
# the checkpoint; once space is freed, `--resume` ends with the bytes of an
# uninterrupted run.
#
# The filesystem is a small tmpfs mounted in a private mount namespace (`unshare -m`),
# so nothing outside this test sees it and the kernel removes it when the test ends.
# Where mounting is not allowed (no CAP_SYS_ADMIN), the test reports itself skipped
# (exit 77, CTest's SKIP_RETURN_CODE); resume_cli.sh covers the same failure there
# through fault injection and a file-size limit.
# Usage: bash disk_full_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: disk_full_cli.sh /path/to/tetstream}")

if [ "${TETSTREAM_IN_PRIVATE_MOUNTS:-}" != 1 ]; then
  if ! unshare -m --propagation private true 2>/dev/null; then
    echo "disk_full_cli: skipped: cannot make a private mount namespace here (needs CAP_SYS_ADMIN)"
    exit 77
  fi
  exec env TETSTREAM_IN_PRIVATE_MOUNTS=1 unshare -m --propagation private bash "$0" "$T"
fi

dir=$(mktemp -d)
trap 'kill -9 ${job:-} 2>/dev/null || true; umount "$dir/fs" 2>/dev/null || true; rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
segments_done() { python3 -c "import json,sys
try: print(json.load(open('fs/out.tets.ckpt/state.json'))['output']['segments'])
except Exception: print(-1)"; }

# 10^5 points, 4 sort runs, about 40 segments (as in resume_cli.sh). The reference is
# made on the ordinary disk with the same budget.
"$T" -q gen --dist mixed --n 100000 --seed 11 -o points.f64
opts=(run points.f64 --memory 64M --sort-run-points 25000 --zone-points 2500 --threads 2)
"$T" -q "${opts[@]}" -o reference.tets --no-checkpoint --json >reference.json
planned=$(python3 -c "import json; print(json.load(open('reference.json'))['disk_planned_bytes'])")
[ "$planned" -gt 0 ] || fail "the reference run planned no disk"

# A tmpfs with room for the plan and 1 MiB more: the job's plan passes on it.
mkdir fs
size=$(( (planned + 1024 * 1024 + 4095) / 4096 * 4096 ))
mount -t tmpfs -o size=$size tmpfs fs || {
  echo "disk_full_cli: skipped: mount -t tmpfs is not allowed here"
  exit 77
}
echo "disk_full_cli: plan $planned bytes, tmpfs of $size bytes"

# Start the job; once 5 segments are committed, stop it, fill the filesystem from this
# shell (the other process), and let it go on.
"$T" -q "${opts[@]}" -o fs/out.tets --tmpdir fs 2>err.txt &
job=$!
for _ in $(seq 1 6000); do
  kill -0 $job 2>/dev/null || break
  [ "$(segments_done)" -ge 5 ] && break
  sleep 0.01
done
kill -STOP $job 2>/dev/null || fail "the job ended before it could be stopped: $(cat err.txt)"
done_at_stop=$(segments_done)
[ "$done_at_stop" -ge 5 ] || fail "the job was stopped before 5 segments ($done_at_stop)"
dd if=/dev/zero of=fs/filler bs=64K 2>/dev/null && fail "the filler did not fill the filesystem"
[ "$(df -B1 --output=avail fs | tail -1)" -lt 65536 ] || fail "the filesystem is not full"
kill -CONT $job
set +e; wait $job; rc=$?; set -e
job=
msg=$(cat err.txt)
[ $rc = 3 ] || fail "a full filesystem: exit $rc (want 3): $msg"
echo "$msg" | grep -q "No space left on device" || fail "a full filesystem: the message does not say so: $msg"
[ "$(grep -c "error" err.txt)" = 1 ] || fail "a full filesystem: not one error line: $msg"
grep -q "with --resume to continue" err.txt || fail "a full filesystem: the message does not say how to continue: $msg"
echo "$msg" | grep -q "fs/" || fail "a full filesystem: the message names no file: $msg"
[ -e fs/out.tets.ckpt/state.json ] || fail "a full filesystem: the checkpoint was not kept"
[ ! -e fs/out.tets ] || fail "a full filesystem: a file named like the finished output exists"
echo "disk_full_cli: filled after $done_at_stop segments: exit 3: $(grep error err.txt)"

# Resumed while still full: the same failure, and the checkpoint still resumes later.
set +e; msg=$("$T" -q "${opts[@]}" -o fs/out.tets --tmpdir fs --resume 2>&1); rc=$?; set -e
[ $rc = 3 ] && echo "$msg" | grep -q "No space left on device" || fail "resumed on the full filesystem: exit $rc: $msg"
[ -e fs/out.tets.ckpt/state.json ] && [ ! -e fs/out.tets ] || fail "resumed on the full filesystem: checkpoint lost or output made"

# Space freed: --resume finishes with the reference's bytes and removes its checkpoint.
rm fs/filler
"$T" -q "${opts[@]}" -o fs/out.tets --tmpdir fs --resume
cmp reference.tets fs/out.tets || fail "resumed after the disk was freed: output differs from an uninterrupted run"
[ ! -e fs/out.tets.ckpt ] || fail "checkpoint left after the resumed job finished"
left=$(ls -A fs | grep -v '^out.tets$' || true)
[ -z "$left" ] || fail "files left on the filesystem: $left"
"$T" -q verify fs/out.tets >/dev/null || fail "resumed output invalid"
echo "disk_full_cli: all checks passed"
