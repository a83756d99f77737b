"""Fits that cannot diverge, parameters that obey physics, answers with their uncertainty.

Every data set here is made by a forward model written out in this file on Pinocchio
directly (``pin.framesForwardKinematics``, ``pin.computeGeneralizedGravity``), not by the
project's effect classes, so the diagnosis' own maps cannot cancel their mistakes.
"""

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import lsq_linear

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fitting import FitEngine
from tcr_accuracy.diagnosis.least_squares import box_quadratic
from tcr_accuracy.io.measurements import MeasurementSet
from tcr_accuracy.effects import effect_classes, make_effect
from tcr_accuracy.model.robot import load_robot, robot_from_urdf_text

from conftest import random_joint_values


def _positions(robot, q: np.ndarray, frame: str | None = None) -> np.ndarray:
    """(N, 3) position of a frame [m] by Pinocchio's own forward kinematics, pose by pose."""
    model = robot.model
    data = model.createData()
    fid = model.getFrameId(frame or robot.tool_frame)
    out = np.empty((q.shape[0], 3))
    for i, row in enumerate(q):
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(row))
        out[i] = data.oMf[fid].translation
    return out


def _gravity(robot, q: np.ndarray) -> np.ndarray:
    """(N, n) torque gravity exerts on the chain joints [Nm]: minus Pinocchio's generalized
    gravity (the torque that holds the arm), on the whole tree, no payload."""
    model = robot.full_model
    data = model.createData()
    rows = [model.joints[j].idx_v for j in robot.chain_joint_ids]
    return np.array([-pin.computeGeneralizedGravity(model, data, config)[rows]
                     for config in robot.full_configurations(q)])


def _observations(q, position, direction=None) -> MeasurementSet:
    return MeasurementSet(joint_names=[f"j{k}" for k in range(q.shape[1])], q=q, position=position,
                          direction=direction)


# ---------------------------------------------------------------------------------------
# The bounded step
# ---------------------------------------------------------------------------------------
def test_box_quadratic_matches_scipy_bvls():
    """The active-set box solver reaches scipy's BVLS optimum on random convex problems."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        k = int(rng.integers(1, 25))
        a = rng.normal(size=(k + 4, k))
        hessian = a.T @ a + 1e-8 * np.eye(k)
        gradient = 3 * rng.normal(size=k)
        low = np.where(rng.random(k) < 0.5, -rng.random(k), -np.inf)
        high = np.where(rng.random(k) < 0.5, rng.random(k), np.inf)
        d = box_quadratic(hessian, gradient, low, high)
        root = np.linalg.cholesky(hessian)
        reference = lsq_linear(root.T, -np.linalg.solve(root, gradient), bounds=(low, high), method="bvls",
                               tol=1e-14).x
        objective = lambda x: 0.5 * x @ hessian @ x + gradient @ x  # noqa: E731
        assert np.all(d >= low - 1e-12) and np.all(d <= high + 1e-12)
        assert objective(d) <= objective(reference) + 1e-9 * max(1.0, abs(objective(reference)))


def test_every_effect_declares_its_physics():
    """Each effect in the vocabulary says why its parameters lie where they do; magnitudes
    cannot be negative in its own physics; the ranges hold the typical sizes; the fit range is
    the union of its mechanisms' ranges, its own physics first among them."""
    robot = load_robot("ur5")
    for name, cls in effect_classes().items():
        if cls.stochastic:
            continue
        assert cls.physics, f"{name} gives no reason for its range"
        effect = make_effect(name, robot)
        lower, upper = effect.physical_range()
        scales = effect.parameter_scales()
        assert np.all(lower <= 0.0) and np.all(upper >= scales), name  # zero and the typical size inside
        if cls.non_negative:
            assert np.all(lower == 0.0), name
        else:
            assert np.all(lower <= -scales) or name == "thermal", name
        mechanisms = effect.mechanisms()
        fit_lower, fit_upper = effect.fit_range()
        own = [m for m in mechanisms if m.textbook]  # its own physics first (one mechanism, or one per shape)
        assert all(m.textbook for m in mechanisms[:len(own)]), name
        np.testing.assert_allclose(np.minimum.reduce([m.lower for m in own]), lower, err_msg=name)
        np.testing.assert_allclose(np.maximum.reduce([m.upper for m in own]), upper, err_msg=name)
        if name != "frames":
            np.testing.assert_allclose(np.minimum.reduce([m.lower for m in mechanisms]), fit_lower, err_msg=name)
            np.testing.assert_allclose(np.maximum.reduce([m.upper for m in mechanisms]), fit_upper, err_msg=name)


