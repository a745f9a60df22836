#!/usr/bin/python3
"""raytime.refine on arrays: a match graph built elsewhere (here a synthetic scene made with
numpy; with pycolmap or hloc, their cameras, inverted poses, keypoints and verified matches).

  PYTHONPATH=build/python /usr/bin/python3 examples/python/refine_arrays.py
"""
import numpy as np

import raytime

CAMERA = {"model": "PINHOLE", "width": 1536, "height": 1024,
          "params": [1400.0, 1400.0, 767.5, 511.5]}  # fx, fy, cx, cy (OpenCV pixel convention)


def look_at(centre):
    """Camera-to-world pose of a camera at `centre` looking at the origin (OpenCV axes)."""
    z = -centre / np.linalg.norm(centre)
    x = np.cross([0.0, -1.0, 0.0], z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    pose[:3, 3] = centre
    return pose


def small_rotation(rng, degrees):
    axis = rng.normal(size=3)
    axis *= np.radians(degrees) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + k + k @ k / 2  # near a rotation; made one in main (SVD)


def main():
    rng = np.random.default_rng(0)
    points = rng.uniform(-5, 5, size=(400, 3))
    truth = np.stack([look_at(16 * np.array([np.sin(a), 0.0, -np.cos(a)]))
                      for a in np.radians(np.linspace(-30, 30, 6))])
    fx, fy, cx, cy = CAMERA["params"]
    keypoints = []
    for pose in truth:
        local = (points - pose[:3, 3]) @ pose[:3, :3]
        pixels = np.stack([fx * local[:, 0] / local[:, 2] + cx,
                           fy * local[:, 1] / local[:, 2] + cy], axis=1)
        keypoints.append(pixels + rng.normal(scale=0.5, size=pixels.shape))
    # Every point is seen by every camera here, so keypoint k of each image is point k.
    rows = np.stack([np.arange(len(points))] * 2, axis=1)
    matches = [(i, j, rows) for i in range(len(truth)) for j in range(i + 1, len(truth))]

    prior = truth.copy()
    for pose in prior:
        u, _, vt = np.linalg.svd(small_rotation(rng, 3.0) @ pose[:3, :3])
        pose[:3, :3] = u @ vt
        pose[:3, 3] += rng.normal(scale=0.3, size=3)

    result = raytime.refine(CAMERA, prior, keypoints, matches, preset="auto")
    print(f"mean relative rotation error: prior {relative_error_deg(prior, truth):.3f} deg, "
          f"refined {relative_error_deg(result['poses'], truth):.4f} deg")
    for i, verdict in enumerate(result["verdicts"]):
        print(f"image {i}: {verdict['verdict']}, sigma {result['sigma_rotation_deg'][i]:.4f} deg")
    print(f"{result['summary']['total_iterations']} iterations, preset "
          f"{result['summary']['preset']}")


def relative_error_deg(poses, truth):
    """Mean over pairs of the angle between estimated and true relative rotation (free of the
    gauge the refined poses are in)."""
    errors = []
    for i in range(len(poses)):
        for j in range(i + 1, len(poses)):
            estimate = poses[i, :3, :3].T @ poses[j, :3, :3]
            true = truth[i, :3, :3].T @ truth[j, :3, :3]
            cos = (np.trace(estimate.T @ true) - 1) / 2
            errors.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return float(np.mean(errors))


if __name__ == "__main__":
    main()
