"""read_poses / write_poses: each writable format read back gives the poses written."""
import numpy as np
import pytest

import raytime
from synthetic import CAMERA, make_scene


@pytest.mark.parametrize("format,name", [("colmap", "model"), ("colmap_binary", "model_bin"),
                                         ("nerfstudio", "transforms.json"), ("tum", "poses.txt")])
def test_round_trip(tmp_path, format, name):
    truth, _, _ = make_scene(num_cameras=5, num_points=50)
    poses = {f"{i:04d}.jpg": pose for i, pose in enumerate(truth)}
    path = tmp_path / name
    cameras = None if format == "tum" else CAMERA
    raytime.write_poses(path, poses, format, cameras=cameras)
    read_format = {"colmap_binary": "colmap"}.get(format, format)
    back = raytime.read_poses(path, read_format)
    assert back.keys() == poses.keys()
    for key, pose in poses.items():
        # TUM and nerfstudio files carry fewer digits than COLMAP's 17.
        np.testing.assert_allclose(back[key], pose, atol=1e-6 if format in ("tum", "nerfstudio")
                                   else 1e-12)


def test_sample_ground_truth_and_errors(tmp_path):
    from conftest import SAMPLE
    poses = raytime.read_poses(SAMPLE, "strecha")
    assert len(poses) == 11
    assert all(np.allclose(p[:3, :3] @ p[:3, :3].T, np.eye(3)) for p in poses.values())
    assert "colmap" in raytime.READABLE_FORMATS and "hdf5" in raytime.READABLE_FORMATS
    with pytest.raises(raytime.InputError, match="did you mean"):
        raytime.write_poses(tmp_path / "x", poses, "colmapp", cameras=CAMERA)
    with pytest.raises(raytime.InputError, match="cameras"):
        raytime.write_poses(tmp_path / "x", poses, "colmap")
    with pytest.raises(raytime.InputError):
        raytime.read_poses(tmp_path / "missing", "colmap")
