#!/usr/bin/env bash
# `pip install .` as docs/python.md shows it, offline: a fresh venv made with
# --system-site-packages (Debian's numpy, setuptools and wheel), then
# `pip install --no-build-isolation --no-index SRC`, with TETSTREAM_BUILD_DIR=BUILD so that
# the module and the binary built there are reused. The package then imports from the venv
# outside the source tree, and the venv's `tetstream` command runs every subcommand's
# --help and a gen/run/field/info job.
# Usage: bash pip_install_test.sh BUILD_DIR
set -euo pipefail
build=$(realpath "${1:?usage: pip_install_test.sh BUILD_DIR}")
src=$(cd "$(dirname "$0")/../.." && pwd)
scratch=$(mktemp -d)
[ -n "${KEEP_SCRATCH:-}" ] || trap 'rm -rf "$scratch"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
py=/usr/bin/python3  # Debian's, whose packages the venv sees

"$py" -m venv --system-site-packages "$scratch/venv" || fail "python3 -m venv (apt install python3-venv)"
venv="$scratch/venv"
cd "$scratch"
TETSTREAM_BUILD_DIR="$build" "$venv/bin/pip" install --no-build-isolation --no-index "$src" > pip.log 2>&1 ||
  fail "pip install: $(tail -20 pip.log)"
[ -x "$venv/bin/tetstream" ] || fail "pip installed no tetstream command: $(ls "$venv/bin")"
"$venv/bin/tetstream" --version | grep -q '^tetstream 0\.1\.0' || fail "tetstream --version"
for sub in gen run info cat verify field convert clean; do
  "$venv/bin/tetstream" "$sub" --help > /dev/null || fail "tetstream $sub --help"
done
"$venv/bin/tetstream" -q gen --n 3000 --seed 2 -o p.f64
"$venv/bin/tetstream" -q run p.f64 -o p.tets --no-checkpoint
"$venv/bin/tetstream" -q field p.tets -o f --density dtfe > /dev/null
[ -s f.density.npy ] || fail "field from the venv's command"
"$venv/bin/python" - "$venv" <<'PY' || fail "the installed package"
import os, sys
import numpy as np
import tetstream
venv = os.path.realpath(sys.argv[1])
assert os.path.realpath(tetstream.__file__).startswith(venv), tetstream.__file__
with tetstream.open("p.tets") as f:
    assert f.n_points == 3000 and f.n_tets > 0
tri = tetstream.delaunay(np.fromfile("p.f64").reshape(-1, 3))
assert tri.nsimplex == tetstream.open("p.tets").n_tets
PY
echo "pip install test: passed"
