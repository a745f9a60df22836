#!/usr/bin/env bash
# A capture that grows (issue 34): runs configs/capture.yaml on part of a shared phone capture, adds
# frames and runs again in the same work directory, then runs the grown capture fresh, and prints
# the wall times, their ratio and how far the two runs' refined poses are apart.
#
#   bench/growing_capture.sh chair|desk OUT_DIR [raytime options, e.g. --set refine.warm_start=true]
#
# chair: the 3D Scanner App chair, its first 18 images, then all 24.
# desk: the Record3D desk, every 3rd frame (153), then also every frame of 150..209 (193).
# The capture is reassembled in OUT_DIR/scene from symbolic links; nothing is written elsewhere.
set -euo pipefail
cd "$(dirname "$0")/.."
which="${1:?chair or desk}"
out="$(realpath -m "${2:?output directory}")"
shift 2
raytime="${RAYTIME:-build/cli/raytime}"
captures="$(realpath ../shared/data/captures)"
rm -rf "$out"
mkdir -p "$out/scene"
case "$which" in
  chair)
    source="$captures/3dscanner-chair"
    format=scanner3d
    for f in "$source"/*.json; do ln -s "$f" "$out/scene/"; done
    mapfile -t images < <(ls "$source"/*.jpg)
    for f in "${images[@]:0:18}"; do ln -s "$f" "$out/scene/"; done
    grow() { for f in "${images[@]:18}"; do ln -s "$f" "$out/scene/"; done; }
    ;;
  desk)
    source="$captures/record3d-desk"
    format=record3d
    mkdir "$out/scene/rgb"
    ln -s "$source/metadata.json" "$out/scene/"
    for i in $(seq 0 3 456); do ln -s "$source/rgb/$i.jpg" "$out/scene/rgb/"; done
    grow() {
      for i in $(seq 150 209); do
        [ -e "$out/scene/rgb/$i.jpg" ] || ln -s "$source/rgb/$i.jpg" "$out/scene/rgb/"
      done
    }
    ;;
  *) echo "growing_capture.sh: unknown capture '$which' (chair or desk)" >&2; exit 2 ;;
esac

run() {  # run NAME WORKDIR [options]: one pipeline run, its wall time in seconds on stdout
  local name="$1" workdir="$2" start end
  shift 2
  start=$(date +%s.%N)
  "$raytime" run configs/capture.yaml --workdir "$workdir" --set "dataset.format=$format" \
    --set "dataset.root=$out/scene" "$@" > "$out/$name.log" 2>&1 ||
    { echo "growing_capture.sh: run $name failed, see $out/$name.log" >&2; exit 1; }
  end=$(date +%s.%N)
  awk -v a="$start" -v b="$end" 'BEGIN { printf "%.2f", b - a }'
}

first=$(run first "$out/grown" "$@")
grow
second=$(run second "$out/grown" "$@")
fresh=$(run fresh "$out/fresh" "$@")
echo "first run ${first} s, second run (grown, same work directory) ${second} s, fresh run ${fresh} s"
awk -v a="$second" -v b="$fresh" 'BEGIN { printf "ratio second / fresh: %.2f\n", a / b }'
/usr/bin/python3 - "$out/grown/refined/images.txt" "$out/fresh/refined/images.txt" <<'EOF'
import sys
import numpy as np

def load(path):
    poses = {}
    lines = [l for l in open(path) if not l.startswith('#')]
    for k in range(0, len(lines), 2):
        t = lines[k].split()
        if len(t) >= 10:
            poses[t[9]] = np.array(list(map(float, t[1:5])))
    return poses

a, b = load(sys.argv[1]), load(sys.argv[2])
common = sorted(set(a) & set(b))
# Angle between unit quaternions (w, x, y, z): 2 acos |<qa, qb>|.
angles = [np.degrees(2 * np.arccos(min(1.0, abs(float(a[n] @ b[n]))))) for n in common]
print(f"refined poses, grown vs fresh: {len(common)} images, rotation max {max(angles):.5f}°, "
      f"median {np.median(angles):.5f}°")
EOF
