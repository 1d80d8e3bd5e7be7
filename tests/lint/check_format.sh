#!/usr/bin/env bash
# Fails when a C++ source differs from what clang-format makes of it with the
# repository's .clang-format (the style is applied to every file; keep it so with
# `clang-format -i FILE`). Usage: check_format.sh SOURCE_ROOT
set -euo pipefail
root=${1:-.}
cd "$root"
command -v clang-format >/dev/null || { echo "check_format: clang-format is not installed (scripts/setup.sh installs it)"; exit 1; }
mapfile -t files < <(git ls-files -- '*.cpp' '*.hpp' '*.ipp' 2>/dev/null || find core io pipeline tools python tests scripts -name '*.[ch]pp' -o -name '*.ipp')
bad=0
for f in "${files[@]}"; do
  [ -f "$f" ] || continue
  if ! clang-format --dry-run --Werror "$f" >/dev/null 2>&1; then
    echo "$f: not formatted (clang-format -i $f)"
    bad=$((bad + 1))
  fi
done
echo "check_format: ${#files[@]} files, $bad not formatted"
[ "$bad" -eq 0 ]
