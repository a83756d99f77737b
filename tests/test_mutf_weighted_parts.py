"""The fit engine on two measured frames, one of them weighted by a per-point whitening (the instrument's
Sigma^-1/2), with two fold assignments (``diagnosis/fitting.py``, ``gram.py``, ``fit_columns.py``): every
figure against weighted least squares written out here on the engine's exact residual. The weights,
the stacking of the two frames and the fold arithmetic are numpy's in this file: scipy's ``least_squares``
for the optimum, a central finite-difference Jacobian for the standard errors sqrt(diag(s^2 (J_w^T
J_w)^-1)) with s^2 the weighted cost over 6N - k, each fold's one Gauss-Newton step on its weighted
training rows of both frames, its held-out rows moved by the (unweighted) Jacobian times the step, the
per-row squares averaged over the two assignments. The data: joint offsets hidden in a Pinocchio model
(tests/mutd_truth.py); the second frame's targets are the first's moved by a pattern of 30 um, so the two
frames disagree and their weighting matters. Each test names a planted change it was seen to catch
(issue 36)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import pinocchio as pin
from mutd_truth import OFFSETS
from scipy.optimize import least_squares
from test_mutfit_fitting import _jacobian  # the central finite differences of the one-frame tests

from tcr_accuracy.diagnosis.bases import UnionBasis
from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fitting import FitEngine
from tcr_accuracy.io.measurements import MeasurementSet
from tcr_accuracy.model.robot import load_robot

MODEL = ["frames", "joint_offsets"]
N = 16
WEIGHT = 0.3  # [m/rad] of the orientation rows


def _measurements(seed: int):
    """(robot, MeasurementSet) of N poses of the tool-changer whose joints are off by mutd_truth's OFFSETS: the
    tool's position (30 um noise per axis) and orientation (turned by 50 urad per axis) from Pinocchio."""
    from scipy.spatial.transform import Rotation

    robot = load_robot()
    rng = np.random.default_rng(seed)
    q = rng.uniform(*robot.joint_bounds(), size=(N, robot.n_joints))
    model, data = robot.model, robot.model.createData()
    position, rotation = np.empty((N, 3)), np.empty((N, 3, 3))
    for i, row in enumerate(q + OFFSETS):
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(row))
        position[i] = data.oMf[robot.tool_frame_id].translation
        rotation[i] = data.oMf[robot.tool_frame_id].rotation
    position += 3e-5 * rng.standard_normal(position.shape)
    rotation = Rotation.from_rotvec(5e-5 * rng.standard_normal((N, 3))).as_matrix() @ rotation
    xyzw = Rotation.from_matrix(rotation).as_quat()
    return robot, MeasurementSet(joint_names=robot.joint_names, q=q, position=position,
                                 quaternion=np.column_stack([xyzw[:, 3], xyzw[:, :3]]))


@pytest.fixture(scope="module")
def setup():
    """(engine, whitening (N, 3, 3) of the first frame's positions, the fold assignments): both frames
    measure orientation (weighted 0.3 m/rad), the second frame's positions unweighted."""
    robot, measured = _measurements(4012)
    fitted = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2,
                          orientation_weight=WEIGHT).fit(measured).engine_
    rng = np.random.default_rng(4013)
    # each point's whitening: a symmetric positive definite matrix around one, far from a multiple of it
    a = rng.standard_normal((N, 3, 3))
    whitening = np.eye(3) + 0.35 * (a + np.swapaxes(a, 1, 2))
    whitening = np.einsum("nij,nkj->nik", whitening, whitening)
    first = dataclasses.replace(fitted.parts[0], whitening=whitening)
    assert first.rows_per_pose == 6 and first.orientation_weight == WEIGHT
    second = dataclasses.replace(fitted.parts[0], whitening=None, label="second",
                                 target=fitted.parts[0].target + 3e-5 * np.sin(np.arange(3 * N)).reshape(N, 3))
    bases = {e: UnionBasis([b.per_part[0], b.per_part[0]]) for e, b in fitted.bases.items()}
    repeats = []
    for k in (3, 2):
        tests = np.array_split(rng.permutation(N), k)
        repeats.append([(np.setdiff1d(np.arange(N), t), np.sort(t)) for t in tests])
    engine = FitEngine([first, second], bases, repeats, rank_tol=fitted.rank_tol, min_motion=fitted.min_motion)
    return engine, whitening, repeats


