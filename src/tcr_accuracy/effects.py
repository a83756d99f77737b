"""The effect library: one class per effect that can open a gap between model and robot.

Every effect has the same small interface (:class:`Effect`), so new effects plug into
``simulate`` and ``diagnose`` without touching them:

* ``parameter_names()`` / ``parameter_units()`` / ``parameter_scales()``: the effect's
  parameters (SI), e.g. ``compliance.j2`` [rad/Nm], ``geometry.j3.dy`` [m];
* ``perturb(params, q, context)``: what the effect does to the *model* for commanded
  joint values q (N, n): joint-side offsets ``dq`` (N, n) and/or geometric error
  vectors ``x`` (N, n_params of :class:`~tcr_accuracy.errors.ErrorModel`);
* ``parameter_jacobian(params, q, context)``: d(dq)/d(params) and d(x)/d(params).
  Every effect but ``clearance`` is linear in its parameters, so these maps are exact;
  the base class falls back to central finite differences for an effect that does
  not provide them (and says so in ``analytic_jacobian``).

The robot the effects describe is::

    TCP = tcp_poses(robot, q + sum(dq), sum(x), error_model)

(:func:`predict_poses`). Effects act on the Pinocchio model's joint values and joint
placements, never on the output positions. :func:`prediction_jacobian` gives d(TCP)/d(all
parameters) from Pinocchio's frame Jacobian (joint side) and frame kinematic regressor
(placement side), chained with the effects' parameter maps.

Vocabulary (:data:`EFFECTS`, in this order): ``frames``, ``joint_offsets``, ``geometry``,
``compliance``, ``backlash``, ``thermal``, ``transmission``, ``encoder_scale``,
``clearance``.
"""

from __future__ import annotations

import abc
import math
import warnings
from dataclasses import dataclass
from typing import ClassVar, Sequence

import numpy as np
import pinocchio as pin

from .errors import PLACEMENT_COMPONENTS, ErrorModel
from .exceptions import InputError
from .kinematics import TcpPoses, tcp_poses
from .measurements import REFERENCE_TEMPERATURE_C, MeasurementContext
from .robot import REVOLUTE, JointLimitWarning, RobotModel

#: skew(p)_ij = -eps_ijk p_k
_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0


@dataclass(frozen=True)
class EffectOutput:
    """What an effect does to the model for N joint vectors.

    dq : ndarray of shape (N, n_joints) or None
        Offsets added to the commanded joint values [rad, m].
    x : ndarray of shape (N, n_error_params) or None
        Geometric error vectors (layout of :class:`~tcr_accuracy.errors.ErrorModel`).
    """

    dq: np.ndarray | None = None
    x: np.ndarray | None = None


@dataclass(frozen=True)
class EffectJacobian:
    """Derivatives of an effect's output with respect to its k parameters.

    dq : ndarray of shape (N, n_joints, k) or None
    x : ndarray of shape (N, n_error_params, k), or (n_error_params, k) when the same
        for every row, or None
    """

    dq: np.ndarray | None = None
    x: np.ndarray | None = None


# ---------------------------------------------------------------------------------------
# Base class
# ---------------------------------------------------------------------------------------
class Effect(abc.ABC):
    """One effect: its parameters and how it perturbs the model.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot (never modified).
    **options
        Effect-specific settings, only stored (see each class).
    """

    name: ClassVar[str]
    #: CSV context columns the effect reads (``<joint>_dir`` stands for the direction columns).
    context_columns: ClassVar[tuple[str, ...]] = ()
    #: True only for random effects (clearance): scatter, not bias.
    stochastic: ClassVar[bool] = False
    #: False when parameter_jacobian falls back to finite differences.
    analytic_jacobian: ClassVar[bool] = True

    def __init__(self, robot: RobotModel, **options) -> None:
        self.robot = robot
        self.options = options

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.items() if k != "rng")
        return f"{type(self).__name__}({self.robot.name}{', ' + opts if opts else ''})"

    # -- parameters ----------------------------------------------------------------------
    @abc.abstractmethod
    def parameter_names(self) -> list[str]:
        """Names ``<effect>.<...>`` of the k parameters."""

    @abc.abstractmethod
    def parameter_units(self) -> list[str]:
        """SI unit of each parameter (``m``, ``rad``, ``rad/Nm``, ``m/N``, ``1/K``, ``1``)."""

    @abc.abstractmethod
    def parameter_scales(self) -> np.ndarray:
        """(k,) typical magnitude of each parameter [SI]: fit scaling, simulate defaults."""

    @property
    def n_params(self) -> int:
        return len(self.parameter_names())

    def zeros(self) -> np.ndarray:
        return np.zeros(self.n_params)

    def check_params(self, params) -> np.ndarray:
        params = np.asarray(params, dtype=float).reshape(-1)
        if params.shape != (self.n_params,):
            raise InputError(f"effect {self.name}: {params.size} parameter values given, it has "
                             f"{self.n_params} ({', '.join(self.parameter_names()[:4])}, ...)")
        if not np.all(np.isfinite(params)):
            raise InputError(f"effect {self.name}: non-finite parameter value")
        return params

    @property
    def error_model(self) -> ErrorModel:
        em = self.__dict__.get("_error_model")
        if em is None:
            em = self.__dict__["_error_model"] = ErrorModel(self.robot)
        return em

    # -- what it does --------------------------------------------------------------------
    @abc.abstractmethod
    def perturb(self, params, q: np.ndarray, context: MeasurementContext) -> EffectOutput:
        """Joint offsets and/or error vectors for commanded joints q (N, n) [SI]."""

    def parameter_jacobian(self, params, q: np.ndarray, context: MeasurementContext) -> EffectJacobian:
        """d(dq)/d(params) (N, n, k) and d(x)/d(params) (N, p, k) at params.

        Fallback: central finite differences of :meth:`perturb` (step 1e-3 of each
        parameter's scale). Linear effects override this with their exact maps.
        """
        params = self.check_params(params)
        q = np.atleast_2d(q)
        steps = 1e-3 * self.parameter_scales()
        n, nj, p = q.shape[0], self.robot.n_joints, self.error_model.size
        ddq = np.zeros((n, nj, self.n_params))
        dx = np.zeros((n, p, self.n_params))
        for k, h in enumerate(steps):
            e = np.zeros(self.n_params)
            e[k] = h
            plus, minus = self.perturb(params + e, q, context), self.perturb(params - e, q, context)
            if plus.dq is not None:
                ddq[:, :, k] = (plus.dq - minus.dq) / (2 * h)
            if plus.x is not None:
                dx[:, :, k] = (plus.x - minus.x) / (2 * h)
        return EffectJacobian(ddq, dx)


