#!/usr/bin/env bash
# `tetstream info / cat` on .tets containers as a user runs them, on the golden files:
# the contract spellings, --frames, --original-ids, binary formats, an independent
# reading of the layout against docs/format.md, and damaged files (truncated, bit
# flip, wrong version, not a container) failing with exit 1 and a message naming the
# frame and byte offset.
# Usage: bash container_cli.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: container_cli.sh /path/to/tetstream}")
data=$(realpath "$(dirname "$0")/../data")
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cd "$dir"
fail() { echo "FAIL: $*" >&2; exit 1; }
json() { python3 -c "import json,sys; d=json.load(sys.stdin); print($1)"; }
cp "$data/golden_v1_f64_u32.golden" g.tets   # 64 points, 162 tets in 3 frames of 54
cp "$data/golden_v1_f32_u64.golden" w.tets   # 24 points, 36 tets, 64-bit labels
cp "$data/golden_v2_f64_u32.golden" b.tets   # version 2: 80 points, 216 tets in 4 frames

# Version 2 reads as version 1 does: info names it, cat gives every tet.
"$T" info b.tets | grep -q "container 2.0" || fail "info b.tets: $("$T" info b.tets)"
[ "$("$T" -q --json info b.tets | json "d['tets'], d['frames'], d['points']")" = "216 4 80" ] || fail "info b.tets --json"
[ "$("$T" -q cat b.tets | wc -l)" = 216 ] || fail "cat b.tets"
[ "$("$T" -q cat b.tets --original-ids | sort -u | wc -l)" = 216 ] || fail "cat b.tets --original-ids"

# info, text and --json.
"$T" info g.tets >info.txt 2>/dev/null
grep -q '^tets: *162 in 3 frames (32-bit labels)' info.txt || fail "info tets: $(cat info.txt)"
grep -q '^points: *64 (float64' info.txt || fail "info points"
grep -q '^made by: *tetstream golden' info.txt || fail "info tool"
i=$("$T" -q --json info g.tets)
[ "$(echo "$i" | json "d['tets'], d['frames'], d['points'], d['options']['frame_tets'], d['bytes_per_tet'] < 16")" = \
  "162 3 64 60 True" ] || fail "info --json: $i"
[ "$("$T" -q --json info w.tets | json "d['label_width'], d['coord_type'], d['tets']")" = "64 float32 36" ] || fail "info w"

# cat: text, frames, binary.
[ "$("$T" -q cat g.tets | wc -l)" = 162 ] || fail "cat lines"
"$T" -q cat g.tets | awk 'NF != 4 { exit 1 }' || fail "cat: 4 labels a line"
[ "$("$T" -q cat g.tets --frames 1:2 | wc -l)" = 54 ] || fail "--frames 1:2"
[ "$("$T" -q cat g.tets --frames 2 | wc -l)" = 54 ] || fail "--frames 2"
[ "$("$T" -q cat g.tets --frames 1: | wc -l)" = 108 ] || fail "--frames 1:"
[ "$("$T" -q cat g.tets --frames :1 | wc -l)" = 54 ] || fail "--frames :1"
[ "$("$T" -q cat g.tets --frames 1:1 | wc -l)" = 0 ] || fail "--frames 1:1"
cmp -s <("$T" -q cat g.tets --frames 0:3) <("$T" -q cat g.tets) || fail "--frames 0:3 differs from all"
cmp -s <("$T" -q cat g.tets --frames 0:1; "$T" -q cat g.tets --frames 1:3) <("$T" -q cat g.tets) || fail "frames concatenate"
set +e
"$T" -q cat g.tets --frames 2:5 >/dev/null 2>err.txt; rc=$?
set -e
[ $rc = 2 ] && grep -q 'frames 0..3' err.txt || fail "--frames out of range: rc $rc $(cat err.txt)"
"$T" -q cat g.tets --format u32 >t32.bin
"$T" -q cat g.tets --format u64 >t64.bin
[ "$(stat -c %s t32.bin)" = $((162 * 16)) ] && [ "$(stat -c %s t64.bin)" = $((162 * 32)) ] || fail "binary sizes"
"$T" -q cat g.tets | python3 -c "
import struct, sys
text = list(map(int, sys.stdin.read().split()))
b32, b64 = open('t32.bin', 'rb').read(), open('t64.bin', 'rb').read()
assert text == list(struct.unpack('<%dI' % len(text), b32)) == list(struct.unpack('<%dQ' % len(text), b64))
" || fail "text, u32 and u64 output differ"
[ "$("$T" -q cat w.tets | wc -l)" = 36 ] || fail "cat w.tets"
[ "$("$T" -q cat w.tets --format u32 | wc -c)" = $((36 * 16)) ] || fail "u32 of a 64-bit-label file with small labels"

# --original-ids maps every label through the stored permutation (cat --points: x y z id).
"$T" -q cat g.tets --points >points.txt
[ "$(wc -l <points.txt)" = 64 ] || fail "--points"
"$T" -q cat g.tets >labels.txt
"$T" -q cat g.tets --original-ids >orig.txt
awk 'NR == FNR { id[NR - 1] = $4; next } { print id[$1], id[$2], id[$3], id[$4] }' points.txt labels.txt >mapped.txt
cmp -s mapped.txt orig.txt || fail "--original-ids is not the permutation of --points"
! cmp -s labels.txt orig.txt || fail "--original-ids changed nothing"

