# Sourced by the resume tests (resume_cli.sh, periodic_resume_cli.sh).
#
# kill_at SITE:N THREADS: starts "$T" --threads THREADS "${opts[@]}" --resume in the
# background with TETSTREAM_STALL=SITE:N (pipeline/util/fault.hpp), so that it stops
# at that passage and says so on stderr, SIGKILLs it there and counts the kill in
# $kills. The moment does not depend on the machine's speed: a job that ends without
# reaching it fails the test (the caller orders the sites along the job).
#
# kill_when CONDITION THREADS: the same, killed when CONDITION (a shell command,
# polled every 5 ms) holds; the job may end first on a fast or a loaded machine (a
# random moment, a short phase), so these kills are counted in $random_kills only and
# no test depends on their number.
kills=${kills:-0}
random_kills=${random_kills:-0}
kill_at() {
  local site=$1 threads=$2
  TETSTREAM_STALL=$site "$T" --threads "$threads" "${opts[@]}" --resume 2>stall.err &
  local pid=$! landed=0
  while kill -0 $pid 2>/dev/null; do
    if grep -qF "stalled at $site " stall.err; then kill -9 $pid && landed=1; break; fi
    sleep 0.005
  done
  wait $pid 2>/dev/null || true
  if ((!landed)); then
    echo "FAIL: the job ended without reaching $site: $(cat stall.err)" >&2
    exit 1
  fi
  rm -f stall.err
  kills=$((kills + 1))
}
kill_when() {
  local condition=$1 threads=$2
  "$T" --threads "$threads" "${opts[@]}" --resume 2>/dev/null &
  local pid=$!
  for _ in $(seq 1 3000); do
    if ! kill -0 $pid 2>/dev/null; then break; fi
    if eval "$condition"; then kill -9 $pid 2>/dev/null && random_kills=$((random_kills + 1)); break; fi
    sleep 0.005
  done
  wait $pid 2>/dev/null || true
}
