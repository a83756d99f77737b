"""``drift``: encoder zeros and the robot's base drifting during the campaign (warm-up, a moving base)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..units import REVOLUTE
from .base import EffectJacobian, LinearEffect, joint_unit, per_joint_kind
from .pose_entries import PoseEntries
from .fit_policy import FitPolicy


@dataclass(frozen=True)
class DriftFitPolicy(FitPolicy):
    """Drift is fitted along the time axis the rows carry, over the campaign's span in it."""

    def options_for_data(self, robot, q, context) -> dict:
        """The time axis the rows carry (``time_s`` where it varies, else the measurement order)
        and the campaign's start and span in it."""
        time = None if context is None else context.time_s
        if time is not None and np.all(np.isfinite(time)) and np.ptp(time) > 0:
            return {"time_axis": "time_s", "start": float(np.min(time)), "span": float(np.ptp(time))}
        order = None if context is None else context.order
        if order is not None and np.ptp(order) > 0:
            return {"time_axis": "order", "start": float(np.min(order)), "span": float(np.ptp(order))}
        return {}


class Drift(LinearEffect):
    """Encoder zero offsets and the base (or the tracker) drifting over the campaign, as a straight
    line and a warm-up that settles: for every joint and each base translation,
    ``d(u) = a_lin * (u - 1/2) + a_warm * (w(u) - mean w)``, ``w(u) = (1 - exp(-u / tau)) /
    (1 - exp(-1 / tau))``, with ``u`` the campaign's progress from 0 (first row) to 1 (last row),
    in ``time_s`` where the rows carry it, else in measurement order.

    Both shapes average to zero over the campaign: the other effects describe the robot as it was
    on average (a constant is a joint offset or the tracker frame), and the parameters are what
    drifted from the first row to the last [rad, m]. Rows without a time or an order (poses to
    predict) are taken at that average. ``time_axis``: ``"time_s"`` or ``"order"``; ``start``,
    ``span``: where u = 0 and
    how long the campaign lasted in that axis' unit (s or rows); ``time_constant``: the warm-up's
    tau as a share of the campaign (default 0.25). The diagnosis sets them from the data
    (:meth:`DriftFitPolicy.options_for_data`), and keeps them for any prediction.
    """

    name = "drift"
    in_words = "drift over the campaign"
    summary = "encoder zeros and the base drifting over the campaign (warm-up, a moving base)"
    context_columns = ("time_s",)
    family = "time"
    physics = ("a robot warming up moves its encoder zeros by hundredths of a degree and its base by tenths of a "
               "millimetre: more than 0.2 deg or 0.5 mm over a campaign is a joint or a base that slipped")
    # before encoder_scale: a joint swept in measurement order is a drift until shown otherwise
    fit_policy = DriftFitPolicy(order=52.0)

    def __init__(self, robot, *, time_axis: str = "order", start: float = 0.0, span: float = 1.0,
                 time_constant: float = 0.25) -> None:
        super().__init__(robot)
        self.time_axis = time_axis
        self.start = start
        self.span = span
        self.time_constant = time_constant

    def parameter_names(self):
        joints = [f"drift.{j}.{shape}" for j in self.robot.joint_names for shape in ("linear", "warmup")]
        return joints + [f"drift.base.{axis}.{shape}" for axis in ("dx", "dy", "dz") for shape in ("linear", "warmup")]

    def parameter_units(self):
        joints = [joint_unit(k) for k in self.robot.joint_kinds for _ in range(2)]
        return joints + ["m"] * 6

    def parameter_scales(self):
        joints = [math.radians(0.01) if k == REVOLUTE else 2e-5 for k in self.robot.joint_kinds for _ in range(2)]
        return np.array(joints + [5e-5] * 6)

    def physical_range(self):
        bound = np.concatenate([np.repeat(per_joint_kind(self.robot, math.radians(0.2), 5e-4), 2),
                                np.full(6, 5e-4)])
        return -bound, bound

    def fit_range(self):
        bound = np.concatenate([np.repeat(per_joint_kind(self.robot, math.radians(5.0), 0.01), 2), np.full(6, 0.01)])
        return -bound, bound

    def mechanisms(self):
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        return (Mechanism("warm_up", "encoder zeros or the base drifting while the campaign ran: the arm warming up, "
                          "or the base or the tracker settling", "measure a reference pose (or a target on the base) "
                          "at the start, middle and end of a campaign; warm the robot up before measuring",
                          lower, upper),
                Mechanism("slip", "more than 0.2 deg or 0.5 mm of drift over the campaign: a joint, the base or the "
                          "tracker that slipped", "check the base's anchoring, the tracker's stand and each joint's "
                          "brake and coupling", wide_lower, wide_upper, False))

    def progress(self, context, n: int) -> np.ndarray | None:
        """(n,) the campaign's progress u in [0, 1] of each row, or None when the rows have no
        time or order (then they stand for the campaign's average)."""
        values = None if context is None else (context.time_s if self.time_axis == "time_s" else context.order)
        if values is None:
            return None
        return np.clip((np.asarray(values, dtype=float) - self.start) / max(self.span, 1e-300), 0.0, None)

    def shapes(self, u: np.ndarray | None, n: int) -> np.ndarray:
        """(n, 2) the linear and warm-up shapes at progress u, each rising by 1 from the first row to
        the last and averaging zero over the campaign (zero where u is None)."""
        if u is None:
            return np.zeros((n, 2))
        tau = self.time_constant
        settle = 1.0 - math.exp(-1.0 / tau)
        warm = (1.0 - np.exp(-u / tau)) / settle
        warm_mean = (1.0 - tau * settle) / settle  # the mean of warm over u in [0, 1]
        return np.stack([u - 0.5, warm - warm_mean], axis=1)

    def parameter_jacobian(self, params, q, context):
        jac, entries = self.sparse_parameter_jacobian(params, q, context)
        return EffectJacobian(dq=jac.dq, x=entries.dense(self.error_model.size, self.n_params))

    def sparse_parameter_jacobian(self, params, q, context) -> tuple[EffectJacobian, PoseEntries]:
        """:meth:`parameter_jacobian` with its error-vector part as its nonzero entries
        (:class:`~tcr_accuracy.effects.pose_entries.PoseEntries`): each base parameter moves one entry, the
        base translation applied on the left of the chain as frames' base twist."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n, nj = q.shape
        shape = self.shapes(self.progress(context, n), n)  # (n, 2)
        ddq = np.zeros((n, nj, self.n_params))
        for j in range(nj):
            ddq[:, j, 2 * j:2 * j + 2] = shape
        start = self.error_model.base_slice.start
        return EffectJacobian(dq=ddq), PoseEntries.of([(start + a, shape[:, i:i + 1], 2 * nj + 2 * a + i)
                                                       for a in range(3) for i in range(2)], n)
