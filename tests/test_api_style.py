"""One Python API style: scikit-learn's estimator conventions, ``random_state`` for every source
of randomness, SI attributes, short reprs, and the printed summary reachable from Python.

The diagnosis is run once on a small simulated data set (two effects, 60 rows) and shared.
"""

import math
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest
from sklearn.base import clone

import tcr_accuracy as tcr
from tcr_accuracy.cli.writers import write_measurements
from tcr_accuracy.prediction.methods import METHODS

from conftest import REPO

FRAMES = {"base_mm": {"dx": 1250.0, "dy": -830.0, "dz": -410.0}, "base_deg": {"rz": 35.0},
          "tool_mm": {"dx": 0.8, "dy": -0.5, "dz": 1.2}}
SCENARIO = {"effects": {"frames": FRAMES, "joint_offsets": {"offsets_deg": {"j2": 0.03, "j3": -0.02, "j5": 0.04}},
                        "geometry": {"spread_mm": 0.05, "spread_mrad": 0.05}},
            "noise_mm": 0.02}
EFFECTS = ["joint_offsets", "geometry"]
SETTINGS = {"effects": EFFECTS, "folds": 3, "stability_replays": 3, "tracker_noise": 2e-5}


@pytest.fixture(scope="module")
def measured(tool_changer):
    mset, _ = tcr.simulate_measurements(tool_changer, SCENARIO, 60, random_state=3)
    return mset


@pytest.fixture(scope="module")
def fitted(tool_changer, measured):
    return tcr.GapDiagnosis(robot=tool_changer, random_state=0, **SETTINGS).fit(measured)


def _constructor_examples(robot):
    """Non-default constructor parameters of every estimator the package exports."""
    return {
        "GapDiagnosis": {"robot": robot, "effects": ["geometry"], "folds": 4, "random_state": 7,
                         "tracker_noise": 3e-5, "stability_replays": 5},
        "MeasuredErrorModel": {"robot": robot, "estimator": tcr.make_predictor("gp", robot, random_state=1),
                               "fit_frame": False},
    }


def _exported_estimators():
    return [name for name in tcr._EXPORTS
            if isinstance(getattr(tcr, name), type) and hasattr(getattr(tcr, name), "get_params")]


def _same(x, y) -> bool:
    """Parameter values equal: estimators by class and their own parameters, robots by URDF,
    lists and tuples (a Pipeline's steps) item by item."""
    if hasattr(x, "get_params"):
        return type(x) is type(y) and _same_params(x.get_params(deep=False), y.get_params(deep=False))
    if isinstance(x, tcr.RobotModel):
        return isinstance(y, tcr.RobotModel) and x.name == y.name and x.urdf_text == y.urdf_text
    if isinstance(x, (list, tuple)):
        return type(x) is type(y) and len(x) == len(y) and all(_same(a, b) for a, b in zip(x, y))
    return bool(x == y)