class LinearEffect(Effect):
    """An effect linear in its parameters: perturb = parameter_jacobian @ params."""

    @abc.abstractmethod
    def parameter_jacobian(self, params, q, context) -> EffectJacobian:  # noqa: D102
        ...

    def perturb(self, params, q, context) -> EffectOutput:
        params = self.check_params(params)
        q = np.atleast_2d(np.asarray(q, dtype=float))
        jac = self.parameter_jacobian(params, q, context)
        dq = None if jac.dq is None else jac.dq @ params
        x = None
        if jac.x is not None:
            x = jac.x @ params
            if x.ndim == 1:
                x = np.broadcast_to(x, (q.shape[0], x.size))
        return EffectOutput(dq=dq, x=x)


def _joint_unit(kind: str) -> str:
    return "rad" if kind == REVOLUTE else "m"


# ---------------------------------------------------------------------------------------
# frames, joint_offsets, geometry
# ---------------------------------------------------------------------------------------
class Frames(LinearEffect):
    """Unknown base (tracker) frame and TCP offset.

    Parameters: ``frames.base.dx .. rz`` (a twist applied on the left of the whole
    chain: the measurement frame relative to the robot's base) and ``frames.tool.dx,
    dy, dz`` (the TCP offset in the TCP frame), plus ``frames.tool.rx, ry, rz`` with
    option ``tool_rotation=True`` (only identifiable when orientation is measured).
    Exact for large base transforms: the twist goes through ``exp6``.
    """

    name = "frames"

    def _tool_components(self) -> tuple[str, ...]:
        return PLACEMENT_COMPONENTS if self.options.get("tool_rotation", False) else PLACEMENT_COMPONENTS[:3]

    def parameter_names(self):
        return ([f"frames.base.{c}" for c in PLACEMENT_COMPONENTS]
                + [f"frames.tool.{c}" for c in self._tool_components()])

    def parameter_units(self):
        return ["m" if n.split(".")[-1].startswith("d") else "rad" for n in self.parameter_names()]

    def parameter_scales(self):
        # the tracker sits anywhere: centimetres and degrees; the TCP offset: a millimetre
        scales = {"base.d": 1e-2, "base.r": 1e-2, "tool.d": 1e-3, "tool.r": 1e-3}
        return np.array([scales[".".join(n.split(".")[1:])[:6]] for n in self.parameter_names()])

    def parameter_jacobian(self, params, q, context):
        em = self.error_model
        cols = [em.index(n[len("frames."):]) for n in self.parameter_names()]
        dx = np.zeros((em.size, len(cols)))
        dx[cols, np.arange(len(cols))] = 1.0
        return EffectJacobian(x=dx)


class JointOffsets(LinearEffect):
    """Encoder zero offsets: ``dq_j = offset_j`` [rad or m]. Parameters ``joint_offsets.<joint>``."""

    name = "joint_offsets"

    def parameter_names(self):
        return [f"joint_offsets.{n}" for n in self.robot.joint_names]

    def parameter_units(self):
        return [_joint_unit(k) for k in self.robot.joint_kinds]

    def parameter_scales(self):
        # 0.03 deg, 0.05 mm
        return np.array([math.radians(0.03) if k == REVOLUTE else 5e-5 for k in self.robot.joint_kinds])

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(q)
        n = self.robot.n_joints
        return EffectJacobian(dq=np.broadcast_to(np.eye(n), (q.shape[0], n, n)))


