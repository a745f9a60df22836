#!/usr/bin/env bash
# The auto recipe's refine stage against the COLMAP classical control (point_triangulator +
# bundle_adjuster from the same prior, on the same matches), both timed in the same run
# (summary.json stage seconds), on the shared Strecha scenes at prior levels 0° and 8° (issue 34;
# a benchmark, not a test). Prints per scene and level: both stage times, their ratio (goal
# <= 0.5) and both arms' mean rotation error after Sim(3).
#
#   bench/auto_vs_classical.sh [SCENE ...]   (default: the four scenes under ../shared/data/strecha)
#
# Environment: RAYTIME_BUILD (default build), OUT (default work/auto_vs_classical), LEVELS
# (default "0 8"), SEED (default 0). Features and matches are computed once per scene (the second
# level resumes from them).
set -euo pipefail
cd "$(dirname "$0")/.."

build=${RAYTIME_BUILD:-build}
out=${OUT:-work/auto_vs_classical}
levels=${LEVELS:-0 8}
seed=${SEED:-0}
raytime=$build/cli/raytime
[[ -x $raytime ]] || { echo "error: $raytime not found; build it (scripts/build.sh)" >&2; exit 2; }
command -v jq > /dev/null || { echo "error: jq is not installed" >&2; exit 2; }
if (($# == 0)); then
  set -- ../shared/data/strecha/{entry-P10,fountain-P11,Herz-Jesus-P8,castle-P19}
fi

printf '%-14s %5s %9s %11s %7s %10s %10s %6s\n' scene level "auto s" "classical s" ratio \
  "auto deg" "class. deg" "iters"
mkdir -p "$out"
for scene in "$@"; do
  name=$(basename "$scene")
  for level in $levels; do
    work=$out/$name
    log=$out/$name-$level.log
    "$raytime" run bench/auto_vs_classical.yaml --workdir "$work" --set dataset.root="$scene" \
      --set prior.level_deg="$level" --set prior.seed="$seed" > "$log" 2>&1 ||
      { echo "error: run failed, see $log" >&2; tail -n 5 "$log" >&2; exit 1; }
    cp "$work/summary.json" "$out/$name-$level.json"
    jq -r --arg scene "$name" --arg level "$level" '
      (.stages[] | select(.id == "refine@auto")) as $a
      | (.stages[] | select(.id == "classical")) as $c
      | [$scene, $level, $a.seconds, $c.seconds, $a.seconds / $c.seconds,
         .metrics["refined@auto"].sim3.mean_rotation_deg, .metrics.classical.sim3.mean_rotation_deg,
         $a.summary.total_iterations]
      | "\(.[0]) \(.[1]) \(.[2]) \(.[3]) \(.[4]) \(.[5]) \(.[6]) \(.[7])"' "$out/$name-$level.json" |
      awk '{ printf "%-14s %5s %9.2f %11.2f %7.2f %10.4f %10.4f %6d\n", $1, $2, $3, $4, $5, $6, $7, $8 }'
  done
done
