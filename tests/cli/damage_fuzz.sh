#!/usr/bin/env bash
# The fuzz tier of the safety promises (docs/safety.md): seeded random damage to
# checkpoints and containers for about 90 seconds (scripts/fuzz-damage; longer runs by
# hand, e.g. scripts/fuzz-damage --seconds 3600 --seed 1000). The seed changes with the
# day, so CI explores new cases over time; a failure prints its seed to replay.
# Usage: bash damage_fuzz.sh /path/to/tetstream
set -euo pipefail
T=$(realpath "${1:?usage: damage_fuzz.sh /path/to/tetstream}")
seed=$(( $(date +%j) * 1000 ))
# TETSTREAM_PYTHON (set by CTest): an interpreter with numpy, for the Python reader's cases.
exec python3 "$(dirname "$0")/../../scripts/fuzz-damage" --binary "$T" --seconds 90 --seed "$seed" \
  --python "${TETSTREAM_PYTHON:-python3}"