class Geometry(LinearEffect):
    """Error screws on every joint placement: ``parentMjoint <- parentMjoint * exp6(xi_j)``.

    Parameters ``geometry.<joint>.<dx|dy|dz|rx|ry|rz>`` [m, rad], the twist components
    in the joint's own frame (link lengths, offsets, axis misalignments). All 6n are
    listed; many are not identifiable from TCP positions (a rotation about a revolute
    joint's own axis is a joint offset; a translation along it can be moved to the next
    placement; the first placement trades against the base frame). Option
    ``components``: a list of ``"<joint>.<c>"`` to keep a subset. Otherwise the
    identification (diagnose) must prune with a rank-revealing QR of the Jacobian.
    """

    name = "geometry"

    def parameter_names(self):
        keep = self.options.get("components")
        names = [f"geometry.{j}.{c}" for j in self.robot.joint_names for c in PLACEMENT_COMPONENTS]
        if keep is not None:
            keep = {f"geometry.{k}" for k in keep}
            unknown = keep - set(names)
            if unknown:
                raise InputError(f"geometry: unknown components {sorted(unknown)}")
            names = [n for n in names if n in keep]
        return names

    def parameter_units(self):
        return ["m" if n.split(".")[-1].startswith("d") else "rad" for n in self.parameter_names()]

    def parameter_scales(self):
        return np.full(self.n_params, 2e-4)  # 0.2 mm, 0.2 mrad

    def parameter_jacobian(self, params, q, context):
        em = self.error_model
        cols = [em.index(n[len("geometry."):]) for n in self.parameter_names()]
        dx = np.zeros((em.size, len(cols)))
        dx[cols, np.arange(len(cols))] = 1.0
        return EffectJacobian(x=dx)


# ---------------------------------------------------------------------------------------
# Gravity: compliance and backlash
# ---------------------------------------------------------------------------------------
def gravity_model(robot: RobotModel, link_mass_factors=None, payload_kg: float = 0.0) -> pin.Model:
    """A copy of the robot's Pinocchio model with scaled link masses and a point payload.

    link_mass_factors : array-like of shape (n_joints,), optional
        Factor on the mass (and rotational inertia) of the body moved by each joint.
    payload_kg : float
        Point mass added at the TCP frame's origin [kg].
    """
    model = pin.Model(robot.model)
    if link_mass_factors is not None:
        factors = np.asarray(link_mass_factors, dtype=float)
        if factors.shape != (robot.n_joints,) or np.any(factors < 0):
            raise InputError(f"link mass factors: need {robot.n_joints} values >= 0")
        for j in range(1, model.njoints):
            inertia = model.inertias[j]
            model.inertias[j] = pin.Inertia(inertia.mass * factors[j - 1], inertia.lever,
                                            inertia.inertia * factors[j - 1])
    if payload_kg:
        frame = model.frames[robot.tool_frame_id]
        point = pin.Inertia(float(payload_kg), np.zeros(3), np.zeros((3, 3)))
        model.inertias[frame.parentJoint] = model.inertias[frame.parentJoint] + frame.placement.act(point)
    return model


