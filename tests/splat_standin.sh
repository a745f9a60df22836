#!/bin/sh
# A stand-in for a 3DGS trainer, for the splat stage's tests (no GPU, no PyPI here): it writes what
# gsplat, the Inria code and nerfstudio write, with known numbers per pose set, so one run serves
# every trainer kind (each reads only its own files).
#
#   sh tests/splat_standin.sh TAG POSE_SET RESULT_DIR DATA_DIR FIXTURE_DIR
#
# FIXTURE_DIR holds gt.png, render.png and side.png ([gt | render]) for the held-out renders, and
# steers the run: it appends "TAG POSE_SET" to FIXTURE_DIR/calls.log; FIXTURE_DIR/fail_TAG_POSE_SET
# makes it exit 3 (a crashed trainer), FIXTURE_DIR/nometrics_TAG_POSE_SET makes it exit 0 without
# writing metrics.
#
# Numbers (PSNR / SSIM / LPIPS), chosen exact in binary:
#   pose set       gsplat val_step29999.json   Inria results.json      nerfstudio eval.json
#   prior          20.5   / 0.625  / 0.375     20.25 / 0.5    / 0.5    20.75 / 0.6875 / 0.3125
#   refined        22.25  / 0.75   / 0.25      22.0  / 0.625  / 0.375  22.5  / 0.8125 / 0.1875
#   ground_truth   23.0   / 0.8125 / 0.1875    22.75 / 0.6875 / 0.25   23.25 / 0.875  / 0.125
set -e
tag=$1
pose=$2
result=$3
data=$4
fixture=$5

echo "$tag $pose" >>"$fixture/calls.log"
echo "stand-in trainer $tag: pose set $pose, data $data, result $result"
# The hook hands over the export of this pose set.
case "$data" in
*/3dgs/"$pose") ;;
*) echo "unexpected data_dir $data" >&2; exit 4 ;;
esac
test -d "$data/images" || { echo "no images in $data" >&2; exit 4; }
if [ -e "$fixture/fail_${tag}_$pose" ]; then
  echo "RuntimeError: CUDA out of memory (stand-in failure for $pose)" >&2
  exit 3
fi
if [ -e "$fixture/nometrics_${tag}_$pose" ]; then
  echo "training finished, but no metrics were written"
  exit 0
fi

case "$pose" in
prior) g="20.5 0.625 0.375"; i="20.25 0.5 0.5"; n="20.75 0.6875 0.3125" ;;
refined) g="22.25 0.75 0.25"; i="22.0 0.625 0.375"; n="22.5 0.8125 0.1875" ;;
ground_truth) g="23.0 0.8125 0.1875"; i="22.75 0.6875 0.25"; n="23.25 0.875 0.125" ;;
*) g="10.0 0.1 0.9"; i="10.0 0.1 0.9"; n="10.0 0.1 0.9" ;;
esac

# gsplat: examples/simple_trainer.py, eval at steps 7000 and 30000 (0-based file names).
mkdir -p "$result/stats" "$result/renders"
set -- $g
printf '{"psnr": 1.0, "ssim": 0.01, "lpips": 0.99, "ellipse_time": 0.01, "num_GS": 1000}' \
  >"$result/stats/val_step6999.json"
printf '{"psnr": %s, "ssim": %s, "lpips": %s, "ellipse_time": 0.0134, "num_GS": 250000}' "$1" "$2" "$3" \
  >"$result/stats/val_step29999.json"
cp "$fixture/side.png" "$result/renders/val_step29999_0000.png"
cp "$fixture/side.png" "$result/renders/val_step29999_0001.png"

# Inria: train.py + render.py + metrics.py.
mkdir -p "$result/test/ours_30000/renders" "$result/test/ours_30000/gt"
set -- $i
printf '{\n "ours_30000": {\n  "SSIM": %s,\n  "PSNR": %s,\n  "LPIPS": %s\n }\n}' "$2" "$1" "$3" \
  >"$result/results.json"
cp "$fixture/render.png" "$result/test/ours_30000/renders/00000.png"
cp "$fixture/gt.png" "$result/test/ours_30000/gt/00000.png"

# nerfstudio: ns-train splatfacto, then ns-eval --output-path --render-output-path.
mkdir -p "$result/eval_renders"
set -- $n
printf '{\n  "experiment_name": "raytime",\n  "method_name": "splatfacto",\n  "checkpoint": "%s/raytime/splatfacto/run/nerfstudio_models/step-000029999.ckpt",\n  "results": {\n    "psnr": %s,\n    "psnr_std": 1.5,\n    "ssim": %s,\n    "ssim_std": 0.05,\n    "lpips": %s,\n    "lpips_std": 0.02,\n    "num_rays_per_sec": 1000000.0,\n    "num_rays_per_sec_std": 1000.0,\n    "fps": 30.0,\n    "fps_std": 1.0\n  }\n}\n' \
  "$result" "$1" "$2" "$3" >"$result/eval.json"
cp "$fixture/side.png" "$result/eval_renders/eval_img_0000.png"
echo "stand-in trainer $tag: done"