# ---------------------------------------------------------------------------------------
# Nested models cannot fit worse
# ---------------------------------------------------------------------------------------
def test_nested_models_never_fit_worse_on_ill_conditioned_data():
    """A 7-joint arm, few poses, compliance and periodic gear errors both hidden (written out
    here), every effect free to enter: of all the models the diagnosis fitted, none fits its
    training rows worse than a model nested in it (its effects and, of each, its identifiable
    columns among the larger model's); and each fold's one-step refit predicts its
    held-out rows as a full nonlinear refit of that fold (scipy's least_squares on the exact
    kinematics, started where the engine started) does."""
    from scipy.optimize import least_squares

    robot = load_robot("panda")
    rng = np.random.default_rng(11)
    q = random_joint_values(robot, 70, rng)
    compliance = np.array([4e-4, 6e-4, 4e-4, 5e-4, 8e-4, 8e-4, 8e-4])  # rad/Nm
    amplitude = np.radians(0.02) * rng.standard_normal((robot.n_joints, 2))
    real = q + compliance * _gravity(robot, q) + amplitude[:, 0] * np.sin(q) + amplitude[:, 1] * np.cos(2 * q)
    position = _positions(robot, real) + 3e-5 * rng.standard_normal((q.shape[0], 3))
    fit = GapDiagnosis(robot=robot, folds=4, stability_replays=5).fit(_observations(q, position))
    engine = fit.engine_
    results = list(engine._full_cache.values())

    def nested(inner, outer):  # every column of the inner model is in the outer one: a model of fewer
        # effects measured in a larger model's partition (an own share) may lack a column its own has
        return set(inner["effects"]) < set(outer["effects"]) and all(
            set(np.asarray(inner["keep"][e]).tolist()) <= set(np.asarray(outer["keep"][e]).tolist())
            for e in inner["effects"])

    pairs = 0
    for outer in results:
        for inner in results:  # on the same model of the residual: the linear one, or the exact kinematics
            if nested(inner, outer) and inner["exact"] == outer["exact"]:
                pairs += 1
                assert outer["cost"] <= inner["cost"] * (1 + 1e-9), (inner["effects"], outer["effects"])
    assert pairs > 20
    train = [s.train_rms for s in fit.result_.steps]
    assert all(b <= a * (1 + 1e-9) for a, b in zip(train, train[1:]))
    final = engine.evaluate(list(fit.result_.stages.select.selected), exact=True)
    cols = engine.columns(list(final["effects"]), final["keep"])
    for f, (train_rows, test) in enumerate(engine.folds):
        refit = least_squares(lambda phi: np.concatenate([r.ravel() for r in engine.predict_residual(
            cols, phi, train_rows)]), final["phi"], bounds=(cols.lower, cols.upper), method="trf")
        full = np.sqrt(np.mean(np.sum(engine.predict_residual(cols, refit.x, test)[0] ** 2, axis=1)))
        one_step = np.sqrt(np.mean(np.sum(final["heldout_residual"][test] ** 2, axis=1)))
        assert one_step == pytest.approx(full, rel=0.03), f


# ---------------------------------------------------------------------------------------
# Physics in the fit
# ---------------------------------------------------------------------------------------
LEAD_ARM = """<?xml version="1.0"?>
<robot name="lead_arm">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tcp"/>
  <joint name="a" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="b" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="c" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.5 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="t" type="fixed"><parent link="l3"/><child link="tcp"/><origin xyz="0.4 0 0.05"/></joint>
</robot>
"""