def gravity_torque(robot: RobotModel, q: np.ndarray, payload_kg=0.0, link_mass_factors=None) -> np.ndarray:
    """Torque (force) that gravity exerts on each joint, shape (N, n_joints) [Nm, N].

    This is ``-pin.computeGeneralizedGravity``: Pinocchio returns the torque a drive must
    apply to hold the arm; gravity pulls the other way. A payload is a point mass at
    the TCP frame; ``payload_kg`` is a scalar or (N,) per row. Because gravity torque is
    linear in the payload mass, two Pinocchio models (arm, arm + 1 kg) serve every row.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (q.shape[0],))
    factors = None if link_mass_factors is None else np.asarray(link_mass_factors, dtype=float)
    key = (id(robot.model), _digest(q), _digest(payload), None if factors is None else _digest(factors))
    cached = _GRAVITY_CACHE.get(key)
    if cached is not None and cached[0] is robot.model:
        return cached[1].copy()
    arm = gravity_model(robot, factors)
    with_unit = gravity_model(robot, factors, payload_kg=1.0)
    d_arm, d_unit = arm.createData(), with_unit.createData()
    out = np.empty_like(q)
    any_payload = bool(np.any(payload != 0))
    plain_q = robot.model.nq == robot.n_joints
    for i, qi in enumerate(q):
        qp = qi if plain_q else robot.to_pinocchio_q(qi)
        g_arm = pin.computeGeneralizedGravity(arm, d_arm, qp)
        tau = g_arm
        if any_payload:
            tau = g_arm + payload[i] * (pin.computeGeneralizedGravity(with_unit, d_unit, qp) - g_arm)
        out[i] = -_v_to_joints(robot, tau)
    if len(_GRAVITY_CACHE) >= 8:
        _GRAVITY_CACHE.pop(next(iter(_GRAVITY_CACHE)))
    _GRAVITY_CACHE[key] = (robot.model, out.copy())
    return out


#: The last few gravity torque batches: compliance and backlash, perturb and Jacobian, all
#: ask for the same rows during a fit. Keyed by the model's identity and the inputs' bytes.
_GRAVITY_CACHE: dict = {}


def _digest(a: np.ndarray) -> bytes:
    import hashlib

    a = np.ascontiguousarray(a)
    return hashlib.blake2b(a.tobytes() + str(a.shape).encode(), digest_size=16).digest()


def _v_to_joints(robot: RobotModel, v: np.ndarray) -> np.ndarray:
    """Pinocchio velocity-space vector (nv,) to one value per joint (n_joints,)."""
    if robot.model.nv == robot.n_joints:
        return np.asarray(v)
    model = robot.model
    return np.array([v[model.joints[j].idx_v] for j in range(1, model.njoints)])


def _context_column(context: MeasurementContext, attr: str, n: int, default: float) -> np.ndarray:
    if context is None:
        return np.full(n, default)
    value = np.asarray(getattr(context, attr), dtype=float)
    return np.broadcast_to(value, (n,)) if value.ndim == 0 else value


class Compliance(LinearEffect):
    """Joint elasticity under gravity and payload: ``dq_j = c_j * tau_g,j(q, payload)``.

    ``tau_g`` is the torque gravity exerts on each joint (:func:`gravity_torque`, from
    ``pin.computeGeneralizedGravity`` with the payload as a point mass at the TCP), so a
    positive compliance lets the arm sag the way gravity pulls. Parameters
    ``compliance.<joint>`` = 1/k_j [rad/Nm, or m/N for a prismatic joint]. Context:
    ``payload_kg`` per row. Option ``link_mass_factors`` (n_joints,): the real link
    masses relative to the URDF's (simulate draws them; a fit uses the URDF's).
    """

    name = "compliance"
    context_columns = ("payload_kg",)

    def parameter_names(self):
        return [f"compliance.{n}" for n in self.robot.joint_names]

    def parameter_units(self):
        return ["rad/Nm" if k == REVOLUTE else "m/N" for k in self.robot.joint_kinds]

    def parameter_scales(self):
        """Compliances that turn each joint by 0.01 deg (or 0.05 mm) under a typical torque.

        The typical torque is the RMS gravity torque over a fixed set of poses inside the
        limits with a payload of :func:`typical_payload_kg`; joints gravity never loads
        get the median of the others' scales.
        """
        q = _reference_poses(self.robot)
        tau = gravity_torque(self.robot, q, typical_payload_kg(self.robot),
                             self.options.get("link_mass_factors"))
        rms = np.sqrt(np.mean(tau**2, axis=0))
        target = np.array([math.radians(0.01) if k == REVOLUTE else 5e-5 for k in self.robot.joint_kinds])
        loaded = rms > 1e-6 * max(rms.max(), 1e-300)
        scales = np.where(loaded, target / np.where(loaded, rms, 1.0), np.nan)
        fill = np.nanmedian(scales) if loaded.any() else 1e-6
        return np.where(loaded, scales, fill)

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(np.asarray(q, dtype=float))
        payload = _context_column(context, "payload_kg", q.shape[0], 0.0)
        tau = gravity_torque(self.robot, q, payload, self.options.get("link_mass_factors"))
        n = self.robot.n_joints
        ddq = np.zeros((q.shape[0], n, n))
        ddq[:, np.arange(n), np.arange(n)] = tau
        return EffectJacobian(dq=ddq)


class Backlash(LinearEffect):
    """A dead band per joint: ``dq_j = b_j / 2 * s_j``.

    The side of the band the joint rests on, ``s_j``, is ``-dir_j`` when the approach
    direction ``<joint>_dir`` is given (the output lags behind the motion), else the sign
    of the gravity torque on the joint (gravity pulls the output against one flank);
    a joint gravity does not load (|tau| below 1e-6 of the largest) and with no direction
    sits in the middle of the band (s = 0). Parameters ``backlash.<joint>`` = full band
    width b_j [rad or m]. Option ``link_mass_factors`` as for compliance.
    """

    name = "backlash"
    context_columns = ("payload_kg", "<joint>_dir")

    def parameter_names(self):
        return [f"backlash.{n}" for n in self.robot.joint_names]

    def parameter_units(self):
        return [_joint_unit(k) for k in self.robot.joint_kinds]

    def parameter_scales(self):
        return np.array([math.radians(0.03) if k == REVOLUTE else 5e-5 for k in self.robot.joint_kinds])

    def side(self, q, context) -> np.ndarray:
        """(N, n_joints) side of the dead band, +1, -1 or 0."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        payload = _context_column(context, "payload_kg", q.shape[0], 0.0)
        tau = gravity_torque(self.robot, q, payload, self.options.get("link_mass_factors"))
        threshold = 1e-6 * max(float(np.abs(tau).max()), 1e-300)
        s = np.where(np.abs(tau) > threshold, np.sign(tau), 0.0)
        if context is not None and context.direction is not None:
            direction = np.asarray(context.direction, dtype=float)
            s = np.where(direction != 0, -direction, s)
        return s

    def parameter_jacobian(self, params, q, context):
        s = self.side(q, context)
        n = self.robot.n_joints
        ddq = np.zeros((s.shape[0], n, n))
        ddq[:, np.arange(n), np.arange(n)] = 0.5 * s
        return EffectJacobian(dq=ddq)


