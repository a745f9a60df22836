#!/usr/bin/python3
"""False alarms and catches of raytime's checks over a sweep (issue 30 item 10).

Usage: scripts/false_alarms.py SWEEP_DIR [RAYTIME] [--success_deg 1.0]

For every run of SWEEP_DIR/runs/* and every refined pose set in it (refine stages), scores the
pose set per frame against the dataset's ground truth with `raytime evaluate --json` (Sim(3)), and
reads the warnings its refine stage and the export raised. A run succeeds for a pose set when its
mean rotation error after Sim(3) is below --success_deg; a frame is wrong above it. Prints, per
warning code: pose sets that succeeded and were flagged (false alarms), that failed and were
flagged (caught), successes flagged although every frame is within --success_deg (the alarms that
are false whatever the mean), and, for codes that name frames, named frames that were right / wrong; then the
failed pose sets no check flagged (missed). Needs only the Python standard library.
"""
import argparse
import glob
import json
import os
import subprocess
import sys
from collections import defaultdict


def evaluate(raytime, est_file, est_set, gt_file):
    out = subprocess.run([raytime, "evaluate", "--est", est_file, "--est_format", "hdf5",
                          "--est_set", est_set, "--gt", gt_file, "--gt_format", "hdf5",
                          "--gt_set", "ground_truth", "--json"],
                         capture_output=True, text=True)
    if out.returncode != 0:
        return None
    return json.loads(out.stdout)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("sweep")
    parser.add_argument("raytime", nargs="?", default="build/cli/raytime")
    parser.add_argument("--success_deg", type=float, default=1.0)
    args = parser.parse_args()
    runs = sorted(glob.glob(os.path.join(args.sweep, "runs", "*")))
    flagged_ok = defaultdict(int)
    flagged_failed = defaultdict(int)
    named_right = defaultdict(int)
    named_wrong = defaultdict(int)
    wrong_frames_unnamed = 0
    wrong_frames = 0
    successes = failures = all_right = 0
    flagged_all_right = defaultdict(int)
    missed = []
    false_alarms = defaultdict(list)
    for run in runs:
        summary_path = os.path.join(run, "summary.json")
        if not os.path.exists(summary_path):
            continue
        summary = json.load(open(summary_path))
        for stage in summary.get("stages", []):
            if stage.get("type") != "refine" or stage.get("status") == "failed":
                continue
            stage_id = stage["id"]
            pose_set = stage["summary"].get("pose_set")
            if not pose_set:
                continue
            scores = evaluate(args.raytime, os.path.join(run, stage_id + ".h5"), pose_set,
                              os.path.join(run, "dataset.h5"))
            if scores is None:
                continue
            ok = scores["mean_rotation_deg"] < args.success_deg
            successes += ok
            failures += not ok
            frame_error = {f["name"]: f["rotation_deg"] for f in scores["frames"]}
            every_frame_right = max(frame_error.values()) <= args.success_deg
            all_right += every_frame_right
            codes = set()
            named = defaultdict(set)
            for warning in summary.get("warnings", []):
                mine = warning.get("stage") == stage_id or (
                    warning.get("details", {}).get("pose_set") == pose_set)
                if not mine:
                    continue
                codes.add(warning["code"])
                named[warning["code"]].update(warning.get("images", []))
            for code in codes:
                if every_frame_right:
                    flagged_all_right[code] += 1
                if ok:
                    flagged_ok[code] += 1
                    false_alarms[code].append(os.path.basename(run) + " " + pose_set)
                else:
                    flagged_failed[code] += 1
            all_named = set().union(*named.values()) if named else set()
            for code, images in named.items():
                for image in images:
                    if image not in frame_error:
                        continue
                    if frame_error[image] > args.success_deg:
                        named_wrong[code] += 1
                    else:
                        named_right[code] += 1
            for image, error in frame_error.items():
                if error > args.success_deg:
                    wrong_frames += 1
                    wrong_frames_unnamed += image not in all_named
            if not ok and not codes:
                missed.append("%s %s (%.2f°)" % (os.path.basename(run), pose_set,
                                                  scores["mean_rotation_deg"]))
    print("pose sets: %d succeeded, %d failed (Sim(3) mean rotation < %g°)" %
          (successes, failures, args.success_deg))
    print()
    print("| check (warning code) | successes flagged | of them every frame right | failures caught | frames named right (<= %g°) | frames named wrong (> %g°) |" % (args.success_deg, args.success_deg))
    print("|---|---|---|---|---|---|")
    for code in sorted(set(flagged_ok) | set(flagged_failed)):
        print("| `%s` | %d of %d | %d of %d | %d of %d | %d | %d |" % (
            code, flagged_ok[code], successes, flagged_all_right[code], all_right,
            flagged_failed[code], failures, named_right[code], named_wrong[code]))
    print()
    print("wrong frames (> %g°): %d, named by no warning: %d" % (args.success_deg, wrong_frames,
                                                               wrong_frames_unnamed))
    print("failed pose sets no check flagged: %d%s" % (len(missed), "".join("\n  " + m for m in missed)))
    for code, runs_flagged in sorted(false_alarms.items()):
        print("false alarms of %s: %s" % (code, ", ".join(runs_flagged)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
