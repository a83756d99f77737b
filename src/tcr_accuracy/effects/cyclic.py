"""``cyclic``: cyclic joint errors of high order, a smooth periodic function of each joint's angle."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..units import REVOLUTE
from .joint_columns import JointColumnsEffect
from .fit_policy import FitPolicy


@dataclass(frozen=True)
class CyclicFitPolicy(FitPolicy):
    """The cyclic series is fitted with as many orders as the data hold, under a roughness penalty."""

    def options_for_data(self, robot, q, context) -> dict:
        """The highest order the diagnosis fits: 30 cycles per revolution, fewer when the
        measurements are few (at least 2 poses per parameter over the revolute joints: every
        other joint's motion is noise to one joint's function)."""
        revolute = sum(k == REVOLUTE for k in robot.joint_kinds)
        return {"max_order": int(max(CyclicError.FIRST_ORDER, min(30, 2 + len(q) // (4 * max(revolute, 1)))))}

    def penalty_weights(self, effect) -> np.ndarray:
        """(k,) roughness weight of each parameter, (n / 3)^4: the fit's penalty is
        lambda * sum(w * (theta / scale)^2)."""
        return np.array([(n / effect.FIRST_ORDER) ** 4 for _, _, n, _ in effect._terms()], dtype=float)


class CyclicError(JointColumnsEffect):
    """Cyclic error of each revolute joint, many times per revolution, as a Fourier series of
    its own angle: ``dq_j = sum_n a_n sin(n q_j) + b_n cos(n q_j)`` for n = 3 .. ``max_order``.

    The physics: a strain-wave gear meshes its flexspline teeth twice per wave-generator
    turn and its error repeats at the tooth and wave frequencies, reduced to tens of cycles
    per output revolution; optical and magnetic encoders add their own interpolation and
    eccentricity errors of many cycles. Each joint's output angle then differs from the
    commanded one by a few hundred microradians, oscillating 10-60 times per revolution. The
    first and second harmonics (once and twice per revolution: eccentricity of the gear and
    the encoder) are ``transmission``'s; this effect takes the orders above.

    The series is regularised by its roughness: the fit adds ``lambda * sum_n n^4 (a_n^2 +
    b_n^2)`` (the integral of the squared second derivative of dq over a revolution, up to
    a constant), with lambda chosen by held-out error inside the training rows
    (:meth:`CyclicFitPolicy.penalty_weights`; :class:`~tcr_accuracy.diagnosis.fitting.FitEngine`), so the
    data choose how many orders they support. Parameters ``cyclic.<joint>.a<n>``,
    ``cyclic.<joint>.b<n>`` [rad]. Prismatic joints have none. ``max_order``: the highest
    order (default 30 cycles per revolution).
    """

    name = "cyclic"
    in_words = "cyclic gear and encoder errors"
    summary = "cyclic joint errors of high order (gear tooth mesh, encoder), smoothness-penalised"
    physics = ("strain-wave gear and encoder cyclic errors are a few hundred microradians in all; one harmonic "
               "above 1 mrad (3.4 arc-min) is a damaged gear, not a cyclic error")
    family = "periodic"
    fit_policy = CyclicFitPolicy(order=65.0, last_resort=True)
    #: the lowest order: orders 1 and 2 are transmission's
    FIRST_ORDER = 3

    def __init__(self, robot, *, max_order: int = 30) -> None:
        super().__init__(robot)
        self.max_order = max_order

    def _terms(self):
        orders = range(self.FIRST_ORDER, int(self.max_order) + 1)
        return [(j, name, n, trig) for j, (name, kind) in enumerate(zip(self.robot.joint_names, self.robot.joint_kinds))
                if kind == REVOLUTE for n in orders for trig in ("a", "b")]

    def parameter_names(self):
        return [f"cyclic.{name}.{trig}{n}" for _, name, n, trig in self._terms()]

    def parameter_units(self):
        return ["rad"] * self.n_params

    def parameter_scales(self):
        return np.full(self.n_params, 5e-5)  # 50 urad per harmonic

    def mechanisms(self):
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        return (Mechanism("cyclic_gear_encoder", "cyclic errors of high order: strain-wave gear tooth mesh and encoder "
                          "interpolation", "compare with the gear maker's transmission error curve", lower, upper),
                Mechanism("damaged_gear", "a cyclic error above 1 mrad per harmonic: a damaged gear or a loose "
                          "encoder", "inspect the gear and the encoder's mounting", wide_lower, wide_upper, False))

    def joint_columns(self, q) -> tuple[np.ndarray, np.ndarray]:
        """The parameter Jacobian in its compact form: each term moves one joint only, so
        d(dq)/d(theta) is (N, k) values and the joint (k,) each column moves, n_joints times
        smaller than :meth:`parameter_jacobian`'s (N, n_joints, k) (161 MB at 10^4 poses of a
        six-joint arm with 336 terms, a transient of 1.6 GB at 10^5).

        Returns
        -------
        values : (N, k) d(dq_j)/d(theta_k) of the joint j = ``joint[k]`` [rad/rad]
        joint : (k,) int, the joint each parameter moves
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        terms = self._terms()
        values = np.empty((q.shape[0], len(terms)))
        for k, (j, _, n, trig) in enumerate(terms):
            values[:, k] = np.sin(n * q[:, j]) if trig == "a" else np.cos(n * q[:, j])
        return values, np.array([j for j, _, _, _ in terms], dtype=int)

    def joint_function(self, params, joint: str, angles: np.ndarray) -> np.ndarray:
        """(M,) the fitted cyclic error [rad] of one joint at angles (M,) [rad]."""
        params = self.check_params(params)
        out = np.zeros(np.shape(angles))
        for value, (_, name, n, trig) in zip(params, self._terms()):
            if name == joint:
                out += value * (np.sin(n * angles) if trig == "a" else np.cos(n * angles))
        return out

    def joint_basis(self, joint: str, angles: np.ndarray) -> tuple[list[str], np.ndarray]:
        """The parameters of one joint and their basis (M, k_j) at angles (M,) [rad]."""
        names, columns = [], []
        for (_, name, n, trig), full in zip(self._terms(), self.parameter_names()):
            if name == joint:
                names.append(full)
                columns.append(np.sin(n * angles) if trig == "a" else np.cos(n * angles))
        return names, np.stack(columns, axis=1) if columns else np.zeros((len(angles), 0))
