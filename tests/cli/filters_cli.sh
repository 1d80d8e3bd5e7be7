#!/usr/bin/env bash
# The command line as a filter and as people type it: `cat` keeps stdout for data (the
# --json summary on stderr or in --json-file, no log line unless -v), `cat --points
# --format f64` writes binary points, counts in scientific notation (`gen --n 1e6`), a
# misspelt subcommand gets the nearest name, the help says `tetstream` whatever the
# binary's path and ends its exit-code list with a newline; progress on a terminal
# fits its width and the merge reaches 100%.
# Usage: bash filters_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: filters_cli.sh /path/to/tetstream}")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
one_error_line() {  # FILE WORDS: one line, the prefix, the words
  [ "$(wc -l <"$1")" = 1 ] && grep -q '^tetstream: error: ' "$1" && grep -q -- "$2" "$1" || fail "error '$2': $(cat "$1")"
}

# gen: counts as people write them.
"$T" -q gen --n 1e3 --seed 1 -o a.f64
[ "$(stat -c %s a.f64)" = 24000 ] || fail "gen --n 1e3: $(stat -c %s a.f64) bytes"
"$T" -q gen --n 2.5E3 --seed 1 -o b.f64 --chunk 1e2
[ "$(stat -c %s b.f64)" = 60000 ] || fail "gen --n 2.5E3"
"$T" -q gen --n 1000 --seed 1 -o c.f64
cmp -s a.f64 c.f64 || fail "--n 1e3 and --n 1000 differ"
for bad in 1.5 1e30 -1e3 1e3x; do
  set +e; "$T" -q gen --n "$bad" -o bad.f64 2>err.txt; rc=$?; set -e
  [ $rc = 2 ] || fail "gen --n $bad: exit $rc"
  one_error_line err.txt "$bad"
  [ ! -e bad.f64 ] || fail "gen --n $bad wrote a file"
done

"$T" -q run a.f64 -o a.tets --memory 64M
tets=$("$T" -q --json info a.tets | python3 -c 'import json, sys; print(json.load(sys.stdin)["tets"])')

# cat: stdout is data only; quiet on a pipe unless -v.
"$T" cat a.tets >out.txt 2>err.txt
[ "$(wc -l <out.txt)" = "$tets" ] || fail "cat lines"
[ ! -s err.txt ] || fail "cat logged on a pipe: $(cat err.txt)"
"$T" cat a.tets --points >/dev/null 2>err.txt
[ ! -s err.txt ] || fail "cat --points logged: $(cat err.txt)"
"$T" -v cat a.tets >/dev/null 2>err.txt
grep -q "cat: .* tets (100.0%)" err.txt || fail "cat -v: no progress: $(cat err.txt)"
"$T" -v -q cat a.tets >/dev/null 2>err.txt
[ ! -s err.txt ] || fail "-q wins over -v"

# --json: the summary on stderr, never among the tets; --json-file: in the file.
"$T" --json cat a.tets >out2.txt 2>json.txt
cmp -s out.txt out2.txt || fail "cat --json changed stdout"
[ "$(python3 -c 'import json, sys; d = json.load(open("json.txt")); print(d["command"], d["tets"])')" = "cat $tets" ] ||
  fail "cat --json on stderr: $(cat json.txt)"
"$T" cat a.tets --json-file summary.json >out3.txt 2>err.txt
cmp -s out.txt out3.txt && [ ! -s err.txt ] || fail "cat --json-file changed stdout or stderr"
[ "$(python3 -c 'import json; print(json.load(open("summary.json"))["tets"])')" = "$tets" ] || fail "--json-file content"
"$T" -q --json-file gen.json gen --n 10 -o d.f64 >out4.txt
[ ! -s out4.txt ] && [ "$(python3 -c 'import json; print(json.load(open("gen.json"))["points"])')" = 10 ] ||
  fail "gen --json-file"
"$T" cat - --format u32 <a.tets --json >/dev/null 2>json2.txt || fail "cat - --json"
grep -q '"frames"' json2.txt || fail "cat - --json: $(cat json2.txt)"

# cat --points --format f64: 3 little-endian doubles a point, in label order, equal to
# the text output; tetstream reads it back as a raw .f64 point file.
"$T" cat a.tets --points --format f64 >pts.f64
[ "$(stat -c %s pts.f64)" = 24000 ] || fail "--points --format f64 size $(stat -c %s pts.f64)"
"$T" cat a.tets --points >pts.txt
python3 - <<'PY' || fail "--points f64 differs from text"
import struct
b = open("pts.f64", "rb").read()
xyz = struct.unpack("<%dd" % (len(b) // 8), b)
rows = [list(map(float, l.split()[:3])) for l in open("pts.txt")]
assert [v for r in rows for v in r] == list(xyz)
PY
[ "$("$T" -q --json info pts.f64 | python3 -c 'import json, sys; print(json.load(sys.stdin)["points"])')" = 1000 ] ||
  fail "info on cat --points --format f64"
set +e; "$T" -q cat a.tets --format f64 >/dev/null 2>err.txt; rc=$?; set -e
[ $rc = 2 ] || fail "--format f64 for tets: exit $rc"
one_error_line err.txt "--format f64 is for --points"

# A misspelt subcommand: the nearest name, one line, exit 2.
set +e; "$T" runn a.f64 2>err.txt; rc=$?; set -e
[ $rc = 2 ] || fail "runn: exit $rc"
one_error_line err.txt "unknown subcommand 'runn'; did you mean 'run'?"

# Help: `tetstream`, not the path it was run by; the exit codes end with a newline.
ln -s "$T" ./other-name
for t in "$T" ./other-name; do
  "$t" --help >help.txt
  grep -q '^Usage: tetstream \[OPTIONS\] SUBCOMMAND' help.txt || fail "usage line via $t: $(grep Usage help.txt)"
  ! grep -q "$dir\|other-name" help.txt || fail "help names the path"
  "$t" convert --help | grep -q '^Usage: tetstream convert' || fail "subcommand usage via $t"
done
[ "$(tail -c 1 help.txt | od -An -c | tr -d ' ')" = '\n' ] || fail "help does not end with a newline"
tail -2 help.txt | head -1 | grep -q '130  interrupted' || fail "exit codes last in --help"

# Progress on a terminal: each redraw fits the terminal's width (no trail of wrapped
# lines), and the merge's last line says 100%. `script` gives the job a terminal 50
# columns wide.
command -v script >/dev/null || fail "script(1) (bsdutils) is needed for the terminal check"
"$T" -q gen --n 1e6 --seed 3 -o prog.f64
script -qec "stty cols 50; '$T' run prog.f64 -o prog.tets --memory 256M --threads 1" pty.log >/dev/null
[ -s prog.tets ] || fail "run on a terminal wrote no output"
/usr/bin/env python3 - pty.log <<'PY' || fail "progress on a terminal"
import re, sys
s = open(sys.argv[1], 'rb').read().decode()
# Redraws: after "\r ESC[K", up to the next carriage return; the final lines are log
# lines (a timestamp in brackets), printed whole.
redraws = [r for r in re.findall(r'\r\x1b\[K([^\r\n]*)\r', s) if not r.startswith('[')]
assert redraws, "no progress redraws"
widest = max(len(r) for r in redraws)
assert widest <= 49, f"a redraw of {widest} columns on a 50-column terminal"
merged = [l for l in re.split(r'[\r\n]', s) if 'merging:' in l]
assert merged and '(100.0%)' in merged[-1], f"merge ended at {merged[-1:]}"
PY
echo "filters_cli: ok"
