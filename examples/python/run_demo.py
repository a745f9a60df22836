#!/usr/bin/python3
"""Runs configs/demo.yaml through raytime.run and prints what the refine did.

  PYTHONPATH=build/python /usr/bin/python3 examples/python/run_demo.py work/demo-py

Run it from the repository root (the pipeline's dataset path is relative to it). Ctrl-C stops
the run as it stops `raytime run`; rerun it and the finished stages are skipped.
"""
import sys

import raytime


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    workdir = sys.argv[1]
    try:
        summary = raytime.run("configs/demo.yaml", workdir)
    except raytime.InputError as error:
        sys.exit(f"bad input: {error}")
    print(f"status: {summary['status']} in {summary['seconds']:.1f} s")
    for pose_set in ("prior", "refined"):
        errors = summary["metrics"][pose_set]["sim3"]
        print(f"{pose_set:8s} mean rotation error {errors['mean_rotation_deg']:.3f} deg, "
              f"mean centre error {errors['mean_centre_m']:.4f} m (after Sim(3))")
    refined = raytime.read_poses(f"{workdir}/refined", "colmap")
    print(f"{len(refined)} refined poses in {workdir}/refined (camera-to-world 4x4 by name)")


if __name__ == "__main__":
    main()
