"""A synthetic scene in numpy, as testing/synthetic_scene.h makes them: cameras on an arc looking
at points 8-25 m away, keypoints projected with one pinhole camera plus noise, every pair of
nearby cameras matched. Poses are camera-to-world (OpenCV axes)."""
import numpy as np

CAMERA = {"model": "PINHOLE", "width": 1536, "height": 1024,
          "params": [1400.0, 1400.0, 767.5, 511.5]}


def look_at(centre, target):
    """Camera-to-world 4x4 of a camera at `centre` looking at `target` (y down)."""
    z = target - centre
    z /= np.linalg.norm(z)
    x = np.cross(np.array([0.0, -1.0, 0.0]), z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([x, y, z], axis=1)
    pose[:3, 3] = centre
    return pose


def rotation(axis_angle):
    angle = np.linalg.norm(axis_angle)
    if angle == 0:
        return np.eye(3)
    k = axis_angle / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def make_scene(num_cameras=8, num_points=300, noise_px=0.5, max_gap=3, seed=1):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(num_points, 3))
    points *= 7.0 * rng.uniform(size=(num_points, 1)) ** (1 / 3) / np.linalg.norm(
        points, axis=1, keepdims=True)
    angles = np.radians(np.linspace(-35, 35, num_cameras))
    poses = np.stack([look_at(16.0 * np.array([np.sin(a), 0.0, -np.cos(a)]), np.zeros(3))
                      for a in angles])
    fx, fy, cx, cy = CAMERA["params"]
    keypoints, index_of_point = [], []
    for pose in poses:
        in_camera = (points - pose[:3, 3]) @ pose[:3, :3]
        pixels = np.stack([fx * in_camera[:, 0] / in_camera[:, 2] + cx,
                           fy * in_camera[:, 1] / in_camera[:, 2] + cy], axis=1)
        pixels += rng.normal(scale=noise_px, size=pixels.shape)
        visible = ((in_camera[:, 2] > 0) & (pixels[:, 0] >= 0) & (pixels[:, 0] < 1536) &
                   (pixels[:, 1] >= 0) & (pixels[:, 1] < 1024))
        rows = np.flatnonzero(visible)
        keypoints.append(pixels[rows])
        index = np.full(num_points, -1)
        index[rows] = np.arange(len(rows))
        index_of_point.append(index)
    matches = []
    for i in range(num_cameras):
        for j in range(i + 1, min(num_cameras, i + max_gap + 1)):
            both = (index_of_point[i] >= 0) & (index_of_point[j] >= 0)
            matches.append((i, j, np.stack([index_of_point[i][both],
                                             index_of_point[j][both]], axis=1)))
    return poses, keypoints, matches


def perturb(poses, level_deg, seed=2):
    """Each pose rotated by `level_deg` about a random axis and moved by 1.25 % of 16 m per
    degree in a random direction."""
    rng = np.random.default_rng(seed)
    out = poses.copy()
    for pose in out:
        axis = rng.normal(size=3)
        pose[:3, :3] = rotation(np.radians(level_deg) * axis / np.linalg.norm(axis)) @ pose[:3, :3]
        step = rng.normal(size=3)
        pose[:3, 3] += 0.0125 * 16.0 * level_deg * step / np.linalg.norm(step)
    return out


def rotation_errors_deg(estimate, truth):
    """Per camera, the angle between estimated and true orientation after the best rotation
    between the two frames (the gauge's rotation; scale and translation do not enter angles)."""
    r_est = estimate[:, :3, :3]
    r_true = truth[:, :3, :3]
    # The world rotation that maps the truth's frame onto the estimate's (Kabsch on the axes).
    m = np.einsum("nij,nkj->ik", r_est, r_true)
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    align = u @ np.diag([1, 1, d]) @ vt
    relative = np.einsum("ij,njk->nik", align, r_true)
    cos = (np.einsum("nij,nij->n", relative, r_est) - 1) / 2
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))