def _residual(engine, cols, whitening, weighted=True):
    """The stacked residual of both frames (2 x N x 6: positions, then rotation vectors times WEIGHT) at
    phi, the first frame's positions whitened here."""
    def flat(phi):
        first, second = engine.predict_residual(cols, phi, np.arange(N))
        if weighted:
            first = first.copy()
            first[:, :3] = np.einsum("nij,nj->ni", whitening, first[:, :3])
        return np.concatenate([first.ravel(), second.ravel()])
    return flat


def test_a_weighted_two_frame_exact_fit_is_weighted_least_squares_written_out(setup):
    """The optimum (scipy's, each parameter within 1 % of its standard error), the weighted cost, the
    standard errors with s^2 = cost / (12N - k), the observation count 2 x 6N, each frame's training
    positions in metres (unweighted) and orientations in radians (both frames one after the other). Seen
    failing on ``_weighted``'s ``res[:, :3] = np.einsum(...)`` turned to rows 3: (``[:, 3:]``), on
    ``_rotations``' ``r[:, 3:] / part.orientation_weight`` turned to ``r[:, 4:]`` and on
    ``n_observations``' ``self.n_rows * p.rows_per_pose`` turned to ``+``."""
    engine, whitening, _ = setup
    result = engine.evaluate(MODEL, exact=True)
    cols = engine.columns(MODEL)
    fun = _residual(engine, cols, whitening)
    phi = result["phi"]
    k = phi.size
    assert result["n_observations"] == 12 * N and result["n_parameters"] == k == len(cols.names)
    cost = float(fun(phi) @ fun(phi))
    assert result["cost"] == pytest.approx(cost, rel=1e-9)
    jac = _jacobian(fun, phi)
    std = np.sqrt(np.diag(cost / (12 * N - k) * np.linalg.inv(jac.T @ jac)))
    np.testing.assert_allclose(result["phi_std"], std, rtol=3e-3)
    reference = least_squares(fun, phi + 0.01, jac=lambda p: _jacobian(fun, p), xtol=1e-15, ftol=1e-15,
                              gtol=1e-15, method="lm").x
    assert np.all(np.abs(phi - reference) < 1e-2 * std)  # the fit stops at a cost cut of 1e-7 of the cost
    raw = _residual(engine, cols, whitening, weighted=False)(phi).reshape(2, N, 6)
    np.testing.assert_allclose(result["train_residual"], raw[:, :, :3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(result["train_orientation"], raw[:, :, 3:].reshape(2 * N, 3) / WEIGHT, rtol=0,
                               atol=1e-12)
    norms = np.linalg.norm(raw[:, :, :3].reshape(-1, 3), axis=1)
    assert result["train_stats"].rms == pytest.approx(np.sqrt(np.mean(norms**2)), rel=1e-9)


def test_each_folds_step_and_held_out_rows_are_the_weighted_gauss_newton_step_of_both_frames(setup):
    """Every fold of both assignments: the full optimum moved by -(J_t^T J_t)^-1 J_t^T r_t on the weighted
    training rows of both frames (to 2 % of a standard error and 0.2 % of the step); the held-out rows of each assignment the
    unweighted residual plus the unweighted Jacobian times the step (positions in m, the first assignment's
    orientations in rad); the per-row squared position errors (both frames added) averaged over the two
    assignments. Seen failing on the held-out gradient's rows (``_weighted([res[test] ...], test)``)
    whitened as all rows (``test`` turned to ``None``) and on the squares' mean over the assignments turned
    to their sum; on ``transposed_times``' whitened ``residual[:, :3]`` turned to ``residual[:, :4]``."""
    engine, whitening, repeats = setup
    result = engine.evaluate(MODEL, exact=True)
    cols = engine.columns(MODEL)
    phi = result["phi"]
    weighted = _residual(engine, cols, whitening)
    raw = _residual(engine, cols, whitening, weighted=False)
    jac_w = _jacobian(weighted, phi).reshape(2, N, 6, -1)
    jac_u = _jacobian(raw, phi).reshape(2, N, 6, -1)
    r_w, r_u = weighted(phi).reshape(2, N, 6), raw(phi).reshape(2, N, 6)
    squares = []
    for a, (folds, steps, held_out) in enumerate(zip(repeats, result["fold_steps"], result["heldout_repeats"])):
        expected = np.empty((2, N, 6))
        for (train, test), fold_phi in zip(folds, steps):
            j = jac_w[:, train].reshape(-1, phi.size)
            step = -np.linalg.solve(j.T @ j, j.T @ r_w[:, train].ravel())
            # the engine's Jacobian is the effects' linearisation at zero, this one is taken at phi
            assert np.all(np.abs(fold_phi - phi - step) < 2e-2 * result["phi_std"] + 2e-3 * np.abs(step))
            expected[:, test] = r_u[:, test] + jac_u[:, test] @ step
        np.testing.assert_allclose(held_out, expected[:, :, :3], rtol=0, atol=3e-3 * np.abs(expected[:, :, :3]).max())
        if a == 0:
            rotations = expected[:, :, 3:].reshape(2 * N, 3) / WEIGHT
            np.testing.assert_allclose(result["heldout_orientation"], rotations, rtol=0,
                                       atol=3e-3 * np.abs(rotations).max())
        squares.append(np.sum(expected[:, :, :3] ** 2, axis=(0, 2)))
    np.testing.assert_allclose(result["heldout_squares"], np.mean(squares, axis=0), rtol=3e-3)
    np.testing.assert_allclose(result["heldout_residual"], result["heldout_repeats"][0], rtol=0, atol=0)


def test_the_linear_fit_of_weighted_frames_is_the_exact_ones_and_its_sums_are_weighted(setup):
    """The linear model's fit (from the Gram blocks, whitened a chunk of rows at a time) lands on the exact
    fit (5 % of each standard error); its cost is the weighted sum of squares of its training rows
    (positions through the whitening, orientations times 0.3 m/rad), and each fold's held-out sum of
    squares the weighted sum over its held-out rows of both frames, in both assignments. Seen failing on
    ``FoldGrams._block``'s whitening test ``part.whitening is not None`` turned to ``is None``, on
    ``residual_products``' whitened ``r[:, :3]`` turned to ``r[:, :2]`` and on ``_whitened``'s
    ``out[:, :3]`` turned to ``out[:, :2]``."""
    engine, whitening, repeats = setup
    exact = engine.evaluate(MODEL, exact=True)
    linear = engine.evaluate(MODEL)
    assert np.all(np.abs(linear["phi"] - exact["phi"]) < 0.05 * exact["phi_std"])

    def weighted_squares(positions, rotations):  # each row's weighted squares, both frames added
        first = np.einsum("nij,nj->ni", whitening, positions[0])
        turned = (WEIGHT * rotations) ** 2
        return np.sum(first**2, axis=1) + np.sum(positions[1] ** 2, axis=1) + np.sum(turned[:N] + turned[N:], axis=1)

    train = weighted_squares(linear["train_residual"], linear["train_orientation"])
    assert linear["cost"] == pytest.approx(np.sum(train), rel=1e-6)
    row_ssq = weighted_squares(linear["heldout_residual"], linear["heldout_orientation"])
    for (_, test), value in zip(repeats[0], linear["heldout_ssq"][0]):
        assert value == pytest.approx(np.sum(row_ssq[test]), rel=1e-6)


def test_two_unweighted_frames_keep_the_columns_identifiability_keeps_on_their_dense_columns(setup):
    """Both frames unweighted (the engine then judges identifiability from a factor of its Gram matrix): at
    motion thresholds from 1 um to 1 mm RMS, the columns kept are those ``identifiability`` keeps on the dense
    stacked columns of the two frames (2N poses) written out here, and the thresholds do drop columns in that
    range. Seen failing on the poses counted ``self.n_rows * len(self.parts)`` turned to ``+`` and on
    ``gram_factor``'s ``f *= np.where(norms > 0, norms, 0.0)`` with the norms squared."""
    from tcr_accuracy.diagnosis.identifiability import SensitivityColumns, identifiability

    engine, _, repeats = setup
    parts = [dataclasses.replace(p, whitening=None) for p in engine.parts]
    dense = {e: SensitivityColumns(list(b.names), np.asarray(b.g), b.scales) for e, b in engine.bases.items()}
    assert all(c.g.shape[0] == 2 * N for c in dense.values())
    counts = []
    for motion in np.logspace(-6, -3, 7):
        plain = FitEngine(parts, engine.bases, repeats, rank_tol=engine.rank_tol, min_motion=motion)
        keep = plain.kept(MODEL)
        expected, _ = identifiability(dense, MODEL, engine.rank_tol, motion, report=False)
        assert all(np.array_equal(keep[e], expected[e]) for e in MODEL), motion
        counts.append(sum(k.size for k in keep.values()))
    assert counts[0] > counts[-1]