# ---------------------------------------------------------------------------------------
# thermal, transmission, encoder_scale
# ---------------------------------------------------------------------------------------
class Thermal(LinearEffect):
    """Links growing with temperature: every placement translation scaled by 1 + alpha (T - T_ref).

    A placement ``(R, t)`` becomes ``(R, t (1 + alpha dT))`` through the twist
    ``v = alpha dT R^T t`` on the right (exact: a pure translation). The TCP frame's
    offset grows the same way. Parameters: ``thermal.alpha`` [1/K] for the whole arm, or
    with option ``per_link=True`` one ``thermal.alpha.<joint>`` per placement that has
    a length (and ``thermal.alpha.tool``). Option ``reference_temperature_c`` (default
    20 degC). Context: ``temperature_c`` per row.
    """

    name = "thermal"
    context_columns = ("temperature_c",)

    def _links(self) -> list[tuple[str, int | None]]:
        """(label, joint index or None for the tool) of every placement with a length."""
        links = [(n, j) for j, (n, pl) in enumerate(zip(self.robot.joint_names, self.robot.joint_placements))
                 if np.linalg.norm(pl.translation) > 1e-9]
        if np.linalg.norm(self.robot.tool_placement.translation) > 1e-9:
            links.append(("tool", None))
        return links

    def parameter_names(self):
        if self.options.get("per_link", False):
            return [f"thermal.alpha.{label}" for label, _ in self._links()]
        return ["thermal.alpha"]

    def parameter_units(self):
        return ["1/K"] * self.n_params

    def parameter_scales(self):
        return np.full(self.n_params, 1.2e-5)  # steel

    def growth_directions(self) -> np.ndarray:
        """(n_error_params, k): d(x)/d(alpha dT) for each parameter."""
        em = self.error_model
        links = self._links()
        per_link = self.options.get("per_link", False)
        out = np.zeros((em.size, len(links) if per_link else 1))
        for k, (label, j) in enumerate(links):
            col = k if per_link else 0
            if j is None:
                tool = self.robot.tool_placement
                out[em.tool_slice.start:em.tool_slice.start + 3, col] = tool.rotation.T @ tool.translation
            else:
                pl = self.robot.joint_placements[j]
                start = em.index(f"{label}.dx")
                out[start:start + 3, col] = pl.rotation.T @ pl.translation
        return out

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(q)
        t_ref = float(self.options.get("reference_temperature_c", REFERENCE_TEMPERATURE_C))
        temperature = _context_column(context, "temperature_c", q.shape[0], t_ref)
        d_t = temperature - t_ref
        return EffectJacobian(x=d_t[:, None, None] * self.growth_directions()[None])


class Transmission(LinearEffect):
    """Periodic gear error per revolute joint, first and second harmonic of the joint angle.

    ``dq_j = a1 sin(q_j) + b1 cos(q_j) + a2 sin(2 q_j) + b2 cos(2 q_j)``. Parameters
    ``transmission.<joint>.a1, b1, a2, b2`` [rad]. Prismatic joints have none (their
    period is not a joint angle). Option ``harmonics`` (default (1, 2)).
    """

    name = "transmission"

    def _terms(self):
        harmonics = tuple(self.options.get("harmonics", (1, 2)))
        return [(j, name, h, trig) for j, (name, kind) in enumerate(zip(self.robot.joint_names, self.robot.joint_kinds))
                if kind == REVOLUTE for h in harmonics for trig in ("a", "b")]

    def parameter_names(self):
        return [f"transmission.{name}.{trig}{h}" for _, name, h, trig in self._terms()]

    def parameter_units(self):
        return ["rad"] * self.n_params

    def parameter_scales(self):
        return np.full(self.n_params, math.radians(0.01))

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(np.asarray(q, dtype=float))
        terms = self._terms()
        ddq = np.zeros((q.shape[0], self.robot.n_joints, len(terms)))
        for k, (j, _, h, trig) in enumerate(terms):
            ddq[:, j, k] = np.sin(h * q[:, j]) if trig == "a" else np.cos(h * q[:, j])
        return EffectJacobian(dq=ddq)


