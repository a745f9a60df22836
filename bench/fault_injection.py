#!/usr/bin/python3
"""Fault-injection benchmark of raytime's per-frame verdicts (issue 46).

    bench/fault_injection.py OUT [--raytime build/cli/raytime] [--seed 0] [--faults N]
                             [--clean N] [--scenes a,b,...] [--types a,b,...]

Prepares every scene once under OUT/scenes (a COLMAP dataset of its images, each frame's camera
and its reference poses, and its fault-free prior), then runs bench/fault_injection.yaml on:
- fault-free runs (--clean per scene; the Strecha scenes' priors differ by seed, the captures'
  subsets by offset), and
- runs with one injected fault each (--faults in all, spread over the scenes and fault types in
  turn), frames and magnitudes drawn from the seed:
  focal        one frame's focal length x[1.15, 2]
  principal    one frame's principal point moved by 5-20 % of the width
  foreign      an image of another scene (same size) under one frame's name
  swap         two frames' images swapped (their names, priors and cameras stay)
  rotate       one frame's prior rotated 10-90 degrees about a random axis
  move         one frame's prior centre moved by 0.2-2x the scene size
  units        the whole prior's translations x10^u, |u| in [1, 3]
  no_baseline  every prior centre at one point (rotations kept)
  inverted     the prior written camera-to-world where world-to-camera is expected
  flipped      the prior in OpenGL camera axes
  collinear    (only with --types) every prior centre projected onto their main line

Scenes: the four shared Strecha scenes (prior: ground truth perturbed by 2 degrees per frame),
the shipped sample (4 degrees, the demo's), and the two real captures from the phone's own
poses: the chair (24 frames) and the desk's every 3rd frame as its two halves (every 6th frame,
from the first and the fourth; at most 300 matches per pair); and two synthetic corridor walks
(testing/synthetic_capture) with a weak link and a good prior, run as the stages alone on their
HDF5 files (their image faults made by the tool). A capture's reference is the capture job's
solve on every 3rd frame (no ground truth exists); the Strecha and synthetic scenes' is their
ground truth.

A frame is wrong when, after a Sim(3) fit on the frames no fault touched, it is more than 1 degree
or 1 % of the scene size (median camera-to-scene distance) from its reference. Each fault ends as:
  refused      the run stopped with an error (a prior the refine stage refused)
  caught       its frame(s) named by a warning and not exported as held (left out, or held_by_prior)
  named_held   named, but exported as held
  silent_wrong not named, exported, wrong (the must-show's 0)
  absorbed     not named, exported, right (the solve undid the fault)
For a whole-prior fault every frame counts, and a run-level warning the fault-free run did not
raise names it. Fault-free runs report the correct frames not exported and the runs with a
warning that names frames. Prints the tables; writes OUT/results.json (one record per run).
Needs /usr/bin/python3 with numpy and PIL (Debian's python3-numpy, python3-pil).
"""
import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np
from PIL import Image

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(os.path.dirname(REPO), "shared", "data")
STRECHA = ["fountain-P11", "entry-P10", "Herz-Jesus-P8", "castle-P19"]
FAULTS = ["focal", "principal", "foreign", "swap", "rotate", "move", "units", "no_baseline",
          "inverted", "flipped"]
WHOLE_PRIOR = {"units", "no_baseline", "inverted", "flipped", "collinear"}
# Run only when asked (--types): not in the cycle whose draws the before/after tables share.
EXTRA_FAULTS = ["collinear"]
OUTCOMES = ["refused", "caught", "named_held", "silent_wrong", "absorbed"]
STRECHA_FEATURES = ["--set", "features.max_features=8192", "--set", "features.first_octave=-1",
                    "--set", "matches.pairs=exhaustive"]


# ---- geometry -------------------------------------------------------------------------------

