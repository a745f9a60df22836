"""raytime from Python: pipelines run in this process, the refiner on arrays, pose files.

Poses are camera-to-world 4x4 matrices in OpenCV camera axes (x right, y down, z forward):
``[[R, c], [0, 0, 0, 1]]`` with ``R`` the camera's axes in world coordinates and ``c`` its centre
(raytime's ``world_from_cam``). COLMAP and pycolmap store the inverse (``cam_from_world``):
invert theirs (``numpy.linalg.inv``) before passing them.

Cameras are dicts ``{"model": "PINHOLE", "width": 768, "height": 512, "params": [...]}`` with
COLMAP's model names and parameter order (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL,
OPENCV). Pixel coordinates (keypoints, principal points) follow ``pixel_convention``: "opencv"
(the centre of the top-left pixel at (0, 0), raytime's) or "colmap" (at (0.5, 0.5), pycolmap's).

Errors: ``raytime.InputError`` for what a user can fix (a file, an option, unusable data), with
the message ``raytime`` prints; ``raytime.Error`` (its base) for the rest. Both carry ``cause``
(summary.json's: input, memory, threads, open_files, disk_space or error). Logs go to stderr.
"""
import json

import numpy as np

from ._raytime import Error, InputError
from . import _raytime

Error.__module__ = InputError.__module__ = __name__

__all__ = ["Error", "InputError", "run", "refine", "read_poses", "write_poses",
           "READABLE_FORMATS", "WRITABLE_FORMATS"]

READABLE_FORMATS = tuple(_raytime.readable_formats)
WRITABLE_FORMATS = tuple(_raytime.writable_formats)


def _override(key, value):
    """'STAGE.KEY=VALUE' as `raytime run --set` takes it; non-strings as YAML (JSON) values."""
    if isinstance(value, str):
        return f"{key}={value}"
    return f"{key}={json.dumps(value)}"


def run(pipeline, workdir, set=None, cache_dir=None, force=False):
    """Runs a pipeline file as ``raytime run PIPELINE --workdir WORKDIR`` does; returns the run's
    summary (WORKDIR/summary.json) as a dict.

    set: overrides, ``{"refine.preset": "auto", "prior.level_deg": 8}`` (or a list of
    "STAGE.KEY=VALUE" strings), each as ``--set``. cache_dir: ``--cache_dir``. force: ``--force``.
    The work runs without the GIL. Ctrl-C (KeyboardInterrupt) stops it as it stops the command:
    summary.json says "interrupted", temporary files are removed, and KeyboardInterrupt is raised
    once the work has stopped. A pipeline with a sweep is refused (run it with ``raytime run``).
    A stage that fails raises ``Error`` (``InputError`` for bad input) after summary.json has
    recorded the failure.
    """
    if set is None:
        overrides = []
    elif isinstance(set, dict):
        overrides = [_override(k, v) for k, v in set.items()]
    else:
        overrides = [str(s) for s in set]
    text = _raytime.run(str(pipeline), str(workdir), overrides,
                        "" if cache_dir is None else str(cache_dir), bool(force))
    return json.loads(text)


def _per_image(cameras, n):
    if isinstance(cameras, dict):
        return [cameras] * n
    cameras = list(cameras)
    if len(cameras) != n:
        raise InputError(f"cameras: {len(cameras)} given for {n} images (one, or one per image)")
    return cameras


def refine(cameras, poses, keypoints, matches, names=None, options=None, preset="auto",
           pixel_convention="opencv"):
    """The refine stage on a match graph built elsewhere (pycolmap, hloc, your own matcher).

    cameras: one camera dict shared by every image, or one per image.
    poses: (N, 4, 4) camera-to-world prior poses (see the module's docstring).
    keypoints: N arrays (K_i, 2) of pixel coordinates.
    matches: verified pairs ``(i, j, rows)``, rows an (M, 2) integer array of keypoint indices
        into keypoints[i] and keypoints[j].
    names: N image names (default image_000000, ...), the keys of the summary's per-frame parts.
    options: refine stage keys as in a pipeline file (``{"max_matches_per_pair": 300}``), applied
        over ``preset`` (configs/presets/refine/NAME.yaml) and validated as the stage does.
    Runs without the GIL; Ctrl-C stops the solve and raises KeyboardInterrupt.

    Returns a dict: "poses" (N, 4, 4) refined camera-to-world (the prior's where not refined),
    "refined" (N,) bool: a solve refined the pose (not: no verified pair, a component not solved,
    or a guardrail returned the prior, e.g. the gnc preset's trust region), "verdicts" N frame verdicts (held, held_by_prior, doubted; README "Frame
    verdicts"), "sigma_rotation_deg" and "sigma_centre" (N,) each pose's σ from the solve (NaN where
    none), "summary" the stage's summary (as summary.json's refine stage), "uncertainty" by name.
    """
    poses = np.ascontiguousarray(poses, dtype=np.float64)
    n = poses.shape[0] if poses.ndim == 3 else 0
    if names is None:
        names = [f"image_{i:06d}" for i in range(n)]
    names = [str(name) for name in names]
    keypoints = [np.ascontiguousarray(k, dtype=np.float64) for k in keypoints]
    matches = [(int(i), int(j), np.ascontiguousarray(rows, dtype=np.int64))
               for i, j, rows in matches]
    refined_poses, refined, text = _raytime.refine(
        _per_image(cameras, len(names)), poses, keypoints, matches, names,
        json.dumps(options or {}), str(preset), str(pixel_convention))
    result = json.loads(text)
    uncertainty = result["uncertainty"]
    nan = float("nan")
    refined = np.array(refined, dtype=bool)
    return {
        # The caller's own matrices where not refined (raytime's quaternions round them).
        "poses": np.where(refined[:, None, None], refined_poses, poses),
        "refined": refined,
        "verdicts": [result["frame_verdicts"].get(name) for name in names],
        "sigma_rotation_deg": np.array(
            [uncertainty.get(name, {}).get("rotation_deg", nan) for name in names]),
        "sigma_centre": np.array([uncertainty.get(name, {}).get("centre", nan) for name in names]),
        "uncertainty": uncertainty,
        "summary": result["summary"],
    }


def read_poses(path, format, pose_set=None):
    """{image name: 4x4 camera-to-world} of a pose file in one of READABLE_FORMATS (those of
    ``raytime evaluate --est-format``; "hdf5" reads ``pose_set`` of a raytime HDF5 file)."""
    names, poses = _raytime.read_poses(str(path), str(format), pose_set or "")
    return dict(zip(names, poses))


def write_poses(path, poses, format, cameras=None, pixel_convention="opencv"):
    """Writes {image name: 4x4 camera-to-world} in one of WRITABLE_FORMATS: "colmap" (a text model
    folder), "colmap_binary", "nerfstudio" (transforms.json, OpenGL axes as nerfstudio reads them),
    "tum" (a trajectory; names in the first column). COLMAP and nerfstudio write intrinsics:
    ``cameras`` is one camera dict for all, or {name: camera dict}."""
    names = list(poses)
    array = np.ascontiguousarray([poses[name] for name in names], dtype=np.float64).reshape(-1, 4, 4)
    if cameras is None:
        per_image = []
    elif isinstance(cameras, dict) and "model" in cameras:
        per_image = [cameras] * len(names)
    else:
        per_image = [cameras[name] for name in names]
    _raytime.write_poses(str(path), names, array, str(format), per_image, str(pixel_convention))
