#!/usr/bin/python3
"""Writes a Record3D folder holding every STRIDE-th frame of another (issue 10: prior-guided pairs
against exhaustive on a subsample of the 457-frame desk capture, a benchmark input, not a test).

    bench/record3d_subsample.py SOURCE DEST STRIDE [COUNT]

DEST/rgb/<k>.jpg links to SOURCE/rgb/<k*STRIDE>.jpg (Record3D numbers frames 0..N-1 and indexes
`poses`, `perFrameIntrinsicCoeffs` and `frameTimestamps` by that number, so the subsample is
renumbered and those lists are cut to match); DEST/names.csv maps the new names to the old ones.
The source is read in place and never copied."""
import json
import os
import sys


def main():
    if len(sys.argv) not in (4, 5):
        sys.exit(__doc__)
    source, dest, stride = os.path.abspath(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    meta = json.load(open(os.path.join(source, "metadata.json")))
    frames = list(range(0, len(meta["poses"]), stride))
    if len(sys.argv) == 5:
        frames = frames[: int(sys.argv[4])]
    os.makedirs(os.path.join(dest, "rgb"), exist_ok=True)
    with open(os.path.join(dest, "names.csv"), "w") as names:
        names.write("name,source_name\n")
        for k, i in enumerate(frames):
            link = os.path.join(dest, "rgb", f"{k}.jpg")
            if os.path.lexists(link):
                os.remove(link)
            os.symlink(os.path.join(source, "rgb", f"{i}.jpg"), link)
            names.write(f"{k}.jpg,{i}.jpg\n")
    for key in ("poses", "perFrameIntrinsicCoeffs", "frameTimestamps"):
        if key in meta:
            meta[key] = [meta[key][i] for i in frames]
    tmp = os.path.join(dest, "metadata.json.tmp")
    with open(tmp, "w") as out:
        json.dump(meta, out)
    os.replace(tmp, os.path.join(dest, "metadata.json"))
    print(f"{len(frames)} frames (every {stride}th) -> {dest}")


if __name__ == "__main__":
    main()