def test_joints_that_lead_their_motion_are_kept_and_read_as_lost_motion_compensation():
    """Each joint ends ahead of its approach by 0.06-0.1 deg (a lost-motion compensation set
    too high, written out here): the direction-dependent term is kept (backlash's signature with
    negative widths, each within 10 % of the truth), the held-out error reaches the noise, and
    the mechanism named is the controller's compensation, not a dead band."""
    robot = robot_from_urdf_text(LEAD_ARM, "tcp", name="lead_arm")
    rng = np.random.default_rng(5)
    n = 240
    q = random_joint_values(robot, n, rng)
    direction = rng.choice([-1.0, 1.0], size=(n, 3))
    lead = np.radians([0.08, 0.06, 0.1])
    position = _positions(robot, q + lead * direction) + 1e-5 * rng.standard_normal((n, 3))
    d = GapDiagnosis(robot=robot, stability_replays=10).fit(_observations(q, position, direction)).result_
    assert "backlash" in d.selected_effects
    widths = d.parameter_table["backlash"]["values"]  # dq = width / 2 * (-direction): a lead is a negative width
    for j, joint in enumerate(robot.joint_names):
        assert -widths[f"backlash.{joint}"] / 2 == pytest.approx(lead[j], rel=0.1), joint
    assert d.steps[-1].heldout.rms < 1.2 * d.noise_floor
    reading = next(m for m in d.mechanisms if m["effect"] == "backlash")
    assert reading["mechanism_keys"] == ["lost_motion_compensation"]
    assert "ahead of their motion" in reading["mechanism"] and reading["physical"] and not reading["textbook"]
    assert d.primary_family == "direction"


def test_compliance_and_gear_errors_hidden_together_stay_inside_physics():
    """A UR10 whose joints give under gravity (realistic stiffness) and carry small periodic
    gear errors: every reported parameter inside its range, compliance found, its large
    terms near the truth."""
    robot = load_robot("ur10")
    rng = np.random.default_rng(8)
    n = 300
    q = random_joint_values(robot, n, rng)
    compliance = np.array([2e-5, 3e-5, 5e-5, 1e-4, 1e-4, 1e-4])
    tau = _gravity(robot, q)
    amplitude = np.radians(0.01) * rng.standard_normal((6, 2))
    real = q + compliance * tau + amplitude[:, 0] * np.sin(q) + amplitude[:, 1] * np.cos(q)
    position = _positions(robot, real) + 2e-5 * rng.standard_normal((n, 3))
    d = GapDiagnosis(robot=robot, stability_replays=10).fit(_observations(q, position)).result_
    for e, table in d.parameter_table.items():
        for name, value in table["values"].items():
            low, high = table["range"][name]
            assert low <= value <= high, name
            assert table["interval"][name][0] <= value <= table["interval"][name][1]
    assert "compliance" in d.selected_effects
    fitted = d.parameter_table["compliance"]["values"]
    for j, joint in enumerate(robot.joint_names[1:3], start=1):  # shoulder and elbow carry most of the load
        assert fitted[f"compliance.{joint}"] == pytest.approx(compliance[j], rel=0.3)
    assert set(d.selection["frequency"]) >= {"compliance"}
    assert d.selection["frequency"]["compliance"] >= 0.9


# ---------------------------------------------------------------------------------------
# Uncertainty
# ---------------------------------------------------------------------------------------
def test_standard_errors_match_a_monte_carlo_over_noise_draws():
    """Standard errors from the Jacobian and the residual against the spread of the fitted
    values over 200 noise draws on the same poses: within 20 %."""
    robot = load_robot()
    rng = np.random.default_rng(21)
    n = 120
    q = random_joint_values(robot, n, rng)
    offsets = np.radians([0.05, -0.03, 0.04, 0.0, 0.06, 0.02])
    offsets[3] = 3e-4  # prismatic joint [m]
    exact = _positions(robot, q + offsets)
    fit = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(
        _observations(q, exact))
    engine = fit.engine_
    model = ["frames", "joint_offsets"]
    noise = 5e-5
    estimates, errors = [], []
    for _ in range(200):
        parts = [dataclasses.replace(p, target=p.target + noise * rng.standard_normal(p.target.shape))
                 for p in engine.parts]
        result = FitEngine(parts, engine.bases, [], rank_tol=engine.rank_tol, min_motion=engine.min_motion) \
            .evaluate(model)
        estimates.append(result["phi"] * result["scale"])
        errors.append(result["phi_std"] * result["scale"])
    spread = np.std(estimates, axis=0, ddof=1)
    said = np.mean(errors, axis=0)
    ratio = said / spread
    assert np.all(np.abs(ratio - 1.0) < 0.2), ratio



