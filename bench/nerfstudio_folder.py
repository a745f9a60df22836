#!/usr/bin/python3
"""Lays out a capture as `ns-process-data` lays out a nerfstudio folder, for the in-place benchmark
(docs/nerfstudio.md): images/ (and images_2/, half size), depths/ and masks/ (one PNG per frame),
sparse_pc.ply and transforms.json with the documented keys (camera_model, per-frame fl_x, fl_y,
cx, cy, w, h, k1, k2, p1, p2, file_path, transform_matrix, colmap_im_id, depth_file_path,
mask_path; applied_transform, ply_file_path) plus keys of the user's own.

The poses and intrinsics come from a transforms.json raytime exported for the capture's own pose
set (export: {poses: [capture], formats: [transforms_json]}), so both runs read the same numbers.

  bench/nerfstudio_folder.py EXPORTED_TRANSFORMS.json OUT_FOLDER
"""
import json
import os
import shutil
import sys

import numpy as np
from PIL import Image


def main(exported, out):
    source = json.load(open(exported))
    base = os.path.dirname(os.path.abspath(exported))
    for folder in ("images", "images_2", "depths", "masks"):
        os.makedirs(os.path.join(out, folder), exist_ok=True)
    frames = []
    for index, frame in enumerate(source["frames"]):
        image_path = os.path.normpath(os.path.join(base, frame["file_path"]))
        name = os.path.basename(image_path)
        stem = os.path.splitext(name)[0]
        shutil.copyfile(image_path, os.path.join(out, "images", name))
        image = Image.open(image_path)
        image.resize((image.width // 2, image.height // 2)).save(os.path.join(out, "images_2", name))
        depth = np.full((image.height // 8, image.width // 8), 1500, dtype=np.uint16)  # mm
        Image.fromarray(depth).save(os.path.join(out, "depths", stem + ".png"))
        mask = np.full((image.height, image.width), 255, dtype=np.uint8)
        Image.fromarray(mask).save(os.path.join(out, "masks", stem + ".png"))
        entry = {"file_path": "images/" + name, "transform_matrix": frame["transform_matrix"]}
        for key in ("fl_x", "fl_y", "cx", "cy", "w", "h", "k1", "k2", "p1", "p2"):
            entry[key] = frame[key]
        entry["colmap_im_id"] = index + 1
        entry["depth_file_path"] = "depths/" + stem + ".png"
        entry["mask_path"] = "masks/" + stem + ".png"
        entry["my_frame_tag"] = "walk-around %d" % index
        frames.append(entry)
    with open(os.path.join(out, "sparse_pc.ply"), "w") as ply:
        ply.write("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                  "property float z\nproperty uchar red\nproperty uchar green\n"
                  "property uchar blue\nend_header\n0 0 0 128 128 128\n")
    document = {
        "camera_model": "OPENCV",
        "orientation_override": "none",
        "frames": frames,
        "applied_transform": [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
        "ply_file_path": "sparse_pc.ply",
        "my_capture_note": "garden chair, one loop, phone held upright",
    }
    with open(os.path.join(out, "transforms.json"), "w") as f:
        json.dump(document, f, indent=4)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