class EncoderScale(LinearEffect):
    """Gear ratio (scale) error: ``dq_j = s_j q_j``. Parameters ``encoder_scale.<joint>`` [1]."""

    name = "encoder_scale"

    def parameter_names(self):
        return [f"encoder_scale.{n}" for n in self.robot.joint_names]

    def parameter_units(self):
        return ["1"] * self.n_params

    def parameter_scales(self):
        return np.full(self.n_params, 3e-4)

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n = self.robot.n_joints
        ddq = np.zeros((q.shape[0], n, n))
        ddq[:, np.arange(n), np.arange(n)] = q
        return EffectJacobian(dq=ddq)


# ---------------------------------------------------------------------------------------
# clearance: random play
# ---------------------------------------------------------------------------------------
class Clearance(Effect):
    """Random joint play after the first seed paper's clearance model: scatter, not bias.

    In every joint with clearance, for each measurement independently, the journal
    moves in its bearing: an axial shift ``d ~ N(0, axial)`` along the joint axis, a
    radial shift of length ``s ~ N(0, radial)`` in a uniformly random direction
    perpendicular to the axis, and a tilt of the axis about the two perpendicular
    directions, each ``~ N(0, tilt)``. These form the twist on the joint placement (in
    the joint frame). Parameters: the spreads ``clearance.axial`` [m],
    ``clearance.radial`` [m], ``clearance.tilt`` [rad], shared by the joints with play.
    Options: ``joints`` (names; default every revolute joint, as the seed), ``rng`` (a
    numpy Generator; else ``context.rng`` is used).
    """

    name = "clearance"
    stochastic = True
    analytic_jacobian = False

    def parameter_names(self):
        return ["clearance.axial", "clearance.radial", "clearance.tilt"]

    def parameter_units(self):
        return ["m", "m", "rad"]

    def parameter_scales(self):
        return np.array([1e-5, 1e-5, 1e-5])

    def joints(self) -> list[int]:
        names = self.options.get("joints")
        if names is None:
            return [j for j, k in enumerate(self.robot.joint_kinds) if k == REVOLUTE]
        unknown = [n for n in names if n not in self.robot.joint_names]
        if unknown:
            raise InputError(f"clearance: unknown joints {unknown} (joints: {', '.join(self.robot.joint_names)})")
        return [self.robot.joint_names.index(n) for n in names]

    def _frames(self, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit axis and two perpendicular unit vectors of joint j (its own frame)."""
        motion = self.robot.motion_axes[j]
        axis = motion[3:] if self.robot.joint_kinds[j] == REVOLUTE else motion[:3]
        helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
        u = np.cross(axis, helper)
        u /= np.linalg.norm(u)
        return axis, u, np.cross(axis, u)

    def perturb(self, params, q, context) -> EffectOutput:
        params = self.check_params(params)
        q = np.atleast_2d(q)
        rng = self.options.get("rng") or (context.rng if context is not None else None)
        if rng is None:
            raise InputError("clearance: a random generator is needed (option rng= or context.rng)")
        axial, radial, tilt = params
        em = self.error_model
        n = q.shape[0]
        x = np.zeros((n, em.size))
        for j in self.joints():
            axis, u, w = self._frames(j)
            d = axial * rng.standard_normal(n)
            s = radial * rng.standard_normal(n)
            theta = rng.uniform(0.0, 2 * math.pi, n)
            tu, tw = tilt * rng.standard_normal(n), tilt * rng.standard_normal(n)
            start = em.index(f"{self.robot.joint_names[j]}.dx")
            x[:, start:start + 3] = (d[:, None] * axis + (s * np.cos(theta))[:, None] * u
                                     + (s * np.sin(theta))[:, None] * w)
            x[:, start + 3:start + 6] = tu[:, None] * u + tw[:, None] * w
        return EffectOutput(x=x)

    def twist_covariance(self, params) -> np.ndarray:
        """(n_error_params, n_error_params) covariance of the x that perturb draws.

        Radial shift: s cos(theta), s sin(theta) each have variance radial^2 / 2.
        Push it through the TCP Jacobian (d TCP / d x) to get the scatter at the TCP.
        """
        axial, radial, tilt = self.check_params(params)
        em = self.error_model
        cov = np.zeros((em.size, em.size))
        for j in self.joints():
            axis, u, w = self._frames(j)
            start = em.index(f"{self.robot.joint_names[j]}.dx")
            t = slice(start, start + 3)
            r = slice(start + 3, start + 6)
            cov[t, t] = axial**2 * np.outer(axis, axis) + radial**2 / 2 * (np.outer(u, u) + np.outer(w, w))
            cov[r, r] = tilt**2 * (np.outer(u, u) + np.outer(w, w))
        return cov


#: The effect vocabulary, in its fixed order.
EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls for cls in (Frames, JointOffsets, Geometry, Compliance, Backlash, Thermal,
                              Transmission, EncoderScale, Clearance)
}


def make_effect(name: str, robot: RobotModel, **options) -> Effect:
    """An effect of the vocabulary by name."""
    try:
        cls = EFFECTS[name]
    except KeyError:
        raise InputError(f"unknown effect {name!r}; effects: {', '.join(EFFECTS)}") from None
    return cls(robot, **options)


# ---------------------------------------------------------------------------------------
# Helpers shared by effects
# ---------------------------------------------------------------------------------------
def typical_payload_kg(robot: RobotModel) -> float:
    """The payload an analysis assumes by default: a 150 kg disc cutter on the tool-changer,
    else a fifth of the moving links' mass."""
    if robot.name == "tool_changer":
        from .tool_changer import DISC_CUTTER_MASS

        return DISC_CUTTER_MASS
    mass = sum(robot.model.inertias[j].mass for j in range(1, robot.model.njoints))
    return 0.2 * mass


def _reference_poses(robot: RobotModel, n: int = 64) -> np.ndarray:
    """(n, n_joints) fixed, reproducible poses spread inside the limits (unbounded: +-pi)."""
    lo = np.where(np.isnan(robot.lower_limits), -math.pi, robot.lower_limits)
    hi = np.where(np.isnan(robot.upper_limits), math.pi, robot.upper_limits)
    u = np.random.default_rng(20240501).uniform(size=(n, robot.n_joints))
    return lo + (hi - lo) * u


# ---------------------------------------------------------------------------------------
# Composition: the model the effects describe, and its Jacobian
# ---------------------------------------------------------------------------------------
def _as_context(context, n_rows: int, n_joints: int) -> MeasurementContext:
    return context if context is not None else MeasurementContext.defaults(n_rows, n_joints)


def total_perturbation(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                       context: MeasurementContext | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sum of the effects' outputs: dq (N, n_joints) and x (N, n_error_params)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if len(effects) != len(params_list):
        raise InputError(f"{len(effects)} effects but {len(params_list)} parameter vectors")
    context = _as_context(context, q.shape[0], robot.n_joints)
    em = ErrorModel(robot)
    dq = np.zeros_like(q)
    x = np.zeros((q.shape[0], em.size))
    for effect, params in zip(effects, params_list):
        out = effect.perturb(params, q, context)
        if out.dq is not None:
            dq = dq + out.dq
        if out.x is not None:
            x = x + out.x
    return dq, x


def predict_poses(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                  context: MeasurementContext | None = None) -> TcpPoses:
    """TCP poses of the robot the effects describe: ``tcp_poses(robot, q + dq, x)``.

    q : (N, n_joints) commanded joints [SI]; params_list : one (k_e,) array per effect.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    dq, x = total_perturbation(robot, effects, params_list, q, context)
    em = ErrorModel(robot)
    return tcp_poses(robot, q + dq, x if x.any() else None, em if x.any() else None)


def predict_positions(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                      context: MeasurementContext | None = None) -> np.ndarray:
    """(N, 3) TCP positions [m] of the robot the effects describe (see :func:`predict_poses`)."""
    return predict_poses(robot, effects, params_list, q, context).position


def pose_jacobians(robot: RobotModel, q, x=None) -> tuple[np.ndarray, np.ndarray]:
    """TCP Jacobians with respect to joint offsets and error parameters, per row.

    Parameters
    ----------
    q : (N, n_joints) actual joint values [SI] (commanded plus joint-side offsets)
    x : (n_error_params,) or (N, n_error_params), optional
        Error vector the Jacobians are taken at; rows are averaged (the derivatives
        change with x only to second order, so thermal's small per-row spread is
        neglected).

    Returns
    -------
    jq : (N, 6, n_joints) d(TCP)/d(q), jx : (N, 6, n_error_params) d(TCP)/d(x).
    Rows: TCP displacement in base-frame axes, then rotation vector, as Pinocchio's
    LOCAL_WORLD_ALIGNED. From Pinocchio's frame Jacobian and frame kinematic regressor
    of the perturbed model, chained with the derivative of ``exp6`` (``pin.Jexp6``) at x.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    em = ErrorModel(robot)
    x_mean = np.zeros(em.size) if x is None else np.atleast_2d(np.asarray(x, dtype=float)).mean(axis=0)
    parts = em.split(x_mean)
    work = em.perturbed_robot(x_mean) if x_mean.any() else robot
    model, data = work.model, work.model.createData()
    frame_id = robot.tool_frame_id
    n, nj, p = q.shape[0], robot.n_joints, em.size
    jq = np.empty((n, 6, nj))
    jx = np.zeros((n, 6, p))
    idx_v = [model.joints[j].idx_v for j in range(1, model.njoints)]
    plain_q = model.nq == nj
    # right Jacobians of exp6 at the current twists: exp6(xi + d) = exp6(xi) exp6(Jr d)
    axes = robot.motion_axes
    placement_chain = []
    for j in range(nj):
        jr = pin.Jexp6(pin.Motion(parts.placement[j]))
        drive = pin.exp6(axes[j] * parts.drive[j]).inverse().action
        placement_chain.append(drive @ jr)
    tool_chain = pin.Jexp6(pin.Motion(parts.tool))
    base_xi = pin.Motion(parts.base)
    base_chain = pin.exp6(base_xi).action @ pin.Jexp6(base_xi)  # left Jacobian = Ad(exp) Jr
    regressors = np.empty((n, 6, 6 * nj))
    rotations = np.empty((n, 3, 3))
    positions = np.empty((n, 3))
    for i in range(n):
        qp = q[i] if plain_q else work.to_pinocchio_q(q[i])
        pin.computeJointJacobians(model, data, qp)
        pin.updateFramePlacements(model, data)
        rotations[i] = data.oMf[frame_id].rotation
        positions[i] = data.oMf[frame_id].translation
        regressors[i] = pin.computeFrameKinematicRegressor(model, data, frame_id, pin.LOCAL)
        jq[i] = pin.getFrameJacobian(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED)[:, idx_v]
    # LOCAL (TCP frame) -> base-frame axes, then chain each placement block with its exp6 derivative
    aligned = (rotations[:, None] @ regressors.reshape(n, 2, 3, 6 * nj)).reshape(n, 6, nj, 6)
    chain = np.stack(placement_chain)  # (nj, 6, 6)
    jx[:, :, em.placement_slice] = (aligned.transpose(0, 2, 1, 3) @ chain).transpose(0, 2, 1, 3).reshape(
        n, 6, 6 * nj)
    jx[:, :, em.drive_slice] = jq
    base = np.zeros((n, 6, 6))
    base[:, :3, :3] = np.eye(3)
    base[:, :3, 3:] = -np.einsum("nk,ikj->nij", positions, _LEVI_CIVITA)  # -skew(p)
    base[:, 3:, 3:] = np.eye(3)
    jx[:, :, em.base_slice] = base @ base_chain
    tool = np.zeros((n, 6, 6))
    tool[:, :3, :3] = rotations
    tool[:, 3:, 3:] = rotations
    jx[:, :, em.tool_slice] = tool @ tool_chain
    return jq, jx


def prediction_jacobian(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                        context: MeasurementContext | None = None, *, orientation: bool = False
                        ) -> np.ndarray:
    """d(TCP)/d(parameters of all effects), shape (N, 3, K) (or (N, 6, K) with orientation).

    Columns follow the effects' order, each effect's parameters in its own order
    (K = sum of n_params). Stochastic effects (clearance) get zero columns: they add
    scatter, not a predictable displacement. Rows: TCP displacement in base-frame axes
    [m], then rotation vector [rad] with orientation.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    context = _as_context(context, q.shape[0], robot.n_joints)
    deterministic = [(e, p) for e, p in zip(effects, params_list) if not e.stochastic]
    dq, x = total_perturbation(robot, [e for e, _ in deterministic], [p for _, p in deterministic], q, context)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", JointLimitWarning)
        jq, jx = pose_jacobians(robot, q + dq, x)
    rows = 6 if orientation else 3
    jq, jx = jq[:, :rows], jx[:, :rows]
    blocks = []
    for effect, params in zip(effects, params_list):
        block = np.zeros((q.shape[0], rows, effect.n_params))
        if not effect.stochastic:
            maps = effect.parameter_jacobian(params, q, context)
            if maps.dq is not None:
                block += jq @ maps.dq  # (N, r, n) @ (N, n, k)
            if maps.x is not None:
                block += jx @ maps.x  # (N, r, p) @ (p, k) or (N, p, k)
        blocks.append(block)
    return np.concatenate(blocks, axis=2) if blocks else np.zeros((q.shape[0], rows, 0))


def split_parameters(effects: Sequence[Effect], flat) -> list[np.ndarray]:
    """One flat vector (K,) of all effects' parameters -> one (k_e,) array per effect."""
    flat = np.asarray(flat, dtype=float)
    sizes = [e.n_params for e in effects]
    if flat.shape != (sum(sizes),):
        raise InputError(f"{flat.size} parameter values for effects with {sum(sizes)} parameters")
    return np.split(flat, np.cumsum(sizes)[:-1]) if effects else []


def parameter_names(effects: Sequence[Effect]) -> list[str]:
    """Names of all effects' parameters, in the order of prediction_jacobian's columns."""
    return [name for effect in effects for name in effect.parameter_names()]


#: SI parameter unit -> (display unit, factor) for reports and exported YAML.
DISPLAY_UNITS: dict[str, tuple[str, float]] = {
    "m": ("mm", 1e3),
    "rad": ("deg", 180.0 / math.pi),
    "rad/Nm": ("deg/kNm", 180.0 / math.pi * 1e3),
    "m/N": ("mm/kN", 1e6),
    "1/K": ("ppm/K", 1e6),
    "1": ("ppm", 1e6),
}


def display_value(value: float, unit: str) -> tuple[float, str]:
    """An SI parameter value in its display unit: (2e-4, "rad") -> (0.01146, "deg")."""
    label, factor = DISPLAY_UNITS.get(unit, (unit, 1.0))
    return float(value) * factor, label
