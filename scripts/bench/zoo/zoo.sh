# Sourced by scripts/bench-pipeline --zoo: every member of the surface zoo beside uniform
# and clustered points, each timed out of core (`tetstream run --json` under
# /usr/bin/time -v) and in core (CGAL, the same points), one after another in one run,
# then one table (table.py). Uses $ts, $cb, $cgal, $dir, $threads, $memory, $run_args.
#
# Members: the generators (`gen --dist`, seed 7, $zoo_n points) and the real scans that
# Debian's libcgal-demo ships in /usr/share/doc/libcgal-dev/data.tar.gz (read as PLY,
# extra properties and all; their own sizes, so uniform is run at each of them too).

zoo_generated="uniform clusters terrain two-plates ellipsoid-shell hills roofs canopy water strips scan-lines survey indoor"
zoo_scans="building b9_training"
zoo_cgal_data=/usr/share/doc/libcgal-dev/data.tar.gz

# The PLY of a real scan, extracted once into $dir; nothing if the package is absent.
zoo_scan_ply() {
  local ply=$dir/$1.ply
  if [ ! -f "$ply" ] && [ -f "$zoo_cgal_data" ]; then
    tar -xzf "$zoo_cgal_data" -O "data/points_3/$1.ply" >"$ply.tmp" 2>/dev/null && mv "$ply.tmp" "$ply" || rm -f "$ply.tmp"
  fi
  [ -f "$ply" ] && echo "$ply"
}

# zoo_time MEMBER INPUT RAW_F64: one JSON line for table.py.
zoo_time() {
  local member=$1 input=$2 raw=$3 timelog out json peak cpu cg="null" cg_peak="null"
  timelog=$(mktemp)
  out=$dir/zoo.tets
  json=$(/usr/bin/time -v -o "$timelog" "$ts" -q --json --threads "$threads" run "$input" -o "$out" \
         --memory "$memory" --tmpdir "$dir" $run_args | tr -d "\n")
  peak=$(awk -F: '/Maximum resident/{print int($2/1024)}' "$timelog")
  cpu=$(awk -F: '/Percent of CPU/{gsub(/[ %]/,"",$2); print $2}' "$timelog")
  rm -f "$out"
  if ((cgal)); then
    cg=$(/usr/bin/time -v -o "$timelog" "$cb/cgal_incore" "$raw" | tr ' ' '\n' | awk -F= '/^total_s/{print $2}')
    cg_peak=$(awk -F: '/Maximum resident/{print int($2/1024)}' "$timelog")
  fi
  rm -f "$timelog"
  echo "{\"member\": \"$member\", \"peak_mib\": $peak, \"cpu\": \"$cpu\", \"cgal_s\": ${cg:-null}, \"cgal_peak_mib\": $cg_peak, \"run\": $json}"
}

bench_zoo() {
  local members=${zoo_members:-"$zoo_generated $zoo_scans"} records=$dir/zoo-$(date +%Y%m%d-%H%M%S).jsonl
  local uniform_sizes="" m pts ply
  echo "bench-pipeline --zoo: $(nproc) cores, $(free -g | awk '/Mem:/{print $2}') GiB, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), n $zoo_n, --memory $memory, --threads $threads${run_args:+, run $run_args}, load $(cut -d' ' -f1-3 /proc/loadavg)"
  for m in $members; do
    if [[ " $zoo_scans " == *" $m "* ]]; then
      ply=$(zoo_scan_ply "$m") || { echo "bench-pipeline: $m skipped ($zoo_cgal_data not found: apt-get install libcgal-demo)" >&2; continue; }
      pts=$dir/$m.f64
      [ -f "$pts" ] || python3 "$root/scripts/bench/zoo/ply_to_f64.py" "$ply" "$pts"
      uniform_sizes+=" $(($(stat -c %s "$pts") / 24))"
      zoo_time "$m" "$ply" "$pts" >>"$records"
    else
      pts=$dir/$m-$zoo_n.f64
      [ -f "$pts" ] || "$ts" -q gen --dist "$m" --n "$zoo_n" --seed 7 -o "$pts"
      zoo_time "$m" "$pts" "$pts" >>"$records"
    fi
  done
  # Uniform at each real scan's size: their ratio to uniform is to the same count.
  for n in $(echo "$uniform_sizes" | tr ' ' '\n' | sort -un); do
    [ "$n" = "$zoo_n" ] && continue
    pts=$dir/uniform-$n.f64
    [ -f "$pts" ] || "$ts" -q gen --dist uniform --n "$n" --seed 7 -o "$pts"
    zoo_time "uniform" "$pts" "$pts" >>"$records"
  done
  python3 "$root/scripts/bench/zoo/table.py" "$records" "$memory"
  echo "records: $records"
}