def test_standard_errors_count_the_fitted_parameters_as_degrees_of_freedom():
    """On 10 poses (30 coordinates, 15 parameters) the residual variance is the training sum of
    squares over n - k, not n: the standard errors said against the spread of the estimates over
    300 noise draws (within 15 %: dividing by n would say 0.76 of it)."""
    robot = load_robot()
    rng = np.random.default_rng(5)
    n = 12
    q = random_joint_values(robot, n, rng)
    offsets = np.radians([0.05, -0.03, 0.04, 0.0, 0.06, 0.02])
    offsets[3] = 3e-4  # prismatic joint [m]
    exact = _positions(robot, q + offsets)
    fit = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(
        _observations(q, exact))
    engine = fit.engine_
    model = ["frames", "joint_offsets"]
    noise = 5e-5
    estimates, errors = [], []
    for _ in range(300):
        parts = [dataclasses.replace(p, target=p.target + noise * rng.standard_normal(p.target.shape))
                 for p in engine.parts]
        result = FitEngine(parts, engine.bases, [], rank_tol=engine.rank_tol, min_motion=engine.min_motion) \
            .evaluate(model)
        estimates.append(result["phi"] * result["scale"])
        errors.append(result["phi_std"] * result["scale"])
    assert 3 * n - result["n_parameters"] <= 24  # few degrees of freedom left: n and n - k differ
    ratio = np.mean(errors, axis=0) / np.std(estimates, axis=0, ddof=1)
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio
    # each parameter's 95 % interval: value +- the two-sided normal quantile (scipy's) x its
    # standard error, cut to the fit range
    from scipy.stats import norm

    for table in fit.result_.parameter_table.values():
        for name, value in table["values"].items():
            half = norm.ppf(0.975) * table["std"][name]
            low, high = table["fit_range"][name]
            np.testing.assert_allclose(table["interval"][name], [max(value - half, low), min(value + half, high)],
                                       rtol=1e-12, atol=0)


THREE_REFLECTORS = """<?xml version="1.0"?>
<robot name="reflector_arm">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.1"/><mass value="8"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.3 0 0"/><mass value="6"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0.2 0 0"/><mass value="4"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="smr_1"/><link name="smr_2"/><link name="smr_3"/>
  <joint name="a" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="b" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="c" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.6 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="f1" type="fixed"><parent link="l3"/><child link="smr_1"/><origin xyz="0.45 0.05 0"/></joint>
  <joint name="f2" type="fixed"><parent link="l3"/><child link="smr_2"/><origin xyz="0.45 -0.05 0.03"/></joint>
  <joint name="f3" type="fixed"><parent link="l3"/><child link="smr_3"/><origin xyz="0.40 0.0 0.08"/></joint>
</robot>
"""


def test_noise_from_three_reflectors_on_one_tool():
    """Three reflectors on one tool, 0.005 mm of tracker noise, a robot with joint offsets and a
    periodic error nothing in the fit expresses: the noise comes from the reflectors'
    distances, within 30 % of the truth, and says so."""
    frames = ["smr_1", "smr_2", "smr_3"]
    robots = [robot_from_urdf_text(THREE_REFLECTORS, f, name="reflector_arm") for f in frames]
    rng = np.random.default_rng(2)
    n = 400
    q = random_joint_values(robots[0], n, rng)
    real = q + np.radians([0.03, -0.02, 0.04]) + np.radians(0.01) * np.sin(7 * q)
    noise = 5e-6
    rotation = pin.rpy.rpyToMatrix(0.1, -0.2, 0.7)
    measurements = []
    for robot, frame in zip(robots, frames):
        position = _positions(robot, real, frame) @ rotation.T + [1.2, -0.4, 0.3]
        measurements.append((robot, _observations(q, position + noise * rng.standard_normal((n, 3)))))
    d = GapDiagnosis(robot=robots[0], effects=["joint_offsets", "geometry"], stability_replays=5).fit(
        measurements).result_
    assert d.noise.source == "rigid frames"
    assert d.noise.independent
    assert d.tracker_noise == pytest.approx(noise, rel=0.3)
    assert "rigid body" in d.noise.detail


