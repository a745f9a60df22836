"""examples/python/refine_arrays.py runs and refines its scene (run_demo.py is test_run's run on
the demo pipeline, too long for the suite)."""
import re
import subprocess
import sys

from conftest import SOURCE_DIR


def test_refine_arrays_example():
    result = subprocess.run([sys.executable, str(SOURCE_DIR / "examples/python/refine_arrays.py")],
                            capture_output=True, text=True, check=True)
    prior, refined = map(float, re.search(r"prior ([\d.]+) deg, refined ([\d.]+) deg",
                                          result.stdout).groups())
    assert prior > 2 and refined < 0.05, result.stdout
