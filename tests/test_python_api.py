"""What a Python user meets: Python 3.10 without tomllib, scenarios that serialise, the
top-level names."""

import json
import sys
import types

import numpy as np
import pytest
import yaml

import tcr_accuracy
from tcr_accuracy.analysis.simulate import random_scenario, simulate_measurements
from tcr_accuracy.io.budget_file import read_table


def test_toml_files_are_read_with_tomli_where_tomllib_is_missing(tmp_path, monkeypatch):
    """Python 3.10 has no tomllib: the tomli package (same API) takes its place."""
    import tomllib as real

    calls = []
    fake_tomli = types.ModuleType("tomli")
    fake_tomli.TOMLDecodeError = real.TOMLDecodeError
    fake_tomli.loads = lambda text: calls.append(text) or real.loads(text)
    monkeypatch.setitem(sys.modules, "tomllib", None)  # `import tomllib` raises ModuleNotFoundError
    monkeypatch.setitem(sys.modules, "tomli", fake_tomli)
    path = tmp_path / "b.toml"
    path.write_text('name = "x"\n[groups.drive]\nstd_deg = 0.3\n')
    assert read_table(path) == {"name": "x", "groups": {"drive": {"std_deg": 0.3}}}
    assert len(calls) == 1


def test_pyproject_asks_for_tomli_before_python_3_11():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text()
    assert "tomli>=1.1; python_version < '3.11'" in text


def test_random_scenario_survives_yaml_and_json_and_simulates_the_same(tool_changer):
    scenario = random_scenario(tool_changer, np.random.default_rng(5), n_dominant=2, outside="unmodelled")
    text = yaml.safe_dump(scenario)            # raised on numpy str keys before
    loaded = yaml.safe_load(text)
    assert json.loads(json.dumps(scenario)) == loaded
    a, _ = simulate_measurements(tool_changer, scenario, 20, np.random.default_rng(1))
    b, _ = simulate_measurements(tool_changer, loaded, 20, np.random.default_rng(1))
    assert np.array_equal(a.q, b.q) and np.array_equal(a.position, b.position)


def test_top_level_names_load_and_are_listed():
    for name in ("load_robot", "run_monte_carlo", "diagnose", "make_predictor", "compensate_joints",
                 "simulate_measurements", "read_measurements"):
        assert name in dir(tcr_accuracy) and callable(getattr(tcr_accuracy, name))
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        tcr_accuracy.not_a_name  # noqa: B018


# ---------------------------------------------------------------------------------------
# Issue 29 item 10: hyper-parameters checked when fit starts, NaN joints refused
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("make, said", [
    (lambda r: __import__("tcr_accuracy.prediction.baselines", fromlist=["x"]).InverseDistanceWeighting(
        power=float("nan")), "The 'power' parameter of InverseDistanceWeighting must be a float in the range"),
    (lambda r: __import__("tcr_accuracy.prediction.calibration", fromlist=["x"]).GeometricCalibration(
        robot=r, rank_tol=float("nan")), "The 'rank_tol' parameter of GeometricCalibration"),
    (lambda r: tcr_accuracy.GapDiagnosis(robot=r, tracker_noise=-2e-5), "The 'tracker_noise' parameter of GapDiagnosis"),
    (lambda r: tcr_accuracy.GapDiagnosis(robot=r, selection_z=-3.0), "The 'selection_z' parameter of GapDiagnosis"),
    # no replay, no frequency (it divided by zero deep in the attribution before)
    (lambda r: tcr_accuracy.GapDiagnosis(robot=r, stability_replays=0),
     r"The 'stability_replays' parameter of GapDiagnosis must be an int in the range \[1, 100000\]"),
])
def test_29_10_a_hyperparameter_outside_its_range_is_refused_when_fit_starts(make, said, tool_changer):
    from sklearn.utils._param_validation import InvalidParameterError

    from tcr_accuracy.exceptions import InputError

    rng = np.random.default_rng(0)
    q = rng.uniform(-1, 1, (30, tool_changer.n_joints))
    estimator = make(tool_changer)
    with pytest.raises(InputError, match=said) as caught:
        estimator.fit(q, np.zeros((30, 3)))
    assert isinstance(caught.value, InvalidParameterError)  # scikit-learn's own checks read it as theirs


def test_29_10_tcp_poses_of_nan_joints_is_refused_naming_the_row(tool_changer):
    from tcr_accuracy.exceptions import InputError

    q = np.zeros((3, tool_changer.n_joints))
    q[2, 4] = np.nan
    with pytest.raises(InputError, match="joint values: row 2, column 4 is nan, not a finite number"):
        tcr_accuracy.tcp_poses(tool_changer, q)
