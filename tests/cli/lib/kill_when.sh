# Sourced by the resume tests (resume_cli.sh, periodic_resume_cli.sh).
# kill_when CONDITION THREADS: starts "$T" --threads THREADS "${opts[@]}" --resume in
# the background, polls CONDITION (a shell command) every 5 ms, SIGKILLs the job when
# it holds and counts the kill in $kills. The job may finish first on a fast machine:
# that is fine (the callers' final comparison still holds).
kills=${kills:-0}
kill_when() {
  local condition=$1 threads=$2
  "$T" --threads "$threads" "${opts[@]}" --resume 2>/dev/null &
  local pid=$!
  for _ in $(seq 1 3000); do
    if ! kill -0 $pid 2>/dev/null; then break; fi
    if eval "$condition"; then kill -9 $pid 2>/dev/null && kills=$((kills + 1)); break; fi
    sleep 0.005
  done
  wait $pid 2>/dev/null || true
}
