"""raytime.run: the pipeline in this process, the same poses as `raytime run`, the CLI's errors,
Ctrl-C as the CLI takes it."""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

import raytime
from conftest import CLI, SAMPLE, run_cli, temporary_files


def test_run_gives_the_cli_poses(tmp_path, small_pipeline):
    summary = raytime.run(small_pipeline, tmp_path / "py")
    assert summary["status"] == "ok"
    assert [s["id"] for s in summary["stages"]][-1] == "export"
    error_deg = summary["metrics"]["refined"]["sim3"]["mean_rotation_deg"]
    assert error_deg < 0.3
    assert summary["metrics"]["prior"]["sim3"]["mean_rotation_deg"] > 2.0

    status, log = run_cli("run", small_pipeline, "--workdir", tmp_path / "cli")
    assert status == 0, log
    # The exported model to the last digit (17 significant digits in images.txt).
    python_images = (tmp_path / "py" / "refined" / "images.txt").read_text()
    cli_images = (tmp_path / "cli" / "refined" / "images.txt").read_text()
    assert python_images == cli_images
    assert raytime.read_poses(tmp_path / "py" / "refined", "colmap").keys() == {
        p.name for p in (SAMPLE / "images").iterdir()}


def test_rerun_skips_every_stage_and_cache_dir_shares_them(tmp_path, small_pipeline):
    cache = tmp_path / "cache"
    raytime.run(small_pipeline, tmp_path / "w", set={"features.max_features": 256}, cache_dir=cache)
    again = raytime.run(small_pipeline, tmp_path / "w", set=["features.max_features=256"])
    assert again["status"] == "ok"
    assert all(s["status"] == "skipped" for s in again["stages"]), again["stages"]
    # Another work directory takes the stages from the cache (export writes folders: runs).
    other = raytime.run(small_pipeline, tmp_path / "w2", set={"features.max_features": 256},
                        cache_dir=cache)
    assert [s["status"] for s in other["stages"]] == ["cached"] * 6 + ["ran"]


@pytest.mark.parametrize("override", ["refine.orientation_weight=-1", "refine.no_such_key=1",
                                      "features.max_features=[1"])
def test_bad_option_is_the_cli_message(tmp_path, small_pipeline, override):
    with pytest.raises(raytime.InputError) as error:
        raytime.run(small_pipeline, tmp_path / "py", set=[override])
    assert error.value.cause == "input"
    assert isinstance(error.value, raytime.Error)
    status, log = run_cli("run", small_pipeline, "--workdir", tmp_path / "cli", "--set", override)
    assert status == 2
    message = str(error.value)
    assert message
    # The CLI prints it after its log prefix ("HH:MM:SS error "), and ends there.
    assert log.endswith(" error " + message + "\n"), (message, log)


def test_missing_pipeline_and_sweep_are_input_errors(tmp_path):
    with pytest.raises(raytime.InputError):
        raytime.run(tmp_path / "none.yaml", tmp_path / "w")
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(textwrap.dedent(f"""\
        dataset: {{format: strecha, root: {SAMPLE}}}
        stages:
          - prior: {{source: perturb, level_deg: 1}}
        sweep:
          prior.seed: [0, 1]
        """))
    with pytest.raises(raytime.InputError, match="raytime run"):
        raytime.run(sweep, tmp_path / "w")


# A run long enough to interrupt: every feature the sample has, then exhaustive matching.
INTERRUPTED = """\
import sys
import raytime
try:
    raytime.run(sys.argv[1], sys.argv[2])
except KeyboardInterrupt:
    print("KeyboardInterrupt", flush=True)
    sys.exit(7)
"""


def test_ctrl_c_stops_the_run_as_the_cli_does(tmp_path):
    pipeline = tmp_path / "long.yaml"
    pipeline.write_text(textwrap.dedent(f"""\
        dataset: {{format: strecha, root: {SAMPLE}}}
        stages:
          - features: {{max_features: 8192, first_octave: -1}}
          - matches: {{pairs: exhaustive}}
        """))
    workdir = tmp_path / "w"
    child = subprocess.Popen([sys.executable, "-c", INTERRUPTED, str(pipeline), str(workdir)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env={**os.environ, "RAYTIME_PROGRESS": "0"})
    deadline = time.monotonic() + 60
    summary_path = workdir / "summary.json"
    while time.monotonic() < deadline:
        if summary_path.exists() and '"stage": "features"' in summary_path.read_text():
            break
        time.sleep(0.02)
    else:
        child.kill()
        pytest.fail("the run never reached the features stage")
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=30)
    stopped_s = time.monotonic() - sent
    assert child.returncode == 7, err
    assert "KeyboardInterrupt" in out
    assert stopped_s < 5, stopped_s
    summary = json.loads(summary_path.read_text())
    assert summary["status"] == "interrupted"
    assert summary["stage"] == "features"
    assert summary["signal"] == signal.SIGINT
    assert temporary_files(workdir) == []
    # Stopped inside the stage, not after it.
    assert not (workdir / "features.h5").exists()
