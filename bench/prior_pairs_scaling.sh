#!/usr/bin/env bash
# Matching cost against the number of frames of a long sequence, prior-guided pairs vs exhaustive
# (issue 10, "Prior-guided pairs"; a benchmark, not a test). The sequence is the Record3D desk
# capture (457 frames of a 60 fps video, ARKit poses, per-frame intrinsics; testing use only, read
# in place and never copied): frames are linked under zero-padded names (so name order is frame
# order) and listed in a nerfstudio transforms.json; bench/prior_pairs_scaling.yaml extracts the
# features and makes the prior from the ARKit poses; bench/pair_scaling then matches the first N
# frames both ways in one process.
#
#   bench/prior_pairs_scaling.sh [FRAMES]     (default 25,50,100,200,300,457)
#
# Environment: RAYTIME_BUILD (default build; needs cli/raytime and bench/pair_scaling), OUT
# (default work/prior-pairs-scaling), DESK (default ../shared/data/captures/record3d-desk),
# MAX_EXHAUSTIVE_PAIRS (default 5000: exhaustive up to N = 100), NICE (default 5).
set -euo pipefail
cd "$(dirname "$0")/.."

frames=${1:-25,50,100,200,300,457}
build=${RAYTIME_BUILD:-build}
out=${OUT:-work/prior-pairs-scaling}
desk=${DESK:-../shared/data/captures/record3d-desk}
nice_level=${NICE:-5}
for tool in "$build/cli/raytime" "$build/bench/pair_scaling"; do
  [[ -x $tool ]] || { echo "error: $tool not found (ninja -C $build raytime pair_scaling)" >&2; exit 2; }
done

mkdir -p "$out/desk-data/images"
/usr/bin/python3 - "$desk" "$out/desk-data" <<'PY'
import json, os, sys
desk, out = os.path.abspath(sys.argv[1]), sys.argv[2]
meta = json.load(open(os.path.join(desk, "metadata.json")))

def matrix(q):  # [qx, qy, qz, qw, tx, ty, tz] camera-to-world (ARKit = OpenGL camera axes)
    x, y, z, w, tx, ty, tz = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), tx],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), ty],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), tz],
            [0, 0, 0, 1]]

frames = []
for i, pose in enumerate(meta["poses"]):
    name = "images/%05d.jpg" % i
    link = os.path.join(out, name)
    if not os.path.lexists(link):
        os.symlink(os.path.join(desk, "rgb", "%d.jpg" % i), link)
    fx, fy, cx, cy = meta["perFrameIntrinsicCoeffs"][i]
    # transforms.json's cx, cy are in COLMAP's pixel convention (+0.5 from OpenCV's).
    frames.append({"file_path": name, "transform_matrix": matrix(pose),
                   "fl_x": fx, "fl_y": fy, "cx": cx + 0.5, "cy": cy + 0.5})
json.dump({"w": meta["w"], "h": meta["h"], "frames": frames},
          open(os.path.join(out, "transforms.json"), "w"), indent=1)
PY

nice -n "$nice_level" "$build/cli/raytime" run bench/prior_pairs_scaling.yaml \
    --workdir "$out/run" --set dataset.root="$out/desk-data" > "$out/run.log" 2>&1 ||
    { tail -n 20 "$out/run.log"; exit 1; }
nice -n "$nice_level" "$build/bench/pair_scaling" --images "$out/run/dataset.h5" \
    --features "$out/run/features.h5" --poses "$out/run/prior.h5" --frames "$frames" \
    --max-exhaustive-pairs "${MAX_EXHAUSTIVE_PAIRS:-5000}" --json "$out/scaling.json" |
    tee "$out/scaling.txt"
