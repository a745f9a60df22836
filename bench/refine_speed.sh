#!/usr/bin/env bash
# Speed of the ray-time refiner against itself and the COLMAP classical control, measured in one
# run on one machine (issue 6; a benchmark, not a test). Runs bench/refine_speed.yaml and prints
# per arm: matches used, iterations, Jacobian evaluations and time, solve time, error after
# Sim(3); then the ratios: Ceres / the ray-time LM solver and the autodiff residual / Ceres'
# fixed-intrinsics residual (Jacobian time per evaluation, whole solve), GNC / plain, all matches /
# cap 100, classical control / cap 100 and / all matches, and solve time against the number of
# matches.
#
#   bench/refine_speed.sh [SCENE]      (default ../shared/data/strecha/fountain-P11)
#
# Environment: RAYTIME_BUILD (default build), OUT (default work/refine_speed/<scene name>).
set -euo pipefail
cd "$(dirname "$0")/.."

scene=${1:-../shared/data/strecha/fountain-P11}
build=${RAYTIME_BUILD:-build}
out=${OUT:-work/refine_speed/$(basename "$scene")}
raytime=$build/cli/raytime
[[ -x $raytime ]] || { echo "error: $raytime not found; build it (scripts/build.sh)" >&2; exit 2; }
command -v jq > /dev/null || { echo "error: jq is not installed" >&2; exit 2; }

echo "== raytime run bench/refine_speed.yaml on $scene (log: $out.log)"
mkdir -p "$(dirname "$out")"
"$raytime" run bench/refine_speed.yaml --workdir "$out" --set dataset.root="$scene" --force \
    > "$out.log" 2>&1 || { tail -n 20 "$out.log"; exit 1; }
summary=$out/summary.json

arm() {  # stage id -> "matches iterations jac_evals jac_s solve_s sim3_deg"
  jq -r --arg id "$1" '
    (.stages[] | select(.id == $id) | .summary) as $s
    | ($s.pose_set // "classical") as $p
    | [ ([$s.passes[]?.num_matches_used] | add // 0),
        ($s.total_iterations // 0),
        ([$s.passes[]?.stages[]?.jacobian_evaluations] | add // 0),
        ($s.timings.jacobian_seconds // 0),
        (.stages[] | select(.id == $id) | .seconds),
        .metrics[$p].sim3.mean_rotation_deg ] | @tsv' "$summary"
}

printf '\n%-20s %9s %6s %6s %10s %9s %10s\n' arm matches iters J-evals "J s/eval" "solve s" "sim3 deg"
declare -A matches solve jac_per_eval
for id in refine@all refine@all_ceres refine@all_nocache refine@all_plain refine@cap25 refine@cap50 \
          refine@cap100 refine@cap200 refine@cap400 refine@cap800 classical; do
  read -r m it je js s err < <(arm "$id")
  per=$(awk -v a="$js" -v b="$je" 'BEGIN { printf "%.4f", (b > 0 ? a / b : 0) }')
  matches[$id]=$m; solve[$id]=$s; jac_per_eval[$id]=$per
  printf '%-20s %9s %6s %6s %10s %9.2f %10.3f\n' "$id" "$m" "$it" "$je" "$per" "$s" "$err"
done

ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }
echo
echo "Ceres / ray-time LM, whole solve:            $(ratio "${solve[refine@all_ceres]}" "${solve[refine@all]}")x"
echo "autodiff / fixed residual (Ceres), J per eval: $(ratio "${jac_per_eval[refine@all_nocache]}" "${jac_per_eval[refine@all_ceres]}")x"
echo "autodiff / fixed residual (Ceres), solve:      $(ratio "${solve[refine@all_nocache]}" "${solve[refine@all_ceres]}")x"
echo "GNC / plain, whole solve (paper: about 2x):   $(ratio "${solve[refine@all]}" "${solve[refine@all_plain]}")x"
echo "all matches / cap 100, whole solve:           $(ratio "${solve[refine@all]}" "${solve[refine@cap100]}")x"
echo "classical control / raytime cap 100:          $(ratio "${solve[classical]}" "${solve[refine@cap100]}")x   (goal >= 2x)"
echo "classical control / raytime all matches:      $(ratio "${solve[classical]}" "${solve[refine@all]}")x   (goal >= 1x)"
echo
echo "solve time against the number of matches (cap: matches, seconds, seconds per 1000 matches):"
for id in refine@cap25 refine@cap50 refine@cap100 refine@cap200 refine@cap400 refine@cap800 refine@all; do
  awk -v id="$id" -v m="${matches[$id]}" -v s="${solve[$id]}" \
      'BEGIN { printf "  %-14s %8d %8.2f %8.3f\n", id, m, s, 1000 * s / m }'
done
