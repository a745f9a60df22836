"""raytime.refine on a synthetic scene with known poses: a prior a few degrees off is refined to
the truth; bad input and options are InputErrors."""
import numpy as np
import pytest

import raytime
from synthetic import CAMERA, make_scene, perturb, rotation_errors_deg


def test_refine_recovers_the_truth():
    truth, keypoints, matches = make_scene()
    prior = perturb(truth, level_deg=3.0)
    assert rotation_errors_deg(prior, truth).mean() > 1.5
    result = raytime.refine(CAMERA, prior, keypoints, matches)
    assert result["refined"].all()
    assert result["poses"].shape == truth.shape
    errors = rotation_errors_deg(result["poses"], truth)
    assert errors.max() < 0.1, errors
    assert [v["verdict"] for v in result["verdicts"]] == ["held"] * len(truth)
    assert np.isfinite(result["sigma_rotation_deg"]).all()
    assert (result["sigma_rotation_deg"] < 0.1).all()
    assert result["summary"]["preset"] == "auto"
    assert result["summary"]["total_iterations"] > 0


def test_refine_reads_options_as_the_stage_does():
    truth, keypoints, matches = make_scene(num_cameras=5, num_points=150)
    prior = perturb(truth, level_deg=1.0)
    # Preset gnc keeps a trust region (3.5°, 2.2 % of the scene): this prior's centres are moved
    # further, so the guardrail returns the prior.
    guarded = raytime.refine([CAMERA] * 5, prior, keypoints, matches, names=list("abcde"),
                             preset="gnc")
    assert guarded["summary"]["preset"] == "gnc"
    assert not guarded["refined"].any()
    assert {v["reason"] for v in guarded["verdicts"]} == {"returned_prior"}
    np.testing.assert_array_equal(guarded["poses"], prior)
    # A key given explicitly wins over the preset's, as in a pipeline file.
    result = raytime.refine([CAMERA] * 5, prior, keypoints, matches, names=list("abcde"),
                            preset="gnc", options={"trust_region": False,
                                                   "max_matches_per_pair": 40})
    assert result["refined"].all()
    assert rotation_errors_deg(result["poses"], truth).max() < 0.1
    assert set(result["uncertainty"]) == set("abcde")
    with pytest.raises(raytime.InputError, match="orientation_weight"):
        raytime.refine(CAMERA, prior, keypoints, matches, options={"orientation_weight": -1})
    with pytest.raises(raytime.InputError, match="did you mean"):
        raytime.refine(CAMERA, prior, keypoints, matches, options={"max_matches_per_par": 40})
    with pytest.raises(raytime.InputError, match="preset"):
        raytime.refine(CAMERA, prior, keypoints, matches, preset="no-such-preset")


def test_refine_refuses_bad_arrays():
    truth, keypoints, matches = make_scene(num_cameras=4, num_points=100)
    with pytest.raises(raytime.InputError, match="keypoint"):
        raytime.refine(CAMERA, truth, keypoints, [(0, 1, np.array([[0, 10**6]]))])
    with pytest.raises(raytime.InputError, match="rotation"):
        bad = truth.copy()
        bad[2, :3, :3] *= 2
        raytime.refine(CAMERA, bad, keypoints, matches)
    with pytest.raises(raytime.InputError, match="model"):
        raytime.refine({**CAMERA, "model": "FISHEYE"}, truth, keypoints, matches)
