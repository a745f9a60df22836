#!/usr/bin/env bash
# Front end vs COLMAP 3.8 on one Strecha-layout scene, measured in the same run (issue 3; a
# benchmark, not a test).
#
#   bench/frontend_vs_colmap.sh [SCENE]      (default ../shared/data/strecha/fountain-P11)
#
# Environment: RAYTIME_BUILD (build folder with cli/raytime and bench/match_quality; default
# build), OUT (work folder; default work/frontend_vs_colmap/<scene name>; replaced).
#
# raytime: bench/frontend.yaml (SIFT 8192 features, first octave -1, exhaustive matching with
# guided re-matching); time = its features + matches stages as recorded in summary.json.
# COLMAP: feature_extractor (CPU SIFT, 8192 features, one PINHOLE camera from the ground-truth K
# with the principal point moved by +0.5 px into COLMAP's pixel convention) and
# exhaustive_matcher (CPU, guided matching); time = wall clock of the two commands.
# Verified inliers: raytime's matches summary; COLMAP's sum of two_view_geometries.rows over
# pairs with a verified configuration (config >= 2) and at least 15 inliers, i.e. what COLMAP
# itself would use. Prints both and the ratios, then the match quality of raytime's matches
# against the ground truth (bench/match_quality).
set -euo pipefail
cd "$(dirname "$0")/.."

scene=${1:-../shared/data/strecha/fountain-P11}
build=${RAYTIME_BUILD:-build}
out=${OUT:-work/frontend_vs_colmap/$(basename "$scene")}
raytime=$build/cli/raytime
quality=$build/bench/match_quality

for tool in "$raytime" "$quality"; do
  if [[ ! -x $tool ]]; then
    echo "error: $tool not found; build it: cmake -S . -B $build -G Ninja" \
         "-DCMAKE_BUILD_TYPE=Release && ninja -C $build raytime match_quality" >&2
    exit 2
  fi
done
for tool in colmap sqlite3 jq; do
  command -v "$tool" > /dev/null || { echo "error: $tool is not installed" >&2; exit 2; }
done
camera=$(ls "$scene"/gt_dense_cameras/*.camera 2> /dev/null | head -n 1)
if [[ -z $camera ]]; then
  echo "error: $scene/gt_dense_cameras has no .camera file (expected the Strecha layout)" >&2
  exit 2
fi

rm -rf "$out"
mkdir -p "$out/colmap"
now() { date +%s.%N; }
seconds() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }

echo "== raytime (features + matches) on $scene"
"$raytime" run bench/frontend.yaml --workdir "$out/raytime" --set dataset.root="$scene" \
    --force > "$out/raytime.log" 2>&1 || { tail -n 20 "$out/raytime.log"; exit 1; }
summary=$out/raytime/summary.json
rt_extract=$(jq '.stages[] | select(.type == "features") | .seconds' "$summary")
rt_match=$(jq '.stages[] | select(.type == "matches") | .seconds' "$summary")
rt_inliers=$(jq '.stages[] | select(.type == "matches") | .summary.num_inliers' "$summary")
rt_pairs=$(jq '.stages[] | select(.type == "matches") | .summary.num_verified_pairs' "$summary")
rt_total=$(awk -v a="$rt_extract" -v b="$rt_match" 'BEGIN { printf "%.1f", a + b }')

echo "== COLMAP 3.8 feature_extractor + exhaustive_matcher (guided), CPU"
# K rows 1 and 2 of the Strecha camera file: fx 0 cx / 0 fy cy (OpenCV pixel convention).
params=$(awk 'NR == 1 { fx = $1; cx = $3 } NR == 2 { fy = $2; cy = $3 }
              END { printf "%.6f,%.6f,%.6f,%.6f", fx, fy, cx + 0.5, cy + 0.5 }' "$camera")
db=$out/colmap/database.db
t0=$(now)
colmap feature_extractor --database_path "$db" --image_path "$scene/images" \
    --ImageReader.camera_model PINHOLE --ImageReader.single_camera 1 \
    --ImageReader.camera_params "$params" \
    --SiftExtraction.use_gpu 0 --SiftExtraction.max_num_features 8192 \
    > "$out/colmap/extract.log" 2>&1 || { tail -n 20 "$out/colmap/extract.log"; exit 1; }
t1=$(now)
colmap exhaustive_matcher --database_path "$db" \
    --SiftMatching.use_gpu 0 --SiftMatching.guided_matching 1 \
    > "$out/colmap/match.log" 2>&1 || { tail -n 20 "$out/colmap/match.log"; exit 1; }
t2=$(now)
cm_extract=$(seconds "$t0" "$t1")
cm_match=$(seconds "$t1" "$t2")
cm_total=$(seconds "$t0" "$t2")
cm_inliers=$(sqlite3 "$db" \
    "SELECT COALESCE(SUM(rows), 0) FROM two_view_geometries WHERE config >= 2 AND rows >= 15;")
cm_pairs=$(sqlite3 "$db" \
    "SELECT COUNT(*) FROM two_view_geometries WHERE config >= 2 AND rows >= 15;")
cm_keypoints=$(sqlite3 "$db" "SELECT SUM(rows) FROM keypoints;")
rt_keypoints=$(jq '.stages[] | select(.type == "features") | .summary.num_keypoints' "$summary")

printf '\n%-8s %10s %10s %10s %10s %14s %10s\n' "" "extract s" "match s" "total s" \
    "keypoints" "verified pairs" "inliers"
printf '%-8s %10s %10s %10s %10s %14s %10s\n' raytime "$(printf %.1f "$rt_extract")" \
    "$(printf %.1f "$rt_match")" "$rt_total" "$rt_keypoints" "$rt_pairs" "$rt_inliers"
printf '%-8s %10s %10s %10s %10s %14s %10s\n' COLMAP "$cm_extract" "$cm_match" "$cm_total" \
    "$cm_keypoints" "$cm_pairs" "$cm_inliers"
awk -v rt="$rt_total" -v cm="$cm_total" -v ri="$rt_inliers" -v ci="$cm_inliers" 'BEGIN {
  printf "speed-up (COLMAP time / raytime time): %.1fx   (target >= 5x)\n", cm / rt
  printf "inliers (raytime / COLMAP): %.1f %%   (target >= 90 %%)\n", 100 * ri / ci }'

echo
"$quality" --workdir "$out/raytime"
