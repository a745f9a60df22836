#!/usr/bin/env bash
# The table of a finished bench/prior_pairs.yaml sweep (issue 10, "Prior-guided pairs"): per run
# and arm, the pairs matched and verified, matching and front-end (features + matches) seconds as
# fractions of exhaustive's in the same run, and the refined mean rotation error after Sim(3)
# beside exhaustive's. Times come only from stages that ran in that run's process: a stage taken
# from the sweep's cache (features and exhaustive matches are shared by a scene's seeds) prints
# "-" in the time columns.
#
#   bench/prior_pairs_table.sh [WORKDIR]      (default work/prior-pairs)
set -euo pipefail
workdir=${1:-work/prior-pairs}
command -v jq > /dev/null || { echo "error: jq is not installed" >&2; exit 2; }
printf 'run\tarm\tpairs\texhaustive_pairs\tpair_fraction\tverified\tmatch_s\tmatch_fraction\tfrontend_fraction\tprior_rot_deg\trefined_rot_deg\tdelta_vs_exhaustive_deg\n'
for summary in "$workdir"/runs/*/summary.json; do
  if ! jq -e '.status | startswith("ok")' "$summary" > /dev/null; then
    echo "skipped (status $(jq -r .status "$summary")): $summary" >&2
    continue
  fi
  jq -r '
    def stage($id): .stages[] | select(.id == $id);
    def secs($s): if $s.status == "ran" then $s.seconds else null end;
    def round3: . * 1000 | round / 1000;
    def rot($set): .metrics[$set].sim3.mean_rotation_deg;
    secs(stage("features")) as $f |
    secs(stage("matches@exhaustive")) as $e |
    (stage("matches@exhaustive").summary.num_pairs) as $ep |
    (input_filename | split("/") | .[-2]) as $run |
    ["exhaustive", "k10", "k5"][] as $arm |
    stage("matches@" + $arm) as $m |
    secs($m) as $ms |
    [$run, $arm, $m.summary.num_pairs, $ep, ($m.summary.num_pairs / $ep | round3),
     $m.summary.num_verified_pairs,
     (if $ms == null then "-" else ($ms * 10 | round / 10) end),
     (if $ms == null or $e == null then "-" else ($ms / $e | round3) end),
     (if $ms == null or $e == null or $f == null then "-"
      else (($f + $ms) / ($f + $e) | round3) end),
     (rot("prior") | round3), (rot("refined@" + $arm) * 10000 | round / 10000),
     ((rot("refined@" + $arm) - rot("refined@exhaustive")) * 10000 | round / 10000)] | @tsv
  ' "$summary"
done
