#!/usr/bin/env bash
# How the refiner's all-match solve scales with the capture (issue 14; a benchmark, not a test):
# synthetic corridor captures (testing/synthetic_capture.cc: 1,000 keypoints per frame, window 10,
# 5 % wrong matches, 0.5 px noise, a 2° i.i.d. prior) of increasing length, each solved by
# `raytime refine --preset basin --max_matches_per_pair 0` in its own process. Prints per size:
# matches, residuals, ray times, iterations, solve seconds, seconds per iteration, peak memory of
# the process (/usr/bin/time) and bytes per match; then the exponents of seconds per iteration and
# of peak memory against the number of matches (least squares on the logarithms).
#
#   bench/refine_scaling.sh [CAMERAS ...]      (default 100 200 500 1000 2000)
#
# Environment: RAYTIME_BUILD (default build), OUT (default work/refine_scaling), THREADS (default
# 0 = all cores).
set -euo pipefail
cd "$(dirname "$0")/.."

build=${RAYTIME_BUILD:-build}
out=${OUT:-work/refine_scaling}
threads=${THREADS:-0}
raytime=$build/cli/raytime
generator=$build/testing/synthetic_capture
for tool in "$raytime" "$generator"; do
  [[ -x $tool ]] || { echo "error: $tool not found; build it (scripts/build.sh)" >&2; exit 2; }
done
command -v jq > /dev/null || { echo "error: jq is not installed" >&2; exit 2; }
[[ -x /usr/bin/time ]] || { echo "error: /usr/bin/time is not installed (apt-get install time)" >&2; exit 2; }
sizes=("$@")
[[ ${#sizes[@]} -gt 0 ]] || sizes=(100 200 500 1000 2000)
mkdir -p "$out"

table=$out/table.tsv
printf 'cameras\tmatches\tresiduals\tray_times\titerations\tsolve_s\ts_per_iteration\tpeak_mb\tbytes_per_match\n' > "$table"
for n in "${sizes[@]}"; do
  scene=$out/scene$n
  if [[ ! -f $scene/prior.h5 ]]; then
    echo "== generating $n frames" >&2
    "$generator" --cameras "$n" --out "$scene" > "$scene.json"
  fi
  echo "== solving $n frames (log: $scene.log)" >&2
  /usr/bin/time -f '%M' -o "$scene.rss" "$raytime" refine \
      --in "$scene/dataset.h5" "$scene/features.h5" "$scene/matches.h5" "$scene/prior.h5" \
      --preset basin --max_matches_per_pair 0 --num_threads "$threads" \
      --out "$scene/refine.h5" > "$scene.summary.json" 2> "$scene.log"
  rss_kb=$(tail -n 1 "$scene.rss")
  jq -r --arg n "$n" --arg rss "$rss_kb" '
    .passes[0] as $p
    | [ $n, $p.num_matches_used, $p.num_residuals, $p.num_ray_times, .total_iterations,
        .timings.solve_seconds, (.timings.solve_seconds / .total_iterations),
        (($rss | tonumber) / 1024), (($rss | tonumber) * 1024 / $p.num_matches_used) ]
    | @tsv' "$scene.summary.json" >> "$table"
done

awk -F'\t' 'NR == 1 { printf "%-8s %10s %10s %9s %6s %9s %9s %9s %8s\n", "cameras", "matches",
                      "residuals", "ray times", "iters", "solve s", "s/iter", "peak MB", "B/match";
                      next }
            { printf "%-8s %10d %10d %9d %6d %9.2f %9.3f %9.1f %8.0f\n", $1, $2, $3, $4, $5, $6,
                     $7, $8, $9
              n++; x = log($2); sx += x; sxx += x * x
              yt = log($7); st += yt; sxt += x * yt
              ym = log($8); sm += ym; sxm += x * ym }
            END { if (n < 2) exit
                  d = n * sxx - sx * sx
                  printf "\nexponent against matches: seconds per iteration %.2f, peak memory %.2f\n",
                         (n * sxt - sx * st) / d, (n * sxm - sx * sm) / d }' "$table"
