#!/usr/bin/env bash
# Every writer keeps the promises `run` keeps, and no reader misjudges a file (issue
# #35, docs/safety.md). Each block is one defect of the audit, run as a user would, in a
# scratch tree with the user's files next door:
#   1. field checks the points' CRC; a damaged frame is one line and exit 1 (no abort),
#      and field's temporary directory goes;
#   2. verify accepts the correct output of points on a slanted plane, and of a small
#      cloud with three points from 1e20 to DBL_MAX on a plane through it;
#   3. --json-file never replaces the input or the output;
#   4. convert never replaces a file beside its output that it did not write (the
#      .h5 of an .xdmf); field never replaces its --mass file;
#   5. gen: no link followed, no link, fifo or device replaced, one job per output;
#   6. --resume never writes through links planted in its checkpoint;
#   7. a copied work-directory marker does not make a directory tetstream's (clean,
#      run's clean-up);
#   8. clean removes a killed field's neighbour rows and a stale checkpoint's
#      OUT.partial;
#  10. gen refuses counts that wrap, plans the disk, bounds --clusters;
#  11. a text file with a UTF-8 BOM; cat into its own input; --checkpoint DIR missing.
# Usage: bash writers_cli.sh /path/to/tetstream [BLOCK...]   (default: all)
set -euo pipefail
T=$(realpath "${1:?usage: writers_cli.sh /path/to/tetstream [BLOCK...]}")
shift
blocks=" ${*:-1 2 3 4 5 6 7 8 10 11} "
want() { [[ $blocks == *" $1 "* ]]; }
dir=$(mktemp -d)
trap 'chmod -R u+w "$dir" 2>/dev/null; rm -rf "$dir"' EXIT
cd "$dir"
mkdir tmp
export TMPDIR=$dir/tmp
fail() { echo "FAIL: $*" >&2; exit 1; }
flip() {  # flips the low bit of byte $2 of file $1
  python3 - "$1" "$2" <<'EOF'
import sys
with open(sys.argv[1], "r+b") as f:
    f.seek(int(sys.argv[2])); b = f.read(1); f.seek(int(sys.argv[2])); f.write(bytes([b[0] ^ 1]))
EOF
}
# expect CODE PATTERN CMD...: exit code CODE and one stderr line matching PATTERN.
expect() {
  local code=$1 pattern=$2
  shift 2
  local rc=0
  "$@" 2>err.txt >/dev/null || rc=$?
  [ "$rc" -eq "$code" ] || fail "exit $rc, not $code: $* ($(cat err.txt))"
  grep -q -- "$pattern" err.txt || fail "no '$pattern' in the error of $*: $(cat err.txt)"
  [ "$(grep -c 'error' err.txt)" -le 1 ] || fail "more than one error line from $*: $(cat err.txt)"
}
"$T" -q gen --n 20000 --seed 3 -o u.f64
"$T" -q run u.f64 -o c.tets --memory 64M
cp c.tets good.tets
# Several sort runs and segments, for the faults injected below.
small=(--memory 64M --zone-points 3000 --sort-run-points 6000)

if want 1; then
  # A flipped bit in the points section: field refuses, as verify does.
  flip c.tets 300000
  expect 1 "checksum" "$T" -q field c.tets -o f --density dtfe
  [ ! -e f.density.npy ] || fail "field wrote densities from damaged points"
  cp good.tets c.tets
  # A flipped bit in a frame: one line, exit 1, not SIGABRT; nothing left in TMPDIR.
  flip c.tets 700000
  for what in "--density dtfe" "--neighbours" "--voronoi-volume"; do
    expect 1 "c.tets" "$T" -q field c.tets -o f $what
    [ -z "$(ls tmp)" ] || fail "field $what left $(ls tmp)"
  done
  cp good.tets c.tets
  "$T" -q field c.tets -o f --density dtfe >/dev/null
  [ -s f.density.npy ] || fail "field on the intact container wrote nothing"
  rm -f f.*
fi

if want 2; then
  # 2000 points on the plane z = 0.1 x + 0.3 y (a roof, a wall).
  python3 - <<'EOF'
import random, struct
r = random.Random(4)
with open("plane.f64", "wb") as f:
    for _ in range(2000):
        x, y = r.random(), r.random()
        f.write(struct.pack("<3d", x, y, 0.1 * x + 0.3 * y))
# A small cloud, and three far points from 1e20 to DBL_MAX on a plane through it.
with open("far.f64", "wb") as f:
    for _ in range(300):
        f.write(struct.pack("<3d", r.random(), r.random(), r.random()))
    for p in ((1e20, 0.0, 0.5), (0.0, 1e200, 0.5), (-1.7976931348623157e308, -1.7976931348623157e308, 0.5)):
        f.write(struct.pack("<3d", *p))
EOF
  for name in plane far; do
    "$T" -q run $name.f64 -o $name.tets
    "$T" -q verify $name.tets >verify.txt 2>&1 || fail "verify rejects run's output of $name.f64: $(cat verify.txt)"
  done
  # It still finds a broken output: the tets of another point set.
  "$T" -q verify good.tets >/dev/null || fail "verify rejects a good container"
