# Sourced by the bench scripts: the tetstream binary to time, in $ts.
# TETSTREAM names one already built (a copy carried to a machine without the build's
# dependencies, or the build before a change, to time beside it); otherwise the build
# tree $root/build is brought up to date and its binary used.
if [ -n "${TETSTREAM:-}" ]; then
  ts=$TETSTREAM
  [ -x "$ts" ] || { echo "$(basename "$0"): TETSTREAM=$ts is not an executable" >&2; exit 2; }
else
  "$root/scripts/build.sh" "$root/build" >/dev/null
  ts=$root/build/tools/tetstream
fi