# The layout, read independently of the C++ code, as docs/format.md describes it.
python3 - g.tets <<'EOF' || fail "layout does not follow docs/format.md"
import struct, sys
def crc32c(b):
    c = 0xFFFFFFFF
    for x in b:
        c ^= x
        for _ in range(8):
            c = (c >> 1) ^ (0x82F63B78 if c & 1 else 0)
    return c ^ 0xFFFFFFFF
f = open(sys.argv[1], "rb").read()
assert f[:8] == b"\x89TETS\r\n\x1a" and struct.unpack_from("<HHI", f, 8) == (1, 0, 0)
foot = f[-48:]
assert foot[40:] == b"TETSEND\x1a" and struct.unpack_from("<I", foot, 36)[0] == crc32c(foot[:36])
ix, tets, frames, points = struct.unpack_from("<QQQQ", foot, 0)
def section(off, tag):
    t, flags, n = struct.unpack_from("<4sIQ", f, off)
    assert t == tag and flags == 1, (t, tag)
    p = f[off + 16: off + 16 + n]
    assert struct.unpack_from("<I", f, off + 16 + n)[0] == crc32c(p), tag
    return p
idx = section(ix, b"INDX")
assert ix + 16 + len(idx) + 4 == len(f) - 48
(s,) = struct.unpack_from("<I", idx, 0)
dirs = [struct.unpack_from("<4sIQQ", idx, 4 + 24 * k) for k in range(s)]
assert [d[0] for d in dirs] == [b"HEAD", b"PNTS"]
head = section(dirs[0][2], b"HEAD")
n, inp, ct, lw, iw = struct.unpack_from("<QQBBB", head, 0)
assert (n, inp, ct, lw, iw) == (points, 70, 2, 32, 32)
pts = section(dirs[1][2], b"PNTS")
assert len(pts) == n * (3 * 8 + 4)
(nf,) = struct.unpack_from("<Q", idx, 4 + 24 * s)
assert nf == frames == 3
first = 0
for k in range(nf):
    off, ft, tc, ln, base, mx = struct.unpack_from("<QQIIQQ", idx, 4 + 24 * s + 8 + 40 * k)
    p = section(off, b"TETF")
    assert len(p) == ln and ft == first
    t, codec, ctx, res, b0, m0 = struct.unpack_from("<IBBHQQ", p, 0)
    sizes = struct.unpack_from("<6I", p, 24)
    assert (t, codec, res, b0, m0) == (tc, 1, 0, base, mx) and ctx <= 16 and 48 + sum(sizes) == ln
    at = 48
    for z in sizes:
        assert p[at:at + 4] == b"\x28\xb5\x2f\xfd", "each stream is a zstd frame"
        at += z
    first += tc
assert first == tets == 162
EOF

# Damaged files: exit 1, one line naming the file, byte offset and (for frames) the frame.
expect_bad() {  # expect_bad FILE PATTERN... (runs `cat`)
  local f=$1; shift
  set +e
  "$T" -q cat "$f" >/dev/null 2>err.txt
  local rc=$?
  set -e
  [ $rc = 1 ] || fail "$f: exit $rc, expected 1: $(cat err.txt)"
  [ "$(wc -l <err.txt)" = 1 ] || fail "$f: not one line: $(cat err.txt)"
  for p in "$@"; do grep -q -- "$p" err.txt || fail "$f: message lacks '$p': $(cat err.txt)"; done
}
size=$(stat -c %s g.tets)
head -c $((size / 2)) g.tets >cut.tets
expect_bad cut.tets "cut.tets: byte" "truncated"
head -c $((size - 1)) g.tets >cut1.tets
expect_bad cut1.tets "cut1.tets: byte"
# A bit flip inside frame 1 (its offset from the frame index, via the reader's layout).
frame1=$(python3 -c "
import struct; f=open('g.tets','rb').read(); ix=struct.unpack_from('<Q',f,len(f)-48)[0]
print(struct.unpack_from('<Q',f,ix+16+4+2*24+8+40)[0])")
python3 -c "
f=bytearray(open('g.tets','rb').read()); f[$frame1+16+100]^=0x20; open('flip.tets','wb').write(f)"
expect_bad flip.tets "flip.tets: byte $frame1:" "frame 1" "checksum mismatch"
python3 -c "
f=bytearray(open('g.tets','rb').read()); f[8]=3; open('v3.tets','wb').write(f)"
expect_bad v3.tets "v3.tets: byte 8:" "unsupported container version 3.0"
echo "not a container" >text.tets
expect_bad text.tets "text.tets: byte 0:" "not a .tets container"
set +e
"$T" -q info cut.tets >/dev/null 2>err.txt
rc=$?
set -e
[ $rc = 1 ] && grep -q truncated err.txt || fail "info on a truncated file: rc $rc $(cat err.txt)"
echo "container_cli: ok"
