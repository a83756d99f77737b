"""Effects' TCP errors written out on Pinocchio directly (``effects/drift.py``, ``effects/cyclic.py``): the
joint angles each effect turns, put into Pinocchio's forward kinematics here, and a base translation added,
against what the effect classes predict; their shapes, options and penalty weights by hand. Each test
names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.effects import predict_positions
from tcr_accuracy.effects.cyclic import CyclicError
from tcr_accuracy.effects.drift import Drift
from tcr_accuracy.model.context import MeasurementContext

from conftest import pinocchio_kinematics, random_joint_values


def _tcp(robot, q):
    """(N, 3) TCP positions by Pinocchio's own forward kinematics, row by row."""
    return np.array([pinocchio_kinematics(robot, row)[1].translation for row in q])


def _warm_shapes(u, tau):
    """(linear, warm-up) at progress u, each centred on its mean over [0, 1] (the warm-up's mean by its
    integral, written out: 1 - tau (1 - e^(-1/tau)), over 1 - e^(-1/tau))."""
    settle = 1 - math.exp(-1 / tau)
    warm = (1 - np.exp(-u / tau)) / settle
    return u - 0.5, warm - (1 - tau * settle) / settle


def test_drift_moves_every_joint_and_the_base_along_its_two_shapes_on_pinocchio(ur5):
    """Rows measured at times 100 .. 700 s (progress u = (t - 100) / 600, clipped below 0): each joint turned by
    a_lin (u - 1/2) + a_warm (w(u) - mean w), the base translated by the same shapes of its own parameters;
    the TCP by Pinocchio at the turned joints plus the base's translation. Rows without a time: the
    campaign's average (no drift). The policy reads the start and span off the times, else the order.
    Seen failing on ``settle = 1.0 - math.exp(-1.0 / tau)`` turned to ``2.0 - ...``, the warm-up mean's
    ``tau * settle`` turned to ``tau / settle``, and the base entries' ``2 * nj + 2 * a + i`` turned to
    ``2 * nj + 2 * a - i``."""
    rng = np.random.default_rng(3)
    n = 8
    q = random_joint_values(ur5, n, rng)
    times = np.linspace(100.0, 700.0, n)
    times[1] = 50.0  # before the start: u clipped to 0
    context = MeasurementContext.defaults(n, 6)
    context = MeasurementContext(context.payload_kg, context.temperature_c, context.direction, time_s=times,
                                 order=np.arange(n, dtype=float))
    policy = Drift(ur5).fit_policy.options_for_data(ur5, q, context)
    assert policy == {"time_axis": "time_s", "start": 50.0, "span": 650.0}
    order_only = MeasurementContext(context.payload_kg, context.temperature_c, context.direction,
                                    order=np.arange(3.0, 3.0 + n))
    assert Drift(ur5).fit_policy.options_for_data(ur5, q, order_only) == {"time_axis": "order", "start": 3.0,
                                                                          "span": float(n - 1)}
    effect = Drift(ur5, time_axis="time_s", start=100.0, span=600.0, time_constant=0.3)
    params = rng.normal(size=effect.n_params) * np.r_[np.full(12, 2e-3), np.full(6, 1e-3)]
    u = np.clip((times - 100.0) / 600.0, 0.0, None)
    linear, warm = _warm_shapes(u, 0.3)
    joint = params[:12].reshape(6, 2)
    base = params[12:].reshape(3, 2)
    turned = q + np.outer(linear, joint[:, 0]) + np.outer(warm, joint[:, 1])
    expected = _tcp(ur5, turned) + np.outer(linear, base[:, 0]) + np.outer(warm, base[:, 1])
    np.testing.assert_allclose(predict_positions(ur5, [effect], [params], q, context), expected, atol=1e-12)
    no_time = MeasurementContext.defaults(n, 6)
    np.testing.assert_allclose(predict_positions(ur5, [effect], [params], q, no_time), _tcp(ur5, q), atol=1e-12)
    assert effect.parameter_names()[:2] == [f"drift.{ur5.joint_names[0]}.linear", f"drift.{ur5.joint_names[0]}.warmup"]
    assert effect.parameter_names()[12:14] == ["drift.base.dx.linear", "drift.base.dx.warmup"]


def test_drift_sizes_by_hand(ur5):
    """Typical sizes 0.01 deg per revolute joint's shape and 0.05 mm per base shape; physics 0.2 deg and
    0.5 mm; the fit's range 5 deg and 10 mm. Catches ``math.radians(0.01)`` turned to ``math.radians(1.01)``
    and ``np.full(6, 5e-4)`` turned to ``np.full(7, ...)``."""
    effect = Drift(ur5)
    np.testing.assert_allclose(effect.parameter_scales(), np.r_[np.full(12, math.radians(0.01)), np.full(6, 5e-5)],
                               rtol=1e-12)
    lower, upper = effect.physical_range()
    np.testing.assert_allclose(upper, np.r_[np.full(12, math.radians(0.2)), np.full(6, 5e-4)], rtol=1e-12)
    np.testing.assert_allclose(lower, -upper)
    wide_lower, wide_upper = effect.fit_range()
    np.testing.assert_allclose(wide_upper, np.r_[np.full(12, math.radians(5.0)), np.full(6, 0.01)], rtol=1e-12)
    np.testing.assert_allclose(wide_lower, -wide_upper)