fi

if want 3; then
  cp u.f64 p.f64
  expect 2 "p.f64" "$T" -q --json-file p.f64 info p.f64
  cmp -s p.f64 u.f64 || fail "--json-file replaced the input"
  expect 2 "o.tets" "$T" -q run p.f64 -o o.tets --json-file o.tets --no-checkpoint
  "$T" -q info o.tets --check >/dev/null || fail "--json-file replaced the finished container"
  "$T" -q --json-file s.json info p.f64 >/dev/null
  grep -q '"command"' s.json || fail "--json-file to a new file wrote no summary"
  rm -f o.tets s.json
fi

if want 4; then
  # The .h5 beside an .xdmf: a file of the same name that convert did not write stays.
  if "$T" convert --help 2>/dev/null | grep -q xdmf && "$T" -q convert good.tets probe.xdmf 2>/dev/null; then
    rm -f probe.xdmf probe.h5
    echo "the HDF5 snapshot" > snap.h5
    "$T" -q run u.f64 -o snap.tets --no-checkpoint
    expect 2 "snap.h5" "$T" -q convert snap.tets snap.xdmf
    [ "$(cat snap.h5)" = "the HDF5 snapshot" ] || fail "convert replaced snap.h5"
    [ ! -e snap.xdmf ] && [ ! -e snap.xdmf.partial ] || fail "convert left an .xdmf behind"
    # A rerun replaces its own pair.
    "$T" -q convert snap.tets other.xdmf && "$T" -q convert snap.tets other.xdmf || fail "convert cannot rerun"
  fi
  echo "tetgen elements of mine" > mine.ele
  expect 2 "mine.ele" "$T" -q convert good.tets mine.node
  [ "$(cat mine.ele)" = "tetgen elements of mine" ] || fail "convert replaced mine.ele"
  # field's --mass file is an input: never an output.
  "$T" -q field good.tets -o m --density dtfe
  cp m.density.npy masses.npy
  expect 2 "m.density.npy" "$T" -q field good.tets -o m --density dtfe --mass m.density.npy
  cmp -s m.density.npy masses.npy || fail "field replaced its --mass file"
fi

if want 5; then
  echo victim > victim.txt
  ln -s victim.txt out.f64.partial
  expect 2 "out.f64.partial" "$T" -q gen --n 1000 -o out.f64
  [ "$(cat victim.txt)" = victim ] || fail "gen wrote through a link at OUT.partial"
  rm out.f64.partial
  ln victim.txt out.f64.partial
  expect 2 "out.f64.partial" "$T" -q gen --n 1000 -o out.f64
  [ "$(cat victim.txt)" = victim ] || fail "gen wrote through a hard link at OUT.partial"
  rm out.f64.partial
  ln -s victim.txt link.f64
  expect 2 "link.f64" "$T" -q gen --n 1000 -o link.f64
  [ -L link.f64 ] && [ "$(cat victim.txt)" = victim ] || fail "gen replaced a link"
  mkfifo fifo.f64
  expect 2 "fifo.f64" "$T" -q gen --n 1000 -o fifo.f64
  [ -p fifo.f64 ] || fail "gen replaced a fifo"
  # Two jobs on one output: the second is refused, the first finishes alone.
  # (The first is stopped while it writes, so that the second surely meets it.)
  "$T" -q gen --n 1e6 -o two.f64 --chunk 1000 &
  first=$!
  for _ in $(seq 200); do [ -s two.f64.partial ] && break; sleep 0.01; done
  kill -STOP $first
  rc=0
  "$T" -q gen --n 1000 --seed 9 -o two.f64 2>err.txt || rc=$?
  kill -CONT $first
  [ $rc = 2 ] && grep -q "another tetstream process" err.txt || fail "a second gen on one output: exit $rc: $(cat err.txt)"
  wait $first || fail "the first gen failed"
  [ "$(stat -c %s two.f64)" = 24000000 ] || fail "two gen jobs mixed their output"
  "$T" -q gen --n 1e6 -o alone.f64
  cmp -s two.f64 alone.f64 || fail "the first gen's output was disturbed"
  rm -f two.f64 alone.f64
fi

if want 6; then
  # A job stopped after its first sort run; links planted at every name the resumed
  # job writes in its checkpoint.
  "$T" -q run u.f64 -o ref.tets "${small[@]}" --no-checkpoint
  rc=0
  TETSTREAM_FAULT=sort-run:1 "$T" -q run u.f64 -o r.tets "${small[@]}" 2>/dev/null || rc=$?
  [ $rc = 3 ] && [ -d r.tets.ckpt ] || fail "the injected fault did not stop the job with its checkpoint ($rc)"
  echo victim > victim.txt
  cd r.tets.ckpt
  for name in state.json.tmp hull.labels.tmp $(seq -f 'points-%g.run' 0 40) $(seq -f 'points-%g.run.hull' 0 40) \
              $(seq -f 'pending-%g.tets.tmp' 0 40) $(seq -f 'pending-%g.tets' 0 40); do
    [ -e $name ] || [ -L $name ] || ln -s ../victim.txt $name
  done
  cd ..
  rc=0
  "$T" -q run u.f64 -o r.tets "${small[@]}" --resume 2>err.txt || rc=$?
  [ "$(cat victim.txt)" = victim ] || fail "--resume wrote through a link in its checkpoint"
  [ $rc = 0 ] || fail "--resume failed: $(cat err.txt)"
  cmp -s <("$T" -q cat r.tets) <("$T" -q cat ref.tets) || fail "the resumed job's tets differ"
  rm -rf r.tets r.tets.ckpt r.tets.partial ref.tets