def test_scatter_is_named_only_when_the_joints_cannot_predict_it():
    """A leftover 3 x the instrument's noise: a smooth function of two joints (structure a
    joint-space predictor takes out of sample) is not called scatter; independent draws of
    the same size are."""
    from tcr_accuracy.frames.noise import NoiseEstimate
    from tcr_accuracy.diagnosis.structure import StructureDetector, name_scatter, scatter_test

    rng = np.random.default_rng(4)
    n, instrument = 400, 1e-5
    q = rng.uniform(-2, 2, (n, 4))
    noise = NoiseEstimate(instrument, "given", True, "")
    detector = StructureDetector(q, np.random.default_rng(0))
    smooth = 2.8e-5 * np.stack([np.sin(1.5 * q[:, 0]) * np.cos(q[:, 1]), np.cos(2 * q[:, 0]), np.sin(q[:, 1])], 1)
    cases = {"structure": smooth + instrument * rng.standard_normal((n, 3)),
             "scatter": 3 * instrument * rng.standard_normal((n, 3))}
    named = {}
    for label, residual in cases.items():
        scatter = scatter_test(residual, 0, instrument)
        assert scatter["detected"]
        notes = []
        name_scatter(scatter, {"verdict": "no"}, [], noise, notes, detector, residual)
        named[label] = scatter.get("named")
    assert named["structure"] is None
    assert named["scatter"] == "random scatter"


def test_weighted_fit_reports_the_spread_of_its_estimates_and_beats_the_unweighted_one():
    """An instrument whose noise grows steeply with distance (5 um + 100 um/m across the beam,
    10 um + 1 um/m along it; the tracker 1.5 m from the base): each point's noise drawn from its
    covariance written out here. The instrument-weighted fit's standard errors are within 20 % of
    the spread of its estimates over 150 noise draws, and that spread is below the unweighted
    fit's on the same draws."""
    from tcr_accuracy.frames.instrument import Instrument

    robot = load_robot("ur5")
    rng = np.random.default_rng(4)
    n = 150
    q = random_joint_values(robot, n, rng)
    offsets = np.radians([0.05, -0.03, 0.04, 0.02, -0.06, 0.0])
    tracker = np.array([-1.5, 0.3, 0.4])  # the instrument's place in the base frame [m]
    exact = _positions(robot, q + offsets) - tracker  # in the instrument's frame (axes as the base's)
    instrument = Instrument("steep", (10e-6, 1e-6), (5e-6, 100e-6))

    def covariance(points):  # the instrument's model, written out: s = MPE / 2 along and across the beam
        d = np.linalg.norm(points, axis=1)
        u = points / d[:, None]
        along = np.einsum("ni,nj->nij", u, u)
        radial, transverse = (10e-6 + 1e-6 * d) / 2, (5e-6 + 100e-6 * d) / 2
        return radial[:, None, None] ** 2 * along + transverse[:, None, None] ** 2 * (np.eye(3) - along)

    chol = np.linalg.cholesky(covariance(exact))
    fit = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2, instrument=instrument,
                       fold_repeats=1).fit(_observations(q, exact + np.einsum("nij,nj->ni", chol,
                                                                              rng.standard_normal((n, 3)))))
    engine = fit.engine_
    model = ["frames", "joint_offsets"]
    weighted, unweighted, said = [], [], []
    for _ in range(150):
        noise = np.einsum("nij,nj->ni", chol, rng.standard_normal((n, 3)))  # base axes = instrument axes
        for whitened, out in ((True, weighted), (False, unweighted)):
            parts = [dataclasses.replace(p, target=_registered_target(p, exact + noise, fit.result_),
                                         whitening=p.whitening if whitened else None) for p in engine.parts]
            result = FitEngine(parts, engine.bases, [], rank_tol=engine.rank_tol, min_motion=engine.min_motion) \
                .evaluate(model)
            out.append(result["phi"] * result["scale"])
            if whitened:
                said.append(result["phi_std"] * result["scale"])
    joints = slice(-5, None)  # the joint offsets (the last columns); frames' spread is not the question
    spread_w = np.std(weighted, axis=0, ddof=1)[joints]
    spread_u = np.std(unweighted, axis=0, ddof=1)[joints]
    ratio = np.mean(said, axis=0)[joints] / spread_w
    assert np.all(np.abs(ratio - 1.0) < 0.2), ratio
    assert np.all(spread_w < spread_u), (spread_w, spread_u)


