#!/usr/bin/env bash
# The capture job end to end on phone-capture folders built from Strecha scenes (issue 10,
# must-shows (b) and (c); a benchmark, not a test). For each scene:
#   colmap     the reference: the scene (images + its K) as dataset, the prior as a COLMAP text model
#              (prior.source file): the route raytime had before captures
#   record3d   a Record3D export (rgb/<i>.jpg + metadata.json)        \  images + the app's poses
#   polycam    a Polycam raw export (keyframes/corrected_*, cameras/)  |  only, no ground truth in
#   stray      a Stray Scanner folder: rgb.mp4 (the images as a video  |  the folder
#              at FPS, CODEC), odometry.csv at ODOMETRY_HZ,            |
#              camera_matrix.csv                                       /
# The app's poses (and the COLMAP prior) are the scene's ground truth perturbed by the ladder
# protocol at LEVEL degrees, seed SEED (configs/ladder.yaml: the same draws as `prior: {source:
# perturb, level_deg: LEVEL, seed: SEED}`), written by tests/capture_fixture_tool. Each arm runs
#   raytime run configs/capture.yaml --workdir W --set dataset.format=F --set dataset.root=FOLDER
# unchanged (refine preset gnc), plus SETS (e.g. SETS="refine.preset=basin", VARIANT=basin), and is
# scored afterwards against the scene's ground truth with `raytime evaluate --gt_format strecha`
# (Sim(3) and none; the capture arms against a Strecha layout of links to the scene's files under
# the capture's image names, kept outside the capture folder).
#
#   bench/capture_fixture_e2e.sh [OUT]          (default work/capture-e2e)
#
# Environment: RAYTIME_BUILD (default build; needs cli/raytime and tests/capture_fixture_tool),
# DATA (default ../shared/data/strecha), SCENES (default "fountain-P11 Herz-Jesus-P8"), ARMS
# (default "colmap record3d polycam stray"), LEVEL (8), SEED (0), FPS (10), ODOMETRY_HZ (30),
# CODEC (avc1: H.264; mp4v: MPEG-4 Part 2; both written by Debian's OpenCV 4.6 and decoded),
# SETS (extra --set KEY=VALUE for every arm, space-separated), VARIANT (suffix of the arm folders
# when SETS is given), NICE (5). Rerunning skips finished stages (the stage cache); delete OUT to
# start over. Writes OUT/results.jsonl (one line per arm and alignment) and OUT/table.md.
set -euo pipefail
cd "$(dirname "$0")/.."

out=${1:-work/capture-e2e}
build=${RAYTIME_BUILD:-build}
data=${DATA:-../shared/data/strecha}
scenes=${SCENES:-"fountain-P11 Herz-Jesus-P8"}
arms=${ARMS:-"colmap record3d polycam stray"}
level=${LEVEL:-8}
seed=${SEED:-0}
fps=${FPS:-10}
odometry_hz=${ODOMETRY_HZ:-30}
codec=${CODEC:-avc1}
variant=${VARIANT:-}
nice_level=${NICE:-5}
raytime="$build/cli/raytime"
tool="$build/tests/capture_fixture_tool"
for exe in "$raytime" "$tool"; do
  [[ -x $exe ]] || { echo "error: $exe not found (ninja -C $build raytime capture_fixture_tool)" >&2; exit 2; }
done
sets=()
for kv in ${SETS:-}; do sets+=(--set "$kv"); done
suffix=${variant:+@$variant}

mkdir -p "$out"
results="$out/results${suffix}.jsonl"
: > "$results"

# Scores pose set $2 of run $1 (arm $3) against ground truth $4 (Strecha layout) and appends one
# line per alignment to results.jsonl, with the run's status, warnings and time per stage.
score() {
  local run=$1 what=$2 arm=$3 gt=$4 scene=$5
  local est est_format est_set=""
  if [[ $what == refined && -d $run/refined ]]; then
    est=$run/refined est_format=colmap  # the export a user gets
  elif [[ $what == refined ]]; then
    est=$run/refine.h5 est_format=hdf5 est_set=refined  # export failed: the refine stage's poses
  else
    est=$run/prior.h5 est_format=hdf5 est_set=prior
  fi
  for align in sim3 none; do
    local json
    json=$("$raytime" evaluate --est "$est" --est_format "$est_format" ${est_set:+--est_set "$est_set"} \
             --gt "$gt" --gt_format strecha --align "$align" --json 2>/dev/null) || json=null
    /usr/bin/python3 - "$run" "$scene" "$arm" "$what" "$align" "$est" "$json" >> "$results" <<'PY'
import json, os, sys
run, scene, arm, what, align, est, errors = sys.argv[1:8]
errors = json.loads(errors)
summary = json.load(open(os.path.join(run, "summary.json")))
row = {"scene": scene, "arm": arm, "poses": what, "alignment": align, "scored": est,
       "status": summary.get("status"),
       "warnings": sorted({w["code"] for w in summary.get("warnings", [])}),
       "seconds": {}}
# A stage the stage cache skipped took 0 s in this run: its time is that of the run that made it
# (the `seconds` of its own summary; refine's timings.total_seconds; a video's decoding time).
for stage in summary.get("stages", []):
    s = stage.get("summary") or {}
    seconds = stage.get("seconds", 0.0)
    if stage.get("status") == "skipped":
        seconds = (s.get("seconds") or (s.get("timings") or {}).get("total_seconds") or
                   (s.get("video") or {}).get("seconds") or 0.0)
    row["seconds"][stage["id"]] = round(seconds, 2)
row["total_seconds"] = round(sum(row["seconds"].values()), 1)
for stage in summary.get("stages", []):
    s = stage.get("summary") or {}
    if stage["id"] == "dataset":
        row["num_images"] = s.get("num_images")
        row["dataset_warnings"] = [(w["code"], len(w.get("images", []))) for w in s.get("warnings", [])]
    if stage["id"] == "matches":
        row["num_pairs"] = s.get("num_pairs")
        row["num_verified_pairs"] = s.get("num_verified_pairs")
    if stage["id"] == "refine":
        row["guardrails_fired"] = (s.get("guardrails") or {}).get("fired")
        tr = (s.get("guardrails") or {}).get("trust_region") or {}
        if tr.get("enabled"):
            row["trust_region_moved"] = [round(tr.get("max_rotation_deg", 0), 3),
                                         round(tr.get("max_translation", 0), 4)]
if errors:
    row.update({k: errors[k] for k in ("num_frames", "mean_rotation_deg", "median_rotation_deg",
                                       "mean_centre_m", "median_centre_m", "only_in_estimate",
                                       "only_in_ground_truth")})
print(json.dumps(row))
PY
  done
}