def _same_params(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(_same(a[key], b[key]) for key in a)


# ---------------------------------------------------------------------------------------
# scikit-learn conventions
# ---------------------------------------------------------------------------------------
def test_the_exported_estimators_are_the_two_expected():
    assert sorted(_exported_estimators()) == ["GapDiagnosis", "MeasuredErrorModel"]


@pytest.mark.parametrize("name", ["GapDiagnosis", "MeasuredErrorModel"])
def test_exported_estimators_store_parameters_unchanged_and_clone(name, tool_changer):
    kwargs = _constructor_examples(tool_changer)[name]
    estimator = getattr(tcr, name)(**kwargs)
    for key, value in kwargs.items():
        assert getattr(estimator, key) is value  # stored as given: no copy, no validation
    copy = clone(estimator)
    assert type(copy) is type(estimator) and copy is not estimator
    assert _same_params(copy.get_params(deep=False), estimator.get_params(deep=False))
    # round trip: a default-built estimator takes the parameters of the other through set_params
    fresh = getattr(tcr, name)()
    assert not _same_params(fresh.get_params(deep=False), estimator.get_params(deep=False))
    fresh.set_params(**estimator.get_params(deep=False))
    assert _same_params(fresh.get_params(deep=False), estimator.get_params(deep=False))
    with pytest.raises(ValueError, match="Invalid parameter"):
        fresh.set_params(not_a_parameter=1)


@pytest.mark.parametrize("method", METHODS)
def test_every_predictor_of_make_predictor_clones_with_its_parameters(method, tool_changer):
    estimator = tcr.make_predictor(method, tool_changer, random_state=5)
    copy = clone(estimator)
    assert type(copy) is type(estimator)
    assert _same_params(copy.get_params(deep=False), estimator.get_params(deep=False))
    params = estimator.get_params(deep=True)
    seeds = [v for k, v in params.items() if k == "random_state" or k.endswith("__random_state")]
    assert all(v == 5 for v in seeds), params  # every random part gets the caller's random_state
    copy.set_params(**{k: v for k, v in params.items() if "__" not in k})
    assert _same_params(copy.get_params(deep=False), estimator.get_params(deep=False))


def test_fitting_a_clone_gives_the_same_numbers_and_random_state_matters(fitted, measured):
    again = clone(fitted)
    assert not hasattr(again, "result_")  # clone is unfitted
    again.fit(measured)
    a, b = fitted.result_, again.result_
    np.testing.assert_array_equal(a.heldout_residual, b.heldout_residual)
    assert a.parameters == b.parameters and a.selected_effects == b.selected_effects
    # another random_state splits the folds differently: the held-out residual changes
    other = clone(fitted).set_params(random_state=1).fit(measured).result_
    assert not np.array_equal(other.heldout_residual, a.heldout_residual)
    # a Generator is a random_state as good as an int
    with_generator = clone(fitted).set_params(random_state=np.random.default_rng(2)).fit(measured)
    assert with_generator.result_.n_measurements == len(measured)


def test_measured_error_model_clone_predicts_the_same(tool_changer, measured):
    model = tcr.MeasuredErrorModel(robot=tool_changer, estimator=tcr.make_predictor("kriging", tool_changer))
    copy = clone(model)
    model.fit(measured.q[:50], measured.position[:50])
    copy.fit(measured.q[:50], measured.position[:50])
    np.testing.assert_array_equal(model.predict(measured.q[50:]), copy.predict(measured.q[50:]))


@pytest.mark.slow
def test_local_gp_passes_the_scikit_learn_estimator_checks():
    """The predictors that are array estimators (joint values in, errors out) pass
    check_estimator: kriging, IDW, GP and the residual composition in test_prediction.py,
    the local GP here. GapDiagnosis and MeasuredErrorModel are not array estimators (they
    need one robot's joint values and the measurement context), so clone and
    get_params/set_params are tested for them above instead."""
    from sklearn.utils.estimator_checks import check_estimator

    from tcr_accuracy.prediction.local_gp import LocalGaussianProcess

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # SkipTestWarning for the array-API check
        results = check_estimator(LocalGaussianProcess(expert_size=30, max_optimize_samples=30, random_state=0),
                                  on_fail=None)
    bad = [(r["check_name"], str(r["exception"])[:200]) for r in results
           if r["status"] != "passed" and r["check_name"] != "check_array_api_input"]
    assert not bad
    assert len(results) > 40


# ---------------------------------------------------------------------------------------
# random_state everywhere; the old keywords still work for one release
# ---------------------------------------------------------------------------------------
def test_old_random_keywords_warn_and_give_the_same_numbers(tool_changer):
    budget = tcr.seed_budget(tool_changer, "table2")
    new = tcr.run_monte_carlo(budget, tool_changer.working_pose, 300, random_state=4)
    with pytest.warns(DeprecationWarning, match=r"run_monte_carlo\(rng=...\) is deprecated.*random_state"):
        old = tcr.run_monte_carlo(budget, tool_changer.working_pose, 300, rng=4)
    np.testing.assert_array_equal(new.cloud, old.cloud)
    with pytest.warns(DeprecationWarning, match="sampler"):
        tcr.run_monte_carlo(sampler=budget, q=tool_changer.working_pose, n_samples=10)
    a, _ = tcr.simulate_measurements(tool_changer, SCENARIO, 5, random_state=np.random.default_rng(9))
    with pytest.warns(DeprecationWarning, match="simulate_measurements"):
        b, _ = tcr.simulate_measurements(tool_changer, SCENARIO, 5, rng=9)
    np.testing.assert_array_equal(a.position, b.position)  # default_rng(9) is the stream of the int 9
    with pytest.warns(DeprecationWarning, match="GapDiagnosis"):
        assert tcr.GapDiagnosis(seed=3).random_state == 3
    with pytest.raises(TypeError, match="both"):
        tcr.run_monte_carlo(budget, tool_changer.working_pose, 10, random_state=1, rng=1)


def test_old_fit_form_warns_and_fits_the_same(fitted, tool_changer, measured):
    estimator = clone(fitted).set_params(robot=None)
    with pytest.warns(DeprecationWarning, match=r"fit\(robot, measurements\)"):
        estimator.fit(tool_changer, measured)
    np.testing.assert_array_equal(estimator.result_.heldout_residual, fitted.result_.heldout_residual)


# ---------------------------------------------------------------------------------------
# SI attributes, context as a property
# ---------------------------------------------------------------------------------------
def test_diagnosis_attributes_are_si_and_the_mm_ones_say_so(fitted):
    d = fitted.result_
    norm = np.linalg.norm(d.gap_residual, axis=1)  # (N, 3) [m]
    assert d.gap.rms == pytest.approx(np.sqrt(np.mean(norm**2)), rel=1e-12)
    assert d.gap.rms < 1e-3  # metres: the gap of 0.05 mm geometry is far below 1 mm
    for c, axis in enumerate("xyz"):  # where_mm holds the same residual in mm
        assert d.where_mm["per_axis"][axis]["rms_mm"] == pytest.approx(
            np.sqrt(np.mean(d.gap_residual[:, c] ** 2)) * 1e3, rel=1e-12)
    held = np.linalg.norm(np.concatenate(d.stages.residual.heldout_repeats), axis=1)  # every fold assignment
    assert d.steps[-1].heldout.rms == pytest.approx(np.sqrt(np.mean(held**2)), rel=1e-12)
    assert d.noise_floor == pytest.approx(np.sqrt(3) * 2e-5)  # tracker_noise given in m
    assert d.where is d.where_mm  # the old name, kept one release


def test_measurement_context_is_a_property_like_payload(measured):
    ctx = measured.context
    np.testing.assert_array_equal(ctx.payload_kg, measured.payload_kg)
    np.testing.assert_array_equal(ctx.temperature_c, measured.temperature_c)
    assert measured.make_context(reference_temperature_c=30.0).payload_kg.shape == (len(measured),)


# ---------------------------------------------------------------------------------------
# Short reprs
# ---------------------------------------------------------------------------------------
def test_reprs_are_one_short_line_with_the_key_facts(tool_changer, ur5, measured, fitted):
    budget = tcr.seed_budget(tool_changer, "table2")
    mc = tcr.run_monte_carlo(budget, tool_changer.working_pose, 200, random_state=0,
                             position_tolerances=[0.25e-3])
    from tcr_accuracy.asbuilt.model import AsBuiltModel

    as_built = AsBuiltModel.from_diagnosis(tool_changer, fitted.result_)
    final_mm = f"{fitted.result_.steps[-1].heldout.rms * 1e3:.4g} mm"
    cases = [
        (tool_changer, ["'tool_changer'", "6 joints", "'tool'"]),
        (ur5, ["'ur5'", "6 joints"]),
        (measured, ["60 rows", "6 joints"]),
        (tcr.ErrorModel(tool_changer), ["'tool_changer'", f"{tcr.ErrorModel(tool_changer).size} parameters"]),
        (budget, ["'table2'", f"{len(budget.sources)} sources"]),
        (mc, ["200 samples", f"{mc.position_reliability[0]:.4f}"]),
        (fitted.result_, ["'tool_changer'", "60 measurements", "frames", final_mm]),
        (as_built, ["'tool_changer'", "geometry"]),
        (fitted, ["GapDiagnosis", "RobotModel('tool_changer'"]),
        (tcr.MeasuredErrorModel(robot=tool_changer, estimator=tcr.make_predictor("diagnosis+gp", tool_changer)),
         ["MeasuredErrorModel", "DiagnosisCalibration"]),
    ]
    for obj, facts in cases:
        text = repr(obj)
        assert "\n" not in text and len(text) < 300, text
        for fact in facts:
            assert fact in text, (fact, text)


# ---------------------------------------------------------------------------------------
# The printed summary from Python
# ---------------------------------------------------------------------------------------
def test_python_summary_prints_the_gap_an_independent_frame_fit_finds(tool_changer, measured):
    """tcr.diagnosis_summary prints, as its gap, what a rigid tracker frame and a TCP offset fitted
    by hand (Pinocchio's forward kinematics and scipy's least squares, written out here) leave."""
    import pinocchio as pin
    from scipy.optimize import least_squares

    d = tcr.diagnose(tool_changer, measured, folds=3, random_state=0, effects=EFFECTS, tracker_noise=2e-5)
    text = tcr.diagnosis_summary(d, source="the test's rows")
    assert text.startswith("Diagnosis of the test's rows: 60 measurements of tool_changer")
    gap_line = next(line for line in text.splitlines() if line.startswith("1. Gap"))
    printed_rms_mm = float(re.search(r"RMS ([0-9.]+) mm", gap_line).group(1))

    model, data = tool_changer.model, tool_changer.model.createData()
    frame = model.getFrameId(tool_changer.tool_frame)

    def tcp(offset):
        out = []
        for row in measured.q:
            pin.framesForwardKinematics(model, data, tool_changer.to_pinocchio_q(row))
            out.append(data.oMf[frame].act(offset))
        return np.array(out)

    def residual(p):  # p: rotation vector and translation of the tracker frame, then the TCP offset
        tracker = pin.exp6(pin.Motion(p[3:6], p[:3]))
        points = tcp(p[6:9]) @ tracker.rotation.T + tracker.translation
        return (points - measured.position).ravel()

    fit = least_squares(residual, np.zeros(9), x_scale=[1, 1, 1, 0.01, 0.01, 0.01, 0.01, 0.01, 0.01])
    by_hand_rms = np.sqrt(np.mean(np.sum(fit.fun.reshape(-1, 3) ** 2, axis=1)))
    assert printed_rms_mm == pytest.approx(by_hand_rms * 1e3, abs=1e-4)  # printed to 4 decimals in mm


def test_python_summary_prints_the_diagnosis_figures_in_mm(tool_changer, measured):
    """The step table and the closing line of tcr.diagnosis_summary are the Diagnosis' SI figures
    converted here by hand (m -> mm: x 1000, printed to 4 decimals); the noise floor is the closed
    form for the tracker noise given (2e-5 m per axis: sqrt(3) x 2e-5 m RMS in 3-D), and each
    step's gain is the previous step's held-out RMS minus its own."""
    d = tcr.diagnose(tool_changer, measured, folds=3, random_state=0, effects=EFFECTS, tracker_noise=2e-5)
    lines = tcr.diagnosis_summary(d).splitlines()
    rows = {}
    for line in lines:
        m = re.match(r"\s+\+?(\w+)\s+(\d+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)(\s+[+-][0-9.]+)?", line)
        if m and m.group(1) in [s.effect for s in d.steps]:
            rows[m.group(1)] = m.groups()[1:]
    assert list(rows) == [s.effect for s in d.steps] and len(rows) >= 2  # frames, then the chosen effects
    previous_rms = None
    for step in d.steps:
        params, train, mean, rms, worst, gain = rows[step.effect]
        assert int(params) == step.n_parameters
        printed = [float(train), float(mean), float(rms), float(worst)]
        expected = [1000.0 * v for v in (step.train_rms, step.heldout.mean, step.heldout.rms, step.heldout.max)]
        np.testing.assert_allclose(printed, expected, atol=5.1e-5)
        if previous_rms is None:
            assert gain is None
        else:
            assert float(gain) == pytest.approx(1000.0 * (previous_rms - step.heldout.rms), abs=1.1e-4)
        previous_rms = step.heldout.rms
    closing = next(line for line in lines if "final held-out RMS" in line)
    floor_mm = math.sqrt(3) * 2e-5 * 1000.0
    final_mm = 1000.0 * d.steps[-1].heldout.rms
    assert f"final held-out RMS {final_mm:.4f} mm = {final_mm / floor_mm:.2f} x the noise floor " \
           f"{floor_mm:.4f} mm (tracker 0.0200 mm per axis)" in closing, closing