def _registered_target(part, measured_tracker, diagnosis):
    """Measured points (N, 3) in the instrument's frame taken to the base frame as the diagnosis
    registered them (its first session's closed-form frame)."""
    rotation, translation = diagnosis.registration
    return (measured_tracker - translation) @ rotation


def test_an_effect_enters_only_when_it_cuts_the_held_out_error_by_the_relative_gain_asked():
    """Joint offsets that leave only the noise: they cut the held-out RMS after frames alone by
    about 90 % (0.40 -> 0.035 mm), with an overwhelming z. Asked for a 50 % cut they enter; asked
    for 95 % they cannot (the relative gate: rms < (1 - gain) x the previous rms)."""
    robot = load_robot()
    rng = np.random.default_rng(8)
    n = 60
    q = random_joint_values(robot, n, rng)
    offsets = np.radians([0.05, -0.03, 0.04, 0.0, 0.06, 0.02])
    offsets[3] = 3e-4  # prismatic joint [m]
    measured = _positions(robot, q + offsets) + 2e-5 * rng.standard_normal((n, 3))
    chosen = {}
    for gain in (0.5, 0.95):
        d = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=3, stability_replays=2,
                         min_relative_gain=gain).fit(_observations(q, measured)).result_
        chosen[gain] = d.selected_effects
        if gain == 0.5:
            frames, offsets_step = d.steps[0].heldout.rms, d.steps[-1].heldout.rms
            assert 0.05 * frames < offsets_step < 0.5 * frames  # the cut lies between the two gates
    assert "joint_offsets" in chosen[0.5]
    assert "joint_offsets" not in chosen[0.95]


def test_penalised_fit_lands_on_the_closed_form_ridge_optimum():
    """The Levenberg-Marquardt loop with a smoothness penalty on a linear residual r = A phi - y:
    its optimum is the ridge solution (A^T A + lambda W) phi = A^T y, written out here. The data are
    small (a tenth of a millimetre in scaled units) so that a penalty term mis-computed at the
    trial point (not lambda * sum(w phi^2)) turns the accepted steps away from it."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.fit_columns import Columns

    rng = np.random.default_rng(11)
    a = rng.standard_normal((30, 3))
    y = a @ np.array([0.02, 0.05, 0.03]) + 1e-3 * rng.standard_normal(30)
    w, lam = np.array([1.0, 2.0, 0.5]), 3.0

    class LinearJacobian:  # the one product the loop asks of a Jacobian: J^T r
        shape = (30, 1, 3)

        @staticmethod
        def transposed_times(r, rows):
            return a.T @ r.ravel()

    def residual(cols, phi, rows):
        return [(a @ phi - y)[:, None]]

    engine = SimpleNamespace(n_fits=0, n_rows=30, MAX_EVALUATIONS=FitEngine.MAX_EVALUATIONS,
                             COST_TOLERANCE=FitEngine.COST_TOLERANCE, predict_residual=residual,
                             _weighted=lambda res, rows: res)
    cols = Columns(names=["p0", "p1", "p2"], scale=np.ones(3), per_part=[], lower=np.full(3, -1e3),
                   upper=np.full(3, 1e3), penalty=w)
    start = np.zeros(3)
    phi, _ = FitEngine._minimise(engine, cols, [LinearJacobian()], None, a.T @ a, start,
                                 residual(cols, start, None), penalty=lam)
    ridge = np.linalg.solve(a.T @ a + lam * np.diag(w), a.T @ y)
    np.testing.assert_allclose(phi, ridge, rtol=1e-6, atol=1e-12)
    assert np.all(np.abs(ridge) > 1e-3)  # the penalised optimum is not the start