def test_cyclic_error_turns_each_joint_by_its_fourier_series_on_pinocchio(ur5):
    """Orders 3 .. 7: dq_j = sum_n a_n sin(n q_j) + b_n cos(n q_j), the joints put into Pinocchio here; the
    roughness weights (n / 3)^4; the basis one joint's columns; the order the policy allows for N poses
    max(3, min(30, 2 + N // (4 x revolute joints))). Seen failing on ``FIRST_ORDER = 3`` turned to 4,
    ``(n / effect.FIRST_ORDER) ** 4`` turned to ``** 5`` and ``2 + len(q) // (4 * ...)`` turned to
    ``// (5 * ...)``."""
    rng = np.random.default_rng(5)
    q = random_joint_values(ur5, 6, rng)
    effect = CyclicError(ur5, max_order=7)
    orders = range(3, 8)
    first = ur5.joint_names[0]
    assert effect.parameter_names()[:4] == [f"cyclic.{first}.a3", f"cyclic.{first}.b3", f"cyclic.{first}.a4",
                                            f"cyclic.{first}.b4"]
    params = rng.normal(size=effect.n_params) * 1e-4
    coefficients = params.reshape(6, len(orders), 2)
    dq = np.zeros_like(q)
    for j in range(6):
        for i, k in enumerate(orders):
            dq[:, j] += coefficients[j, i, 0] * np.sin(k * q[:, j]) + coefficients[j, i, 1] * np.cos(k * q[:, j])
    np.testing.assert_allclose(predict_positions(ur5, [effect], [params], q, MeasurementContext.defaults(6, 6)),
                               _tcp(ur5, q + dq), atol=1e-12)
    np.testing.assert_allclose(effect.fit_policy.penalty_weights(effect),
                               np.repeat([(k / 3) ** 4 for k in orders], 2).tolist() * 6, rtol=1e-12)
    angles = np.linspace(-3, 3, 11)
    names, basis = effect.joint_basis(ur5.joint_names[2], angles)
    assert names == effect.parameter_names()[20:30]
    np.testing.assert_allclose(basis @ params[20:30], effect.joint_function(params, ur5.joint_names[2], angles),
                               rtol=1e-12)
    np.testing.assert_allclose(basis[:, 0], np.sin(3 * angles), rtol=1e-12)
    np.testing.assert_allclose(effect.parameter_scales(), np.full(60, 5e-5))
    for n_poses, order in ((10, 3), (48, 4), (200, 10), (5000, 30)):
        assert effect.fit_policy.options_for_data(ur5, np.zeros((n_poses, 6)), None) == {"max_order": order}


def test_lateral_compliance_tilts_each_joint_by_its_moment_across_the_axis_on_pinocchio(ur5):
    """Each UR5 joint tilted about the two axes across it (x, y for a z joint; z, x for a y joint) by k_c times
    the gravity moment it carries across the axis: the moment from Pinocchio's RNEA here (minus the joint
    force ``data.f[j]`` at rest, in the joint's moving frame, turned into the placement frame by exp3(a q_j)), the tilt applied on the right of the
    joint's placement as exp6((0, w)), and the TCP by Pinocchio's forward kinematics on that model. Seen
    failing on the Rodrigues rotation's ``m * c + np.cross(a, m) * s`` turned to ``m * c - ...`` (its
    ``(1.0 - c)`` term is along the axis, which no tilt reads)."""
    from tcr_accuracy.effects.lateral_compliance import LateralCompliance

    rng = np.random.default_rng(7)
    q = random_joint_values(ur5, 4, rng)
    effect = LateralCompliance(ur5)
    names = effect.parameter_names()
    assert names[:4] == [f"lateral_compliance.{ur5.joint_names[0]}.x", f"lateral_compliance.{ur5.joint_names[0]}.y",
                         f"lateral_compliance.{ur5.joint_names[1]}.z", f"lateral_compliance.{ur5.joint_names[1]}.x"]
    params = rng.uniform(0.5, 2.0, effect.n_params) * 2e-6
    model = ur5.model
    ids = [model.getJointId(name) for name in ur5.joint_names]
    expected = []
    for row in q:
        qp = pin.neutral(model)
        for jid, value in zip(ids, row):
            qp[model.joints[jid].idx_q] = value
        data = model.createData()
        pin.rnea(model, data, qp, np.zeros(model.nv), np.zeros(model.nv))
        tilted = model.copy()
        for j, jid in enumerate(ids):
            moment = -data.f[jid].angular
            placed = pin.exp3(ur5.joint_axis(j) * row[j]) @ moment  # the moving frame turned by q_j about a
            first, second = ur5.axis_perpendiculars(j)
            w = params[2 * j] * (placed @ first) * first + params[2 * j + 1] * (placed @ second) * second
            tilted.jointPlacements[jid] = model.jointPlacements[jid] * pin.exp6(pin.Motion(np.zeros(3), w))
        tilted_data = tilted.createData()
        pin.framesForwardKinematics(tilted, tilted_data, qp)
        expected.append(tilted_data.oMf[tilted.getFrameId(ur5.tool_frame)].translation.copy())
    got = predict_positions(ur5, [effect], [params], q, MeasurementContext.defaults(4, 6))
    np.testing.assert_allclose(got, np.array(expected), atol=1e-12)
    assert np.abs(got - _tcp(ur5, q)).max() > 1e-6  # the tilt moves the TCP by micrometres or more