for scene in $scenes; do
  root=$data/$scene
  [[ -d $root/gt_dense_cameras ]] || { echo "error: $root is not a Strecha scene" >&2; exit 2; }
  for arm in $arms; do
    arm_dir=$out/$scene/$arm
    run=$arm_dir/run$suffix
    mkdir -p "$arm_dir"
    if [[ $arm == colmap ]]; then
      # The prior as a COLMAP model under the scene's names (written by the tool with any format).
      if [[ ! -d $arm_dir/prior_model ]]; then
        rm -rf "$arm_dir/scratch"
        "$tool" --scene "$root" --format record3d --out "$arm_dir/scratch" --level-deg "$level" \
            --seed "$seed" --prior-model "$arm_dir/prior_model" > "$arm_dir/fixture.json"
        rm -rf "$arm_dir/scratch"
      fi
      dataset=(--set dataset.format=strecha --set dataset.root="$root"
               --set prior.source=file --set prior.format=colmap --set prior.path="$arm_dir/prior_model")
      gt=$root
    else
      if [[ ! -d $arm_dir/capture ]]; then
        "$tool" --scene "$root" --format "$arm" --out "$arm_dir/capture" --gt "$arm_dir/gt" \
            --level-deg "$level" --seed "$seed" --fps "$fps" --odometry-hz "$odometry_hz" \
            --codec "$codec" > "$arm_dir/fixture.json"
      fi
      dataset=(--set dataset.format="$arm" --set dataset.root="$arm_dir/capture")
      gt=$arm_dir/gt
    fi
    echo "== $scene $arm$suffix: $run" >&2
    status=0
    nice -n "$nice_level" "$raytime" run configs/capture.yaml --workdir "$run" "${dataset[@]}" \
        "${sets[@]}" > "$run.log" 2>&1 || status=$?
    [[ $status == 0 ]] || { echo "   exit status $status (see $run.log)" >&2; tail -n 3 "$run.log" >&2; }
    [[ -f $run/summary.json ]] || continue
    score "$run" prior "$arm" "$gt" "$scene"
    [[ -f $run/refine.h5 ]] && score "$run" refined "$arm" "$gt" "$scene"
  done
done

# The table: one row per scene and arm, Sim(3) and unaligned mean errors, time per stage.
/usr/bin/python3 - "$results" "$out/table${suffix}.md" <<'PY'
import json, sys
rows = [json.loads(line) for line in open(sys.argv[1])]
by = {}
for r in rows:
    by.setdefault((r["scene"], r["arm"]), {})[(r["poses"], r["alignment"])] = r
lines = ["| scene | arm | frames | status | prior ° (Sim(3) / none) | refined Sim(3) ° / centre m | "
         "refined none ° / centre m | guardrails | dataset / features / matches / refine s | "
         "stages s |",
         "|---|---|---|---|---|---|---|---|---|---|"]
def fmt(r, key, digits):
    return "–" if r is None or r.get(key) is None else f"{r[key]:.{digits}f}"
for (scene, arm), cells in by.items():
    prior, prior_none = cells.get(("prior", "sim3")), cells.get(("prior", "none"))
    sim3, none = cells.get(("refined", "sim3")), cells.get(("refined", "none"))
    any_row = sim3 or prior
    s = any_row["seconds"]
    times = " / ".join(f"{s.get(k, 0):.1f}" for k in ("dataset", "features", "matches", "refine"))
    frames = str(any_row.get("num_images"))
    lines.append(
        f"| {scene} | {arm} | {frames} | {any_row['status']} | "
        f"{fmt(prior, 'mean_rotation_deg', 3)} / {fmt(prior_none, 'mean_rotation_deg', 3)} | "
        f"{fmt(sim3, 'mean_rotation_deg', 3)} / {fmt(sim3, 'mean_centre_m', 4)} | "
        f"{fmt(none, 'mean_rotation_deg', 3)} / {fmt(none, 'mean_centre_m', 4)} | "
        f"{', '.join(any_row.get('guardrails_fired') or []) or 'none'} | {times} | "
        f"{any_row['total_seconds']:.0f} |")
open(sys.argv[2], "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
