#!/usr/bin/env bash
# Containers through pipes: `run -o -` streams the container to stdout (the same bytes
# as a file), `cat -` reads one as it is written, checking every frame and, at the
# end, the index and footer (a cut or extended stream fails, exit 1); `convert -` and
# `verify -` read from stdin too; --json goes to stderr; a stream cannot be resumed;
# a reader that closes the pipe ends the job quietly, as it ends `cat` or `seq` (exit 0,
# no message, nothing left behind).
# Usage: bash stream_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: stream_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }

"$T" -q gen --dist clusters --n 30000 --seed 4 -o p.f64
run=(-q run p.f64 --memory 128M --zone-points 3000)
"$T" "${run[@]}" -o file.tets --no-checkpoint
"$T" "${run[@]}" -o - >piped.tets
cmp -s file.tets piped.tets || fail "run -o - wrote other bytes than run -o FILE"
ls -A | grep -q -- '^-$' && fail "run -o - made a file named -"

"$T" "${run[@]}" -o - | "$T" -q cat - --format u64 >streamed.u64
"$T" -q cat file.tets --format u64 >file.u64
cmp -s streamed.u64 file.u64 || fail "cat - printed other tets"
"$T" -q cat - --original-ids <file.tets >ids.txt
"$T" -q cat file.tets --original-ids >ids_file.txt
cmp -s ids.txt ids_file.txt || fail "cat - --original-ids differs"

size=$(stat -c %s file.tets)
for cut in 10 5000 $((size / 2)) $((size - 30)); do
  rc=0; head -c "$cut" file.tets | "$T" -q cat - >/dev/null 2>err.txt || rc=$?
  [ $rc = 1 ] || fail "a stream cut at $cut bytes: exit $rc"
  grep -q "standard input: byte" err.txt || fail "the cut stream's error names no offset: $(cat err.txt)"
done
rc=0; { cat file.tets; echo extra; } | "$T" -q cat - >/dev/null 2>err.txt || rc=$?
[ $rc = 1 ] && grep -q "after the footer" err.txt || fail "bytes after the footer: exit $rc $(cat err.txt)"

"$T" "${run[@]}" -o - | "$T" -q convert - mesh.vtu
[ -s mesh.vtu ] || fail "convert - made no mesh"
"$T" -q verify - <file.tets >/dev/null || fail "verify - rejected a valid container"

"$T" -q --json "${run[@]}" -o - 2>summary.json >json.tets
cmp -s json.tets file.tets || fail "--json with -o - changed the container on stdout"
grep -q '"command": "run"' summary.json || fail "--json with -o - wrote no summary on stderr"

rc=0; "$T" "${run[@]}" -o - --resume >/dev/null 2>err.txt || rc=$?
[ $rc = 2 ] && grep -q "cannot be resumed" err.txt || fail "--resume with -o -: exit $rc $(cat err.txt)"

set +o pipefail
"$T" "${run[@]}" -o - 2>err.txt | head -c 1000 >/dev/null
rc=${PIPESTATUS[0]}
set -o pipefail
[ "$rc" = 0 ] || fail "a closed pipe: exit $rc ($(cat err.txt))"
[ ! -s err.txt ] || fail "a closed pipe: a message ($(cat err.txt))"
ls -d tetstream-run-* 2>/dev/null && fail "a closed pipe left the job's temporary directory"
echo "stream_cli: all checks passed"
