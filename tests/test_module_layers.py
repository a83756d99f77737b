"""Imports run one way, and building the command line parser loads no heavy library.

Each check runs in a fresh interpreter, so that what other tests imported does not hide
an import the module under test makes itself.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import tcr_accuracy

SRC = str(Path(tcr_accuracy.__file__).resolve().parents[1])


def _modules_after(code: str) -> set[str]:
    """The names in sys.modules after running code in a fresh interpreter on this package."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (SRC, env.get("PYTHONPATH", "")) if p)
    script = f"import json, sys\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return set(json.loads(done.stdout.splitlines()[-1]))


@pytest.mark.parametrize("module, below", [
    ("scenario", ["simulate"]),  # simulate reads scenarios, never the other way round
    ("sensitivity", ["sobol", "tolerance", "random_inputs"]),  # the sweeps need no global analysis
    ("random_inputs", ["sobol", "tolerance"]),
    ("robot_visuals", ["viewer"]),  # the scene draws robots, the robots know no scene
    ("meshcat_page", ["viewer", "robot_visuals"]),
])
def test_module_does_not_import_the_modules_built_on_it(module, below):
    loaded = _modules_after(f"import tcr_accuracy.{module}")
    assert f"tcr_accuracy.{module}" in loaded
    assert not loaded & {f"tcr_accuracy.{name}" for name in below}


def test_building_the_parser_imports_no_heavy_library():
    """``--help`` stays instant: every topic module registers its commands without numpy & co."""
    loaded = _modules_after("from tcr_accuracy.cli import build_parser\nbuild_parser()")
    assert {"tcr_accuracy.cli_tolerance", "tcr_accuracy.cli_trajectory"} <= loaded
    assert not loaded & {"numpy", "pinocchio", "scipy", "meshcat", "SALib", "matplotlib"}
