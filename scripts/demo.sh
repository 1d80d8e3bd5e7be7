#!/usr/bin/env bash
# The main job on a built-in default, from a fresh machine: installs the dependencies,
# builds, generates points, triangulates them out of core under a memory budget,
# verifies the result independently, and prints a summary.
#
# Usage: scripts/demo.sh [N] [DIST] [MEMORY]     (defaults: 1000000 uniform 256M)
# Work files go to ${TETSTREAM_DEMO_DIR:-/tmp/tetstream-demo}.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
n=${1:-1000000}
dist=${2:-uniform}
memory=${3:-256M}
work=${TETSTREAM_DEMO_DIR:-/tmp/tetstream-demo}

"$root/scripts/setup.sh"
"$root/scripts/build.sh" "$root/build" >/dev/null
ts="$root/build/tools/tetstream"
mkdir -p "$work"

echo "== 1. generate $n $dist points"
"$ts" gen --dist "$dist" --n "$n" --seed 7 -o "$work/points.f64"
echo "== 2. triangulate out of core with --memory $memory"
"$ts" run "$work/points.f64" -o "$work/points.tets" --memory "$memory" --tmpdir "$work"
echo "== 3. verify the output independently"
"$ts" verify "$work/points.tets" --memory "$memory"
echo "== 4. summary"
"$ts" info "$work/points.tets"
