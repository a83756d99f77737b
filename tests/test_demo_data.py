"""The bundled demo measurement set ships with the package and is what its script makes."""

import importlib.resources
import subprocess
import sys

import numpy as np

from tcr_accuracy.io.measurements import read_measurements
from tcr_accuracy.model.robot import load_robot

from conftest import REPO


def test_bundled_measurements_read_cleanly_and_carry_the_cutter(tmp_path):
    robot = load_robot()
    data = importlib.resources.files("tcr_accuracy") / "data" / "tool_changer_cutter.csv"
    mset = read_measurements(data, robot, min_rows=100)
    assert mset.q.shape == (300, 6)
    assert set(np.unique(mset.payload_kg)) == {0.0, 150.0}


def test_bundled_measurements_are_reproducible_from_the_scenario(tmp_path):
    """Regenerating with the script's command gives the committed file byte for byte."""
    out, truth = tmp_path / "m.csv", tmp_path / "t.yaml"
    done = subprocess.run([sys.executable, "-m", "tcr_accuracy", "simulate",
                           "--scenario", str(REPO / "examples" / "scenario_demo_cutter.yaml"),
                           "--n", "300", "--seed", "2026", "--out", str(out), "--truth", str(truth)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    committed = importlib.resources.files("tcr_accuracy") / "data" / "tool_changer_cutter.csv"
    assert out.read_text() == committed.read_text()