def quat_to_matrix(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(r):
    u, _, vt = np.linalg.svd(r)
    r = u @ vt
    w = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return np.array([w, x, y, z])


def axis_angle(axis, angle):
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def rotation_angle_deg(r):
    # atan2 form: exact near 0 and 180 degrees.
    c = (np.trace(r) - 1) / 2
    s = np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2
    return math.degrees(math.atan2(s, c))


def scene_distance(poses):
    """Median distance from the centres to the least-squares point nearest all optical axes."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for rotation, centre in poses.values():
        axis = rotation[:, 2]
        p = np.eye(3) - np.outer(axis, axis)
        a += p
        b += p @ centre
    point = np.linalg.lstsq(a, b, rcond=None)[0]
    return float(np.median([np.linalg.norm(c - point) for _, c in poses.values()]))


def fit_similarity(est, ref, names):
    """(s, R, t) mapping est's world onto ref's: R the chordal mean of R_ref R_est^T (well posed
    for a camera path on a line), s and t by least squares on the centres."""
    m = sum(ref[n][0] @ est[n][0].T for n in names)
    u, _, vt = np.linalg.svd(m)
    r = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    ce = np.array([est[n][1] for n in names])
    cr = np.array([ref[n][1] for n in names])
    de, dr = ce - ce.mean(0), cr - cr.mean(0)
    rotated = de @ r.T
    denom = float((rotated * rotated).sum())
    s = float((rotated * dr).sum()) / denom if denom > 0 else 1.0
    t = cr.mean(0) - s * r @ ce.mean(0)
    return s, r, t


def frame_errors(est, ref, trusted, size):
    """Per frame of est in ref: (rotation deg, centre / scene size) after a similarity fitted on
    `trusted` frames, refitted once without those more than 5x the median off; and the fit's
    scale (reference length per estimate length)."""
    names = [n for n in trusted if n in est and n in ref]
    if len(names) < 3:
        names = [n for n in est if n in ref]
    if len(names) < 2:
        return {}, 1.0

    def errors(fit):
        s, r, t = fit
        out = {}
        for n in est:
            if n not in ref:
                continue
            rot = rotation_angle_deg(ref[n][0].T @ r @ est[n][0])
            centre = np.linalg.norm(s * r @ est[n][1] + t - ref[n][1]) / size
            out[n] = (rot, float(centre))
        return out

    first_fit = fit_similarity(est, ref, names)
    first = errors(first_fit)
    med_r = np.median([first[n][0] for n in names]) + 1e-6
    med_c = np.median([first[n][1] for n in names]) + 1e-9
    kept = [n for n in names if first[n][0] <= 5 * med_r and first[n][1] <= 5 * med_c]
    if len(kept) >= 3 and len(kept) < len(names):
        fit = fit_similarity(est, ref, kept)
        return errors(fit), fit[0]
    return first, first_fit[0]


# ---- COLMAP text models ---------------------------------------------------------------------

def read_model(folder):
    """cameras {id: [model, w, h, params]}, images {name: (camera id, R world_from_cam, centre)}."""
    cameras, images = {}, {}
    for line in open(os.path.join(folder, "cameras.txt")):
        if line.startswith("#") or not line.strip():
            continue
        f = line.split()
        cameras[int(f[0])] = [f[1], int(f[2]), int(f[3]), [float(v) for v in f[4:]]]
    lines = [l for l in open(os.path.join(folder, "images.txt")) if not l.startswith("#")]
    for k in range(0, len(lines), 2):
        f = lines[k].split()
        if len(f) < 10:
            continue
        r_cw = quat_to_matrix(np.array([float(v) for v in f[1:5]]))
        t = np.array([float(v) for v in f[5:8]])
        images[f[9]] = (int(f[8]), r_cw.T, -r_cw.T @ t)
    return cameras, images


def write_model(folder, cameras, images, convention="native"):
    """images {name: (camera id, R world_from_cam, centre)}; convention 'inverted' writes each
    camera-to-world pose where COLMAP expects world-to-camera, 'flipped' OpenGL camera axes."""
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, "cameras.txt"), "w") as out:
        for cid, (model, w, h, params) in sorted(cameras.items()):
            out.write(f"{cid} {model} {w} {h} " + " ".join(repr(p) for p in params) + "\n")
    with open(os.path.join(folder, "images.txt"), "w") as out:
        for k, (name, (cid, r_wc, c)) in enumerate(sorted(images.items())):
            if convention == "flipped":
                r_wc = r_wc @ np.diag([1.0, -1.0, -1.0])
            if convention == "inverted":
                q, t = matrix_to_quat(r_wc), c
            else:
                q, t = matrix_to_quat(r_wc.T), -r_wc.T @ c
            out.write(f"{k + 1} " + " ".join(repr(float(v)) for v in list(q) + list(t)) +
                      f" {cid} {name}\n\n")
    open(os.path.join(folder, "points3D.txt"), "w").close()


def read_tum(path):
    poses = {}
    for line in open(path):
        f = line.split()
        if not f or f[0].startswith("#"):
            continue
        t = np.array([float(v) for v in f[1:4]])
        qx, qy, qz, qw = (float(v) for v in f[4:8])
        poses[f[0]] = (quat_to_matrix(np.array([qw, qx, qy, qz])), t)
    return poses


# ---- scenes ---------------------------------------------------------------------------------

def run(cmd, log):
    with open(log, "w") as out:
        return subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, cwd=REPO).returncode


def natural_key(name):
    digits = "".join(ch for ch in name if ch.isdigit())
    return (int(digits) if digits else 0, name)


def prepare_strecha(args, root, level, seed, out):
    """Ground truth and a prior perturbed i.i.d. by `level` degrees, as COLMAP models."""
    if not os.path.exists(os.path.join(out, "prior", "images.txt")):
        spec = os.path.join(out, "prepare.yaml")
        os.makedirs(out, exist_ok=True)
        with open(spec, "w") as f:
            f.write("name: prepare\ndataset: {format: strecha, root: \"\"}\nworkdir: w\nstages:\n"
                    f"  - prior: {{source: perturb, mode: iid, level_deg: {level}, seed: {seed},"
                    " translation_per_deg: 0.0125}\n"
                    "  - export: {poses: [ground_truth, prior], formats: [colmap_text]}\n")
        if run([args.raytime, "run", spec, "--workdir", out, "--set", f"dataset.root={root}"],
               os.path.join(out, "prepare.log")):
            sys.exit(f"preparing {root} failed: {out}/prepare.log")
    cameras, reference = read_model(os.path.join(out, "ground_truth"))
    _, prior = read_model(os.path.join(out, "prior"))
    images = {n: os.path.join(root, "images", n) for n in reference}
    return cameras, reference, prior, images


def prepare_capture(args, fmt, root, out):
    """The capture job on all frames from the phone's poses: its refined poses (nothing left out)
    are the reference, the phone's poses the prior."""
    if not os.path.exists(os.path.join(out, "prior", "images.txt")):
        os.makedirs(out, exist_ok=True)
        cmd = [args.raytime, "run", os.path.join(REPO, "configs", "capture.yaml"), "--workdir",
               out, "--set", f"dataset.format={fmt}", "--set", f"dataset.root={root}",
               "--set", "export.poses=[refined, prior]", "--set",
               "export.leave_out_doubted_images=false", "--cache_dir", args.cache]
        if run(cmd, os.path.join(out, "prepare.log")):
            sys.exit(f"preparing {root} failed: {out}/prepare.log")
    cameras, reference = read_model(os.path.join(out, "refined"))
    _, prior = read_model(os.path.join(out, "prior"))
    return cameras, reference, prior


# Synthetic corridor walks (testing/synthetic_capture.cc) with a weak link, a doorway the frames
# past which hang on the rest by one pair of 40 matches, and a good prior (0.3° per frame, a
# phone's): the case the checks built on the graph alone threw a third of a real walk away for.
SYNTHETIC = {
    "corridor-a": ["--cameras", "60", "--keypoints", "600", "--window", "5", "--level", "0.3",
                   "--weak_link", "40", "--seed", "1"],
    "corridor-b": ["--cameras", "50", "--keypoints", "500", "--window", "4", "--level", "0.5",
                   "--weak_link", "18", "--seed", "2"],
}


def synthetic_tool(args):
    return os.path.join(os.path.dirname(os.path.dirname(args.raytime)), "testing",
                        "synthetic_capture")


def prepare_synthetic(args, tool_args, out):
    """The tool's scene (HDF5) and its ground truth and prior as COLMAP models."""
    if not os.path.exists(os.path.join(out, "prior", "images.txt")):
        os.makedirs(out, exist_ok=True)
        if run([synthetic_tool(args)] + tool_args + ["--out", out], os.path.join(out, "tool.log")):
            sys.exit(f"synthetic scene failed: {out}/tool.log")
        if run([args.raytime, "export", "--in", os.path.join(out, "dataset.h5"),
                os.path.join(out, "prior.h5"), "--poses", "ground_truth", "prior", "--formats",
                "colmap_text", "--out", os.path.join(out, "export.h5")],
               os.path.join(out, "export.log")):
            sys.exit(f"synthetic scene export failed: {out}/export.log")
    cameras, reference = read_model(os.path.join(out, "ground_truth"))
    _, prior = read_model(os.path.join(out, "prior"))
    return cameras, reference, prior


class Scene:
    """Frames renamed NNNN.jpg in capture order: name -> image file, camera, reference, prior."""

    def __init__(self, name, kind, cameras, reference, prior, files, order, extra, rename=True):
        self.name, self.kind, self.extra = name, kind, extra
        # Scenes made of the same images (the sample is fountain-P11 at half size; the desk's
        # subsets) are one group: a foreign image comes from another group.
        self.group = ("fountain" if name in ("sample", "fountain-P11")
                      else "desk" if name.startswith("desk") else name)
        self.names = [f"{k:04d}.jpg" for k in range(len(order))] if rename else list(order)
        self.files, self.cameras, self.reference, self.prior = {}, {}, {}, {}
        for new, old in zip(self.names, order):
            cid, r, c = reference[old]
            self.cameras[new] = list(cameras[cid][:3]) + [list(cameras[cid][3])]
            self.reference[new] = (r, c)
            self.prior[new] = (prior[old][1], prior[old][2])
            self.files[new] = files[old] if files else None
        self.size = scene_distance(self.reference)
        first = self.cameras[self.names[0]]
        self.width, self.height = first[1], first[2]


def load_scenes(args):
    scenes = []
    wanted = set(args.scenes.split(",")) if args.scenes else None
    prep = os.path.join(args.out, "scenes")
    for scene in STRECHA + ["sample"]:
        if wanted and scene not in wanted:
            continue
        root = (os.path.join(REPO, "data", "sample", "fountain-P11") if scene == "sample"
                else os.path.join(SHARED, "strecha", scene))
        level = 4 if scene == "sample" else 2
        for seed in range(max(1, args.clean)):
            cameras, ref, prior, files = prepare_strecha(
                args, root, level, seed, os.path.join(prep, f"{scene}-seed{seed}"))
            order = sorted(ref)
            scenes.append(Scene(scene, "strecha", cameras, ref, prior, files, order,
                                {"seed": seed}))
    if not wanted or wanted & {"chair"}:
        root = os.path.join(SHARED, "captures", "3dscanner-chair")
        cameras, ref, prior = prepare_capture(args, "scanner3d", root, os.path.join(prep, "chair"))
        files = {n: os.path.join(root, n) for n in ref}
        scenes.append(Scene("chair", "capture", cameras, ref, prior, files,
                            sorted(ref, key=natural_key), {}))
    desk = {"desk-even", "desk-odd"}
    if not wanted or wanted & desk:
        sub = os.path.join(prep, "desk3-frames")
        if not os.path.exists(os.path.join(sub, "metadata.json")):
            subprocess.run([sys.executable, os.path.join(REPO, "bench", "record3d_subsample.py"),
                            os.path.join(SHARED, "captures", "record3d-desk"), sub, "3"],
                           check=True, stdout=subprocess.DEVNULL)
        cameras, ref, prior = prepare_capture(args, "record3d", sub, os.path.join(prep, "desk3"))
        files = {n: os.path.realpath(os.path.join(sub, "rgb", n)) for n in ref}
        order = sorted(ref, key=natural_key)
        subsets = {"desk-even": order[0::2], "desk-odd": order[1::2]}
        for scene, frames in subsets.items():
            if not wanted or scene in wanted:
                scenes.append(Scene(scene, "capture", cameras, ref, prior, files, frames, {}))
    for scene, tool_args in SYNTHETIC.items():
        if wanted and scene not in wanted:
            continue
        folder = os.path.join(prep, scene)
        cameras, ref, prior = prepare_synthetic(args, tool_args, folder)
        scenes.append(Scene(scene, "synthetic", cameras, ref, prior, None,
                            sorted(ref), {"tool_args": tool_args, "folder": folder},
                            rename=False))
    return scenes


# ---- faults ---------------------------------------------------------------------------------

def foreign_pool():
    """Images of every scene by group: where a foreign image comes from."""
    pool = {}
    for scene in STRECHA:
        folder = os.path.join(SHARED, "strecha", scene, "images")
        group = "fountain" if scene == "fountain-P11" else scene
        pool[group] = [os.path.join(folder, n) for n in sorted(os.listdir(folder))]
    chair = os.path.join(SHARED, "captures", "3dscanner-chair")
    pool["chair"] = [os.path.join(chair, n) for n in sorted(os.listdir(chair)) if n.endswith(".jpg")]
    desk = os.path.join(SHARED, "captures", "record3d-desk", "rgb")
    pool["desk"] = [os.path.join(desk, n) for n in sorted(os.listdir(desk), key=natural_key)[::3]]
    return pool


def foreign_image(args, scene, rng):
    """An image of another scene at this scene's image size (rotated to its orientation)."""
    pool = foreign_pool()
    groups = sorted(g for g in pool if g != scene.group)
    group = groups[rng.randint(len(groups))]
    source = pool[group][rng.randint(len(pool[group]))]
    name = os.path.basename(source)
    out = os.path.join(args.out, "foreign",
                       f"{group}-{name[:-4]}-{scene.width}x{scene.height}.jpg")
    if not os.path.exists(out):
        os.makedirs(os.path.dirname(out), exist_ok=True)
        image = Image.open(source).convert("RGB")
        if (image.width > image.height) != (scene.width > scene.height):
            image = image.transpose(Image.Transpose.ROTATE_90)
        image.resize((scene.width, scene.height), Image.Resampling.LANCZOS).save(out, quality=95)
    return out, f"{group}/{name}"


def inject(args, scene, fault, rng):
    """The run's dataset (files, cameras) and prior with `fault` applied; the faulted frames; a
    description of the draw."""
    files = dict(scene.files)
    cameras = {n: [c[0], c[1], c[2], list(c[3])] for n, c in scene.cameras.items()}
    prior = dict(scene.prior)
    convention = "native"
    expected_scale = (0.1, 10.0)  # reference length per refined length
    frame = scene.names[rng.randint(len(scene.names))]
    faulted, what = [frame], ""
    tool = []  # a synthetic scene's image faults are the tool's
    if scene.kind == "synthetic" and fault in ("focal", "principal", "foreign", "swap"):
        index = scene.names.index(frame)
        if fault == "focal":
            k = rng.uniform(1.15, 2.0)
            tool, what = ["--focal_fault", f"{index}:{k}"], f"focal x{k:.3f}"
        elif fault == "principal":
            p, angle = rng.uniform(0.05, 0.20), rng.uniform(0, 2 * math.pi)
            dx, dy = p * scene.width * math.cos(angle), p * scene.width * math.sin(angle)
            tool = ["--principal_fault", f"{index}:{dx}:{dy}"]
            what = f"principal point off by {100 * p:.1f} % of the width"
        elif fault == "foreign":
            tool, what = ["--foreign", str(index)], "another scene's view (two spurious pairs)"
        else:
            other = frame
            while other == frame:
                other = scene.names[rng.randint(len(scene.names))]
            tool = ["--swap", f"{index}:{scene.names.index(other)}"]
            faulted, what = [frame, other], f"images of {frame} and {other} swapped"
        return files, cameras, prior, convention, faulted, what, expected_scale, tool
    if fault == "focal":
        k = rng.uniform(1.15, 2.0)
        cameras[frame][3][0] *= k
        if cameras[frame][0] != "SIMPLE_PINHOLE" and cameras[frame][0] != "SIMPLE_RADIAL":
            cameras[frame][3][1] *= k
        what = f"focal x{k:.3f}"
    elif fault == "principal":
        p, angle = rng.uniform(0.05, 0.20), rng.uniform(0, 2 * math.pi)
        cx = 2 if cameras[frame][0] not in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL") else 1
        cameras[frame][3][cx] += p * scene.width * math.cos(angle)
        cameras[frame][3][cx + 1] += p * scene.width * math.sin(angle)
        what = f"principal point off by {100 * p:.1f} % of the width"
    elif fault == "foreign":
        files[frame], origin = foreign_image(args, scene, rng)
        what = f"image of {origin}"
    elif fault == "swap":
        other = frame
        while other == frame:
            other = scene.names[rng.randint(len(scene.names))]
        files[frame], files[other] = files[other], files[frame]
        faulted = [frame, other]
        what = f"images of {frame} and {other} swapped"
    elif fault == "rotate":
        angle = rng.uniform(10, 90)
        r, c = prior[frame]
        prior[frame] = (r @ axis_angle(rng.normal(size=3), math.radians(angle)), c)
        what = f"prior rotated {angle:.1f} deg"
    elif fault == "move":
        m = rng.uniform(0.2, 2.0)
        r, c = prior[frame]
        d = rng.normal(size=3)
        prior[frame] = (r, c + m * scene.size * d / np.linalg.norm(d))
        what = f"prior moved {m:.2f}x the scene size"
    elif fault == "units":
        u = rng.uniform(1, 3) * (1 if rng.rand() < 0.5 else -1)
        prior = {n: (r, c * 10 ** u) for n, (r, c) in prior.items()}
        expected_scale = (0.1 * 10 ** -u, 10 * 10 ** -u)
        faulted, what = list(scene.names), f"prior translations x10^{u:.2f}"
    elif fault == "no_baseline":
        prior = {n: (r, np.zeros(3)) for n, (r, c) in prior.items()}
        faulted, what = list(scene.names), "every prior centre at the origin"
        expected_scale = (1e-3, 1e3)  # the prior has no scale; any sane one
    elif fault == "collinear":
        # Every centre projected onto the centres' main line (an odometry that knows only the
        # distance travelled).
        centres = np.array([c for _, c in prior.values()])
        mean = centres.mean(0)
        direction = np.linalg.svd(centres - mean)[2][0]
        prior = {n: (r, mean + direction * direction.dot(c - mean)) for n, (r, c) in prior.items()}
        faulted, what = list(scene.names), "every prior centre on one line"
    elif fault in ("inverted", "flipped"):
        convention = fault
        faulted, what = list(scene.names), f"prior {fault}"
    return files, cameras, prior, convention, faulted, what, expected_scale, tool


def write_run(folder, scene, files, cameras, prior, convention):
    if os.path.exists(folder):
        shutil.rmtree(folder)
    data = os.path.join(folder, "dataset")
    os.makedirs(os.path.join(data, "images"))
    for n in scene.names:
        os.symlink(os.path.abspath(files[n]), os.path.join(data, "images", n))
    # One camera per distinct set of intrinsics, as the scene's own files have them.
    ids, model_cameras = {}, {}
    for n in scene.names:
        key = repr(cameras[n])
        if key not in model_cameras:
            model_cameras[key] = (len(model_cameras) + 1, cameras[n])
        ids[n] = model_cameras[key][0]
    model_cameras = dict(model_cameras.values())
    write_model(os.path.join(data, "sparse", "0"), model_cameras,
                {n: (ids[n],) + scene.reference[n] for n in scene.names})
    write_model(os.path.join(folder, "prior"), model_cameras,
                {n: (ids[n],) + prior[n] for n in scene.names}, convention)


# ---- one run and its score ------------------------------------------------------------------

def run_synthetic(args, scene, folder, prior, convention, tool):
    """A synthetic scene's run as the stages alone (raytime prior/refine/export on its HDF5
    files), written like a pipeline's work directory: work/summary.json with the refine and
    export stages' summaries, work/refined (COLMAP), work/refined_tum.txt (every refined pose)."""
    if os.path.exists(folder):
        shutil.rmtree(folder)
    work = os.path.join(folder, "work")
    os.makedirs(os.path.join(work, "all"))
    start = time.time()
    data = scene.extra["folder"]
    if tool:
        data = os.path.join(folder, "data")
        if run([synthetic_tool(args)] + scene.extra["tool_args"] + tool + ["--out", data],
               os.path.join(folder, "tool.log")):
            sys.exit(f"synthetic fault failed: {folder}/tool.log")
    dataset = os.path.join(data, "dataset.h5")
    prior_file = os.path.join(data, "prior.h5")
    if prior is not scene.prior or convention != "native":
        write_model(os.path.join(folder, "prior"), {1: ["PINHOLE", 1, 1, [1, 1, 0, 0]]},
                    {n: (1,) + prior[n] for n in scene.names}, convention)
        prior_file = os.path.join(folder, "prior.h5")
        if run([args.raytime, "prior", "--in", dataset, "--source", "file", "--format", "colmap",
                "--path", os.path.join(folder, "prior"), "--out", prior_file],
               os.path.join(folder, "prior.log")):
            return 2, time.time() - start
    stages = []
    for stage, cmd in (
            ("refine", [args.raytime, "refine", "--in", dataset, os.path.join(data, "features.h5"),
                        os.path.join(data, "matches.h5"), prior_file, "--preset", "auto", "--out",
                        os.path.join(work, "refine.h5")]),
            ("export", [args.raytime, "export", "--in", dataset, os.path.join(work, "refine.h5"),
                        "--poses", "refined", "--formats", "colmap_text", "--out",
                        os.path.join(work, "export.h5")]),
            ("export@all", [args.raytime, "export", "--in", dataset,
                            os.path.join(work, "refine.h5"), "--poses", "refined", "--formats",
                            "tum", "--out", os.path.join(work, "all", "export.h5")] +
             sum((["--" + o, "false"] for o in leave_out_options(args)), []))):
        out = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
        with open(os.path.join(folder, stage + ".log"), "w") as log:
            log.write(out.stderr)
        if out.returncode != 0:
            return out.returncode, time.time() - start
        stages.append({"id": stage, "summary": json.loads(out.stdout)})
    os.replace(os.path.join(work, "all", "refined_tum.txt"), os.path.join(work, "refined_tum.txt"))
    with open(os.path.join(work, "summary.json"), "w") as f:
        json.dump({"status": "ok", "stages": stages}, f)
    return 0, time.time() - start


def leave_out_options(args):
    """The export's leave-out options this raytime has (an older one had two)."""
    if not hasattr(args, "leave_out"):
        help_text = subprocess.run([args.raytime, "export", "--help"], capture_output=True,
                                   text=True).stdout
        args.leave_out = [o for o in ("leave_out_unexplained_images", "leave_out_doubted_images")
                          if "--" + o in help_text]
    return args.leave_out


def run_scene(args, scene, folder, files, cameras, prior, convention, tool):
    if scene.kind == "synthetic":
        return run_synthetic(args, scene, folder, prior, convention, tool)
    write_run(folder, scene, files, cameras, prior, convention)
    return run_raytime(args, scene, folder)


def run_raytime(args, scene, folder):
    cmd = [args.raytime, "run", os.path.join(REPO, "bench", "fault_injection.yaml"), "--workdir",
           os.path.join(folder, "work"), "--set",
           f"dataset.root={os.path.join(folder, 'dataset')}", "--set",
           f"prior.path={os.path.join(folder, 'prior')}", "--cache_dir", args.cache]
    if scene.kind == "strecha":
        cmd += STRECHA_FEATURES
    if len(scene.names) > 50:
        # A long capture's finish on every match dominates its time (README: "for hundreds of
        # frames add refine.max_matches_per_pair=300").
        cmd += ["--set", "refine.max_matches_per_pair=300"]
    start = time.time()
    code = run(cmd, os.path.join(folder, "raytime.log"))
    return code, time.time() - start


def read_outcome(folder):
    """Exit, warnings (code -> named images), exported names, all refined poses, verdicts."""
    work = os.path.join(folder, "work")
    out = {"warnings": {}, "exported": set(), "all": {}, "verdicts": {}, "status": None}
    summary_path = os.path.join(work, "summary.json")
    if os.path.exists(summary_path):
        summary = json.load(open(summary_path))
        out["status"] = summary.get("status")
        for stage in summary.get("stages", []):
            stage_summary = stage.get("summary") or {}
            if stage.get("id") == "export@all":
                continue
            for w in stage_summary.get("warnings", []):
                out["warnings"].setdefault(w["code"], set()).update(w.get("images") or [])
            for name, v in (stage_summary.get("frame_verdicts") or {}).items():
                out["verdicts"][name] = v.get("verdict")
    model = os.path.join(work, "refined", "images.txt")
    if os.path.exists(model):
        out["exported"] = set(read_model(os.path.join(work, "refined"))[1])
    tum = os.path.join(work, "refined_tum.txt")
    if os.path.exists(tum):
        out["all"] = read_tum(tum)
    return out


def score(scene, outcome, faulted, baseline_codes, code, expected_scale=(0.1, 10.0)):
    """Per run: the fault's outcome, and the frames outside the fault dropped or wrong."""
    named = set().union(*outcome["warnings"].values()) if outcome["warnings"] else set()
    held = {n for n in outcome["exported"]
            if outcome["verdicts"].get(n, "held") == "held"}
    # Aligned on what the user is given as held (the faulted frames aside): the export's frames
    # must agree with the reference up to one similarity.
    trusted = [n for n in scene.names if n not in faulted and n in held]
    errors, scale = frame_errors(outcome["all"], scene.reference, trusted, scene.size)
    wrong = {n for n, (r, c) in errors.items() if r > 1.0 or c > 0.01}
    # Poses right up to a scale far from the prior's are no answer either (a prior without
    # baseline refined into cameras 1e-7 apart): every frame is wrong then.
    if errors and not (expected_scale[0] <= scale <= expected_scale[1]):
        wrong = set(errors)
    record = {"errors": {n: [round(r, 4), round(c, 5)] for n, (r, c) in errors.items()},
              "named": sorted(named), "exported": sorted(outcome["exported"]),
              "warnings": sorted(outcome["warnings"]), "status": outcome["status"], "exit": code,
              "scale": scale}
    if code != 0:
        record["outcome"] = "refused"
        return record
    whole = len(faulted) == len(scene.names)
    new_codes = set(outcome["warnings"]) - baseline_codes
    worst = None
    for n in faulted:
        is_named = n in named or (whole and bool(new_codes))
        if is_named and n not in held:
            result = "caught"
        elif is_named:
            result = "named_held"
        elif n in held and n in wrong:
            result = "silent_wrong"
        elif n in held:
            result = "absorbed"
        else:
            result = "caught" if is_named else "absorbed"  # not exported, nothing claimed
        order = ["silent_wrong", "named_held", "absorbed", "caught"]
        if worst is None or order.index(result) < order.index(worst):
            worst = result
    record["outcome"] = worst
    others = [n for n in scene.names if n not in faulted]
    record["others_dropped"] = sum(1 for n in others if n not in outcome["exported"])
    record["others_correct_dropped"] = sum(1 for n in others if n not in outcome["exported"] and
                                           n in errors and n not in wrong)
    record["others_wrong_held"] = sum(1 for n in others if n in held and n in wrong)
    return record


# ---- main -----------------------------------------------------------------------------------

def table(results):
    lines = ["| fault | runs | " + " | ".join(OUTCOMES) + " | other frames dropped (of them "
             "right) | other frames wrong and held | median s |",
             "|---" * (len(OUTCOMES) + 5) + "|"]
    for fault in FAULTS + EXTRA_FAULTS:
        rows = [r for r in results if r["fault"] == fault]
        if not rows:
            continue
        counts = [sum(1 for r in rows if r["outcome"] == o) for o in OUTCOMES]
        lines.append(f"| {fault} | {len(rows)} | " + " | ".join(map(str, counts)) +
                     f" | {sum(r.get('others_dropped', 0) for r in rows)}"
                     f" ({sum(r.get('others_correct_dropped', 0) for r in rows)})"
                     f" | {sum(r.get('others_wrong_held', 0) for r in rows)}"
                     f" | {np.median([r['seconds'] for r in rows]):.1f} |")
    return "\n".join(lines)


def clean_table(results):
    lines = ["| scene | runs | frames | correct frames not exported | wrong frames held | "
             "frames held_by_prior | runs naming frames (doubted) | warnings |",
             "|---|---|---|---|---|---|---|---|"]
    by_scene = {}
    for r in results:
        by_scene.setdefault(r["scene"], []).append(r)
    for scene, rows in by_scene.items():
        frames = sum(len(r["errors"]) for r in rows)
        dropped = sum(r["correct_dropped"] for r in rows)
        wrong = sum(r["wrong_held"] for r in rows)
        naming = sum(1 for r in rows if r["named"])
        doubting = sum(1 for r in rows if r["named_doubted"])
        by_prior = sum(r["held_by_prior"] for r in rows)
        codes = sorted(set(c for r in rows for c in r["warnings"]))
        lines.append(f"| {scene} | {len(rows)} | {frames} | {dropped} | {wrong} | {by_prior} | "
                     f"{naming} ({doubting}) | {', '.join(codes)} |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out")
    parser.add_argument("--raytime", default=os.path.join(REPO, "build", "cli", "raytime"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--faults", type=int, default=200, help="faulted runs in all")
    parser.add_argument("--clean", type=int, default=2,
                        help="fault-free runs per scene (Strecha: prior seeds)")
    parser.add_argument("--scenes", default="", help="comma-separated subset of the scenes")
    parser.add_argument("--types", default="", help="comma-separated subset of the faults")
    parser.add_argument("--check", action="store_true",
                        help="exit 1 on a silent wrong fault, a correct frame not exported or a "
                             "frame doubted in a fault-free run (the CI slice)")
    args = parser.parse_args()
    args.raytime = os.path.abspath(args.raytime)
    args.out = os.path.abspath(args.out)
    args.cache = os.path.join(args.out, "cache")
    os.makedirs(args.out, exist_ok=True)
    scenes = load_scenes(args)
    types = args.types.split(",") if args.types else FAULTS
    results, clean = [], []
    baseline_codes = {}
    for scene in scenes:
        tag = f"{scene.name}-seed{scene.extra['seed']}" if "seed" in scene.extra else scene.name
        folder = os.path.join(args.out, "runs", f"clean-{tag}")
        code, seconds = run_scene(args, scene, folder, scene.files, scene.cameras, scene.prior,
                                  "native", [])
        outcome = read_outcome(folder)
        record = score(scene, outcome, [], set(), code)
        errors = record["errors"]
        exported = outcome["exported"]
        held = {n for n in exported if outcome["verdicts"].get(n, "held") == "held"}
        record.update({"scene": scene.name, "tag": tag, "seconds": seconds,
                       "correct_dropped": sum(1 for n in scene.names if n not in exported and (
                           n not in errors or (errors[n][0] <= 1 and errors[n][1] <= 0.01))),
                       "wrong_held": sum(1 for n in held if n in errors and (
                           errors[n][0] > 1 or errors[n][1] > 0.01)),
                       "held_by_prior": len(exported) - len(held)})
        # Frames a warning names as doubted (left out), and any frame a warning names at all.
        record["named"] = sorted(set().union(*outcome["warnings"].values())
                                 if outcome["warnings"] else set())
        record["named_doubted"] = sorted(n for n in record["named"] if n not in exported)
        baseline_codes.setdefault(scene.name, set()).update(outcome["warnings"])
        clean.append(record)
        print(f"clean {tag}: exit {code}, {len(held)}/{len(scene.names)} held, "
              f"{record['correct_dropped']} correct dropped, warnings {record['warnings']} "
              f"({seconds:.1f} s)", flush=True)
    # The faulted runs: scenes and fault types in turn, frames and magnitudes from the seed.
    fault_scenes = [s for s in scenes if s.extra.get("seed", 0) == 0]
    for k in range(args.faults):
        scene = fault_scenes[k % len(fault_scenes)]
        fault = types[(k // len(fault_scenes)) % len(types)]
        rng = np.random.RandomState([args.seed, k])
        files, cameras, prior, convention, faulted, what, expected, tool = inject(args, scene,
                                                                                 fault, rng)
        folder = os.path.join(args.out, "runs", f"fault{k:04d}")
        code, seconds = run_scene(args, scene, folder, files, cameras, prior, convention, tool)
        outcome = read_outcome(folder)
        record = score(scene, outcome, faulted, baseline_codes.get(scene.name, set()), code,
                       expected)
        record.update({"run": k, "scene": scene.name, "fault": fault, "what": what,
                       "frames": faulted if len(faulted) < len(scene.names) else "all",
                       "seconds": seconds})
        results.append(record)
        print(f"fault {k} {scene.name} {fault} ({what}, {faulted[0] if len(faulted) < 3 else 'all'}):"
              f" {record['outcome']}, exit {code} ({seconds:.1f} s)", flush=True)
        with open(os.path.join(args.out, "results.json.tmp"), "w") as f:
            json.dump({"clean": clean, "faults": results}, f, indent=1, default=str)
        os.replace(os.path.join(args.out, "results.json.tmp"),
                   os.path.join(args.out, "results.json"))
    with open(os.path.join(args.out, "results.json.tmp"), "w") as f:
        json.dump({"clean": clean, "faults": results}, f, indent=1, default=str)
    os.replace(os.path.join(args.out, "results.json.tmp"), os.path.join(args.out, "results.json"))
    print("\nFault-free runs:\n" + clean_table(clean))
    print("\nInjected faults:\n" + table(results))
    silent = [r for r in results if r["outcome"] == "silent_wrong"]
    dropped = sum(r["correct_dropped"] for r in clean)
    doubting = sum(1 for r in clean if r["named_doubted"])
    if args.check and (silent or dropped or doubting):
        print(f"\nFAILED: {len(silent)} silent wrong, {dropped} correct frames not exported, "
              f"{doubting} fault-free runs doubting frames")
        sys.exit(1)
    print(f"\n{len(silent)} silent wrong of {len(results)} faults; "
          f"{sum(r['correct_dropped'] for r in clean)} correct frames not exported in "
          f"{len(clean)} fault-free runs, {sum(1 for r in clean if r['named'])} naming frames "
          f"({sum(1 for r in clean if r['named_doubted'])} naming frames as doubted)")


if __name__ == "__main__":
    main()
