"""The per-pose error maps of lateral compliance, drift and thermal growth built from their nonzero
entries (``sparse_parameter_jacobian``, :meth:`ErrorMap.of_entries`) without the dense (N, p_em, k)
Jacobian: compared with the dense Jacobian written out here from each effect's formula, and with the
map :meth:`ErrorMap.of` builds from that dense array (the same floats, every stored part)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tcr_accuracy.diagnosis.error_map import ErrorMap
from tcr_accuracy.effects import make_effect
from tcr_accuracy.model.context import MeasurementContext
from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.robot import load_robot

N = 300


@pytest.fixture(scope="module")
def ur10():
    return load_robot("ur10")


def _poses(robot, seed=0):
    rng = np.random.default_rng(seed)
    low, high = robot.lower_limits, robot.upper_limits
    return rng.uniform(np.maximum(low, -np.pi), np.minimum(high, np.pi), size=(N, robot.n_joints))


def _context(robot, temperature=None, payload=None):
    context = MeasurementContext.defaults(N, robot.n_joints)
    changes = {"order": np.arange(N)}
    if temperature is not None:
        changes["temperature_c"] = np.asarray(temperature, dtype=float)
    if payload is not None:
        changes["payload_kg"] = np.asarray(payload, dtype=float)
    return dataclasses.replace(context, **changes)


def _dense_lateral(effect, q, context):
    """d(x)/d(params): each joint's placement tilted by (m . e) e about the axis e across it (revolute)."""
    em = ErrorModel(effect.robot)
    moment = effect.moments(q, context)
    dx = np.zeros((q.shape[0], em.size, effect.n_params))
    for k, (j, _, e) in enumerate(effect._axes()):
        start = em.index(f"{effect.robot.joint_names[j]}.dx")
        dx[:, start + 3:start + 6, k] = (moment[:, j] @ e)[:, None] * e
    return dx


def _dense_drift(effect, q, context):
    """d(x)/d(params): the base translation along each axis a moved by the two shapes of the campaign."""
    em = ErrorModel(effect.robot)
    nj = effect.robot.n_joints
    shape = effect.shapes(effect.progress(context, q.shape[0]), q.shape[0])
    dx = np.zeros((q.shape[0], em.size, effect.n_params))
    for a in range(3):
        dx[:, em.base_slice.start + a, 2 * nj + 2 * a] = shape[:, 0]
        dx[:, em.base_slice.start + a, 2 * nj + 2 * a + 1] = shape[:, 1]
    return dx


def _dense_thermal(effect, context):
    """d(x)/d(params): growth directions per kelvin times each row's temperature change."""
    em = ErrorModel(effect.robot)
    directions = np.zeros((em.size, effect.n_params))
    directions[:, :len(effect._alphas())] = effect.growth_directions()
    for a in range(3):
        directions[em.base_slice.start + a, len(effect._alphas()) + a] = 1.0
    d_t = context.temperature_c - float(effect.reference_temperature_c)
    return d_t[:, None, None] * directions[None]


def _assert_same_map(a: ErrorMap, b: ErrorMap) -> None:
    assert np.array_equal(a.fixed, b.fixed)
    assert (a.per_pose is None) == (b.per_pose is None)
    if a.per_pose is not None:
        assert np.array_equal(a.per_pose, b.per_pose)
    assert np.array_equal(a.pose_columns, b.pose_columns)
    assert np.array_equal(a.pose_entries, b.pose_entries)
    assert (a.drive is None) == (b.drive is None)
    if a.drive is not None:
        assert np.array_equal(np.asarray(a.drive), np.asarray(b.drive))
        assert np.array_equal(a.drive_columns, b.drive_columns)
        assert np.array_equal(a.drive_joint, b.drive_joint)


def _check(effect, q, context, dense):
    em = ErrorModel(effect.robot)
    k = effect.n_params
    jac = effect.parameter_jacobian(np.zeros(k), q, context)
    assert np.array_equal(jac.x, dense)
    sparse, entries = effect.sparse_parameter_jacobian(np.zeros(k), q, context)
    assert entries.values.shape[1] < em.size * k  # fewer than the dense array's entries per pose
    built = ErrorMap.of_entries(N, em.size, em.drive_slice, sparse.x, sparse.dq, entries, k)
    _assert_same_map(built, ErrorMap.of(N, em.size, em.drive_slice, dense, jac.dq, k))
    theta = np.linspace(-1.0, 2.0, k) * effect.parameter_scales()
    expected = dense @ theta
    if jac.dq is not None:
        expected[:, em.drive_slice] += jac.dq @ theta
    assert np.allclose(built.errors(theta), expected, rtol=1e-13, atol=1e-300)
    return entries


def test_lateral_compliance_entries_one_per_parameter(ur10):
    q = _poses(ur10)
    effect = make_effect("lateral_compliance", ur10)
    context = _context(ur10, payload=np.linspace(0.0, 10.0, N))
    entries = _check(effect, q, context, _dense_lateral(effect, q, context))
    # a six-joint arm with coordinate axes across each joint: one rotation entry per parameter
    assert entries.values.shape == (N, effect.n_params)


def test_drift_entries(ur10):
    q = _poses(ur10, 1)
    effect = make_effect("drift", ur10, time_axis="order", start=0.0, span=float(N - 1))
    context = _context(ur10)
    entries = _check(effect, q, context, _dense_drift(effect, q, context))
    assert entries.values.shape == (N, 6)  # three base translations, two shapes each


@pytest.mark.parametrize("temperature", ["varying", "constant"])
def test_thermal_entries(ur10, temperature):
    q = _poses(ur10, 2)
    effect = make_effect("thermal", ur10)
    t = np.linspace(15.0, 30.0, N) if temperature == "varying" else np.full(N, 27.0)
    context = _context(ur10, temperature=t)
    _check(effect, q, context, _dense_thermal(effect, context))
    em = ErrorModel(ur10)
    sparse, entries = effect.sparse_parameter_jacobian(np.zeros(effect.n_params), q, context)
    built = ErrorMap.of_entries(N, em.size, em.drive_slice, sparse.x, sparse.dq, entries, effect.n_params)
    # a temperature that does not change is the same error for every pose: the fixed part, nothing per pose
    assert (built.per_pose is None) == (temperature == "constant")
