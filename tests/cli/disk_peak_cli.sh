#!/usr/bin/env bash
# The disk a job takes (issue #19): one copy of the points, plus the tets, plus slack,
# at every moment. The sort's runs are given back as the merge reads them, the merge
# writes the points straight into the output's points section, and no other copy of
# them exists. A background loop samples the space allocated to the work and output
# directories every 20 ms while a job with several sort runs and many segments runs,
# with a checkpoint and without; the job's own --json peak must agree.
# Usage: bash disk_peak_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: disk_peak_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'kill $sampler 2>/dev/null || true; rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }

n=200000
"$T" -q gen --n $n --seed 5 -o pts.f64
mkdir out
# Allocated bytes (holes not counted) of everything under out/ but the checkpoint's
# pending frame (tets not yet in a frame, 32 bytes each, at most a frame, twice for a
# moment: disk_plan.hpp counts it apart), every 20 ms, the largest so far in peak.txt.
sample() {
  local peak=0 now
  echo 0 >peak.txt
  while :; do
    now=$(du -s -B1 --exclude='pending-*' out 2>/dev/null | cut -f1) || now=0
    # Renamed into place: the kill below may land at any moment, and a truncated
    # peak.txt read as "" failed the check once.
    if [ "${now:-0}" -gt "$peak" ]; then peak=$now; echo "$peak" >peak.tmp && mv peak.tmp peak.txt; fi
    sleep 0.02
  done
}
for mode in --checkpoint=out --no-checkpoint; do
  rm -rf out/*
  sample &
  sampler=$!
  "$T" -q run pts.f64 -o out/o.tets --memory 48M --threads 2 --sort-run-points 40000 --zone-points 10000 \
    "${mode%%=*}" ${mode#*=} --json >summary.json 2>err.txt || { kill $sampler; fail "$mode: $(cat err.txt)"; }
  kill $sampler
  wait $sampler 2>/dev/null || true
  peak=$(cat peak.txt)
  read -r points tets segments reported < <(python3 -c "import json; d=json.load(open('summary.json'))
print(d['points'], d['tet_bytes'], d['segments'], d.get('disk_peak_bytes', 0))")
  [ "$segments" -ge 10 ] || fail "$mode: only $segments segments"
  record=28  # float64 coordinates and a 32-bit original index (docs/format.md 3.4)
  # Slack: the header, the hull candidates, a partly punched page per run, the state
  # and the directory blocks: 2 MiB.
  limit=$((points * record + tets + 2 * 1024 * 1024))
  # The job's own figure counts the pending frame too.
  frame=$(( 7 * points < 266240 ? 7 * points : 266240 ))
  reported_limit=$((limit + 2 * 32 * frame))
  echo "disk_peak_cli $mode: sampled peak $peak bytes, reported $reported, limit $limit ($points points, $tets bytes of tets)"
  [ "$peak" -le "$limit" ] || fail "$mode: $peak bytes on disk at the peak, over one copy of the points + the tets + slack ($limit)"
  [ "$reported" -gt 0 ] && [ "$reported" -le "$reported_limit" ] ||
    fail "$mode: --json disk_peak_bytes $reported (limit $reported_limit)"
  "$T" -q verify out/o.tets >/dev/null || fail "$mode: output invalid"
done
echo "disk_peak_cli: all checks passed"
