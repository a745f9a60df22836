#!/usr/bin/env bash
# The refiner's stopping rule against the accuracy it costs (issue 34; a benchmark, not a test):
# on the work directories bench/auto_vs_classical.sh leaves (features, matches and dataset per
# scene), the auto recipe from the same i.i.d. prior with several function tolerances. Prints per
# scene, level and tolerance: iterations (all passes, and the finish and anneal), the mean rotation
# error after Sim(3) against the ground truth, and the distance from the ftol 1e-10 solution
# (Sim(3)) beside the solve's own median rotation σ.
#
#   bench/stopping_rule.sh [SCENE_NAME ...]   (default: the four Strecha scenes)
#
# Environment: RAYTIME_BUILD (default build), IN (auto_vs_classical's OUT, default
# work/auto_vs_classical), OUT (default work/stopping_rule), LEVELS (default "0 8"), TOLERANCES
# (default "1e-10 1e-6 1e-5 1e-4"; the first is the reference).
set -euo pipefail
cd "$(dirname "$0")/.."

build=${RAYTIME_BUILD:-build}
in=${IN:-work/auto_vs_classical}
out=${OUT:-work/stopping_rule}
levels=${LEVELS:-0 8}
tolerances=${TOLERANCES:-1e-10 1e-6 1e-5 1e-4}
raytime=$build/cli/raytime
[[ -x $raytime ]] || { echo "error: $raytime not found; build it (scripts/build.sh)" >&2; exit 2; }
command -v jq > /dev/null || { echo "error: jq is not installed" >&2; exit 2; }
(($# > 0)) || set -- entry-P10 fountain-P11 Herz-Jesus-P8 castle-P19
mkdir -p "$out"

printf '%-14s %5s %7s %6s %10s %10s %14s %9s\n' scene level ftol iters "fin,anneal" \
  "error deg" "from ref deg" "sigma deg"
for scene in "$@"; do
  work=$in/$scene
  for file in dataset features matches; do
    [[ -f $work/$file.h5 ]] ||
      { echo "error: $work/$file.h5 missing; run bench/auto_vs_classical.sh first" >&2; exit 2; }
  done
  for level in $levels; do
    prior=$out/$scene-$level-prior.h5
    "$raytime" prior --in "$work/dataset.h5" --source perturb --mode iid --level_deg "$level" \
      --seed 0 --translation_per_deg 0.0125 --out "$prior" > /dev/null 2>&1
    reference=""
    for ftol in $tolerances; do
      result=$out/$scene-$level-$ftol
      "$raytime" refine --in "$work/dataset.h5" "$work/features.h5" "$work/matches.h5" "$prior" \
        --preset auto --function_tolerance "$ftol" --out "$result.h5" > "$result.json" \
        2> "$result.log"
      [[ -n $reference ]] || reference=$result.h5
      error=$("$raytime" evaluate --in "$work/dataset.h5" "$result.h5" --poses refined \
        --alignments sim3 --out "$out/evaluate.h5" 2>&1 |
        sed -n 's/.*refined (sim3): rotation mean \([0-9.]*\)°.*/\1/p' | head -n 1)
      distance=$("$raytime" evaluate --est "$reference" --est_format hdf5 --est_set refined \
        --gt "$result.h5" --gt_format hdf5 --gt_set refined --align sim3 2>&1 |
        sed -n 's/.*rotation mean \([0-9.]*\) median.*/\1/p' | head -n 1)
      jq -r --arg s "$scene" --arg l "$level" --arg f "$ftol" --arg e "$error" --arg d "$distance" '
        [$s, $l, $f, .total_iterations,
         ([.passes[] | select(.name | test("finish")) | .stages[].iterations] | map(tostring) | join(",")),
         $e, $d, .uncertainty.median_rotation_deg] | @tsv' "$result.json" |
        awk -F '\t' '{ printf "%-14s %5s %7s %6s %10s %10s %14s %9.5f\n", $1, $2, $3, $4, $5, $6, $7, $8 }'
    done
  done
done