fi

if want 7; then
  # A real checkpoint, copied: the copy is the user's, with the marker.
  rc=0
  TETSTREAM_FAULT=write:2 "$T" -q run u.f64 -o k.tets "${small[@]}" 2>/dev/null || rc=$?
  [ $rc = 3 ] && [ -d k.tets.ckpt ] || fail "the injected fault did not keep a checkpoint ($rc)"
  mkdir backup
  cp -a k.tets.ckpt backup/copy
  echo "chapter 1" > backup/copy/points-1.run
  echo "my notes" > backup/copy/hull.labels
  "$T" -q clean --checkpoints backup
  [ "$(cat backup/copy/points-1.run)" = "chapter 1" ] && [ -e backup/copy/state.json ] ||
    fail "clean removed files of a directory holding a copied marker"
  # run's own clean-up of stale temporary directories beside its work.
  mkdir -p side/tetstream-run-abc123
  cp k.tets.ckpt/.tetstream-workdir side/tetstream-run-abc123/
  echo "my state" > side/tetstream-run-abc123/state.json
  "$T" -q run u.f64 -o side/x.tets --no-checkpoint --tmpdir side
  [ "$(cat side/tetstream-run-abc123/state.json)" = "my state" ] || fail "run removed a sibling with a copied marker"
  # The genuine one is still recognised and removed.
  "$T" -q clean --checkpoints .
  [ ! -e k.tets.ckpt ] || fail "clean --checkpoints kept a stale checkpoint"
  rm -rf backup side
fi

if want 8; then
  # A stale checkpoint's partial output goes with it.
  rc=0
  TETSTREAM_FAULT=write:2 "$T" -q run u.f64 -o z.tets "${small[@]}" 2>/dev/null || rc=$?
  [ -d z.tets.ckpt ] && [ -e z.tets.partial ] || fail "no checkpoint and partial output to clean ($rc)"
  "$T" -q clean --checkpoints .
  [ ! -e z.tets.ckpt ] && [ ! -e z.tets.partial ] || fail "clean --checkpoints left z.tets.partial"
  # A killed field --neighbours: its temporary directory and neighbour rows go.
  "$T" -q gen --n 400000 --seed 5 -o big.f64
  "$T" -q run big.f64 -o big.tets --no-checkpoint
  "$T" -q field big.tets -o nb --neighbours --memory 64M &
  job=$!
  for _ in $(seq 400); do compgen -G "tmp/tetstream-field-*/neighbour-rows.u32" >/dev/null && break; sleep 0.02; done
  kill -9 $job 2>/dev/null || true
  wait $job 2>/dev/null || true
  compgen -G "tmp/tetstream-field-*/neighbour-rows.u32" >/dev/null || fail "field --neighbours was not caught at work"
  "$T" -q clean tmp
  [ -z "$(ls tmp)" ] || fail "clean left $(ls tmp/*)"
  rm -rf tmp/* big.f64 big.tets nb.*
fi

if want 10; then
  # Guarded: a gen that took these counts would write until the disk is full.
  guarded() { (ulimit -f 2048; ulimit -v 8388608; exec timeout 20 "$@"); }
  expect 2 "whole number" guarded "$T" -q gen --n -1 -o w.f64
  expect 2 "whole number" guarded "$T" -q gen --n 18446744073709551616 -o w.f64
  expect 3 "not enough disk" guarded "$T" -q gen --n 1e18 -o w.f64
  [ ! -e w.f64 ] && [ ! -e w.f64.partial ] || fail "a refused gen left a file"
  expect 2 "clusters" guarded "$T" -q gen --dist clusters --clusters 1000000000 --n 10 -o w.f64
fi

if want 11; then
  printf '\xEF\xBB\xBF0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n' > bom.txt
  "$T" -q info bom.txt >/dev/null 2>err.txt || fail "a text file with a UTF-8 BOM is refused: $(cat err.txt)"
  "$T" -q run bom.txt -o bom.tets --no-checkpoint 2>err.txt || fail "run refuses a BOM: $(cat err.txt)"
  cp good.tets cc.tets
  rc=0
  "$T" -q cat cc.tets >> cc.tets 2>err.txt || rc=$?
  [ $rc = 2 ] || fail "cat into its own input: exit $rc"
  cmp -s cc.tets good.tets || fail "cat appended to its own input"
  expect 2 "does not exist" "$T" -q run u.f64 -o m.tets --checkpoint missing-dir
  [ ! -e m.tets ] && [ ! -e m.tets.partial ] && [ ! -e missing-dir ] || fail "a refused --checkpoint left files"
fi
echo "writers_cli: ok"
