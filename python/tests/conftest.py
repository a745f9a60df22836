"""Shared fixtures: the source tree, the raytime binary built beside the module, a small pipeline
on the sample scene. CTest sets RAYTIME_SOURCE_DIR and RAYTIME_CLI (python/CMakeLists.txt)."""
import os
import pathlib
import subprocess

import pytest

SOURCE_DIR = pathlib.Path(os.environ.get(
    "RAYTIME_SOURCE_DIR", pathlib.Path(__file__).resolve().parents[2]))
CLI = os.environ.get("RAYTIME_CLI", str(SOURCE_DIR / "build" / "cli" / "raytime"))
SAMPLE = SOURCE_DIR / "data" / "sample" / "fountain-P11"

# The sample scene with a cheap front end: few features, every pair, a 4° prior, refine auto.
SMALL_PIPELINE = f"""name: python-small
dataset: {{format: strecha, root: {SAMPLE}}}
stages:
  - features: {{max_features: 1024}}
  - matches: {{pairs: exhaustive}}
  - prior: {{source: perturb, mode: iid, level_deg: 4, seed: 0, translation_per_deg: 0.0125}}
  - refine: {{preset: auto}}
  - evaluate: {{poses: [prior, refined], alignments: [sim3]}}
  - export: {{poses: [refined], formats: [colmap_text]}}
"""


@pytest.fixture
def small_pipeline(tmp_path):
    path = tmp_path / "small.yaml"
    path.write_text(SMALL_PIPELINE)
    return path


def run_cli(*args):
    """`raytime ARGS...`: (exit status, stderr)."""
    result = subprocess.run([CLI, *map(str, args)], capture_output=True, text=True,
                            cwd=SOURCE_DIR, env={**os.environ, "RAYTIME_PROGRESS": "0"})
    return result.returncode, result.stderr


def temporary_files(folder):
    """raytime's temporaries (.NAME.tmp.PID.N) below `folder`."""
    return [p for p in pathlib.Path(folder).rglob("*") if ".tmp." in p.name]
