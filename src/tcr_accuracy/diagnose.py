"""Sim-to-real gap diagnosis: how big the gap is, where it lies, which unmodelled effect
causes it, and how far it shrinks once that effect is in the model.

The input is a set of measurements of the real robot (commanded joint values, TCP
position measured by a laser tracker in the tracker's own frame, optional context);
the nominal model is a :class:`~tcr_accuracy.robot.RobotModel`. Steps:

1. **Gap.** The tracker frame is registered to the robot's base (closed-form Kabsch
   on nominal vs measured positions, scipy's ``Rotation.align_vectors``), then the
   ``frames`` effect (base twist and TCP offset) is fitted; the remaining TCP error is
   the gap.
2. **Where.** That residual per axis, per workspace region, against each joint value,
   gravity torque (Pinocchio's generalized gravity), payload, temperature and approach
   direction, and per-joint semivariograms (:mod:`tcr_accuracy.semivariogram`).
3. **Which effect.** Every effect of :mod:`tcr_accuracy.effects` is a parametric model
   on top of the nominal kinematics. Its parameters map linearly (checked) onto joint
   offsets ``dq`` and error-screw vectors ``x`` for each pose; the identification
   Jacobian is Pinocchio's error Jacobian (``kinematics.error_jacobians``, taken at the
   frames-only fit) chained with that map. Identifiability, for every candidate model:
   columns at the parameters' typical scales are taken effect by effect in vocabulary
   order, each block projected off the columns already kept and reduced by QR with
   column pivoting (as FIGAROH does); a column whose own part moves the TCP less than a
   tenth of the tracker noise is named and removed, with the parameters it duplicates.
   Fits are nonlinear least squares (scipy ``least_squares``, exact batched forward
   kinematics as residual, the chained Jacobian as ``jac``) after one Gauss-Newton step
   from a warm start. Effects enter by forward selection on k-fold held-out error only
   when a one-sided paired test on the per-measurement held-out squared errors gives
   z > ``selection_z``; backward elimination then drops any chosen effect whose removal
   no longer costs held-out error by the same test. The primary effect is the chosen one
   whose removal raises the held-out RMS most (leave-one-out table).
4. **How far it shrinks.** Held-out mean/RMS/max after each step, the leave-one-out
   table over the chosen set, the final residual next to the noise floor, whether
   spatial structure remains in joint space (k-NN prediction of the residual against a
   permutation null) and whether there is random scatter beyond the tracker noise
   (chi-square test), which is how stochastic effects (``clearance``) show up.

All lengths are SI (m) inside; :meth:`Diagnosis.to_dict` converts to mm with unit
suffixed keys. Nothing here prints or plots.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from scipy import linalg, stats
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .context import CONTEXT_FIELDS, MeasurementContext
from .effects import effect_class, make_effect, predict_positions, vocabulary
from .errors import ErrorModel
from .exceptions import AnalysisError, InputError
from .gravity import gravity_torque
from .kinematics import error_jacobians, tcp_poses
from .robot import JointLimitWarning, RobotModel
from .semivariogram import empirical_semivariogram, fit_gaussian_variogram, per_joint_semivariograms, standardize


# ---------------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------------
@dataclass
class Observations:
    """Measurements in the form the diagnosis needs.

    q : (N, n_joints) commanded joint values [rad, m]
    position : (N, 3) measured TCP position in the tracker frame [m]
    context : MeasurementContext (payload, temperature, directions; defaults where absent)
    measured : names of the context columns actually measured (``payload_kg``,
        ``temperature_c``, ``direction``)
    """

    q: np.ndarray
    position: np.ndarray
    context: MeasurementContext
    measured: tuple = ()

    def __len__(self) -> int:
        return self.q.shape[0]


def observations_from(measurements) -> Observations:
    """Adapter from :class:`tcr_accuracy.measurements.MeasurementSet` (or Observations)."""
    if isinstance(measurements, Observations):
        return measurements
    measured = tuple(k for k in ("payload_kg", "temperature_c", "direction")
                     if getattr(measurements, k, None) is not None)
    return Observations(np.asarray(measurements.q, dtype=float), np.asarray(measurements.position, dtype=float),
                        measurements.context(), measured)


# ---------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ErrorStats:
    """Mean, RMS and max of TCP position error norms [m], over ``count`` measurements."""

    mean: float
    rms: float
    max: float
    count: int

    @staticmethod
    def of(errors: np.ndarray) -> "ErrorStats":
        norm = np.linalg.norm(errors, axis=1)
        return ErrorStats(float(norm.mean()), float(np.sqrt(np.mean(norm**2))), float(norm.max()), int(norm.size))

    def to_dict(self) -> dict:
        return {"mean_mm": self.mean * 1e3, "rms_mm": self.rms * 1e3, "max_mm": self.max * 1e3, "count": self.count}


@dataclass(frozen=True)
class Step:
    """One row of the shrink table: the model after adding ``effect``."""

    effect: str
    effects: tuple
    n_parameters: int
    train_rms: float
    heldout: ErrorStats
    z_statistic: float | None  # paired test against the previous step (None for frames)

    def to_dict(self) -> dict:
        return {"effect": self.effect, "effects": list(self.effects), "n_parameters": self.n_parameters,
                "train_rms_mm": self.train_rms * 1e3, "heldout_rms_mm": self.heldout.rms * 1e3,
                "heldout_mean_mm": self.heldout.mean * 1e3, "heldout_max_mm": self.heldout.max * 1e3,
                "z_vs_previous": self.z_statistic}


@dataclass
class Diagnosis:
    """Everything :func:`diagnose` found. Lengths in m inside; :meth:`to_dict` gives mm."""

    robot_name: str
    n_measurements: int
    folds: int
    gap: ErrorStats
    where: dict
    identifiability: dict
    candidates: dict  # effect -> first-step held-out result or why it was not tried
    steps: list
    selected_effects: list
    primary_effect: str | None
    leave_one_out: list
    noise_floor: float  # RMS norm of the tracker noise [m]
    tracker_noise: float  # per-axis std [m]
    scatter: dict
    structure: dict
    parameters: dict  # effect -> {name: value SI}
    parameter_units: dict
    as_built_x: np.ndarray
    tracker_transform: np.ndarray  # (4, 4) robot base -> tracker
    final_residual: np.ndarray  # (N, 3) in-sample residual of the final model [m]
    heldout_residual: np.ndarray  # (N, 3) out-of-fold residual of the final model [m]
    gap_residual: np.ndarray  # (N, 3) residual after frames only [m]
    q: np.ndarray
    nominal_position: np.ndarray
    gravity_torque: np.ndarray
    notes: list
    semivariograms: list = field(default_factory=list)
    eliminated: list = field(default_factory=list)
    n_fits: int = 0
    contribution: dict = field(default_factory=dict)  # effect -> RMS TCP motion of its fit beyond frames [m]
    effect_parameters: dict = field(default_factory=dict)  # effect -> full (k,) vector [SI]
    registration: tuple = (np.eye(3), np.zeros(3))  # (R, t): tracker = R robot + t

    def predict(self, robot: RobotModel, q: np.ndarray, context: MeasurementContext | None = None) -> np.ndarray:
        """TCP positions (N, 3) in the tracker frame [m] that the fitted model predicts."""
        effects = [make_effect(e, robot) for e in self.effect_parameters]
        position = predict_positions(robot, effects, list(self.effect_parameters.values()), q, context)
        rot, trans = self.registration
        return position @ rot.T + trans

    @property
    def structure_remains(self) -> bool:
        return bool(self.structure.get("remains", False))

    def to_dict(self) -> dict:
        last = self.steps[-1]
        return {
            "robot": self.robot_name,
            "n_measurements": self.n_measurements,
            "folds": self.folds,
            "gap": self.gap.to_dict(),
            "where": self.where,
            "identifiability": self.identifiability,
            "candidates": self.candidates,
            "steps": [s.to_dict() for s in self.steps],
            "selected_effects": list(self.selected_effects),
            "primary_effect": self.primary_effect,
            "leave_one_out": self.leave_one_out,
            "backward_eliminated": self.eliminated,
            "noise_floor_mm": self.noise_floor * 1e3,
            "tracker_noise_mm": self.tracker_noise * 1e3,
            "final_heldout_rms_mm": last.heldout.rms * 1e3,
            "final_over_noise": last.heldout.rms / self.noise_floor if self.noise_floor > 0 else None,
            "extra_scatter": self.scatter,
            "structure_remains": self.structure_remains,
            "structure": self.structure,
            "parameters": {e: {k: float(v) for k, v in p.items()} for e, p in self.parameters.items()},
            "parameter_units": self.parameter_units,
            "tracker_transform": self.tracker_transform.tolist(),
            "notes": list(self.notes),
            "n_fits": self.n_fits,
            "contribution_mm": {e: v * 1e3 for e, v in self.contribution.items()},
        }


# ---------------------------------------------------------------------------------------
# Effects as linear maps onto (x, dq) per pose
# ---------------------------------------------------------------------------------------
class _EffectBasis:
    """One effect, linearised: x_total(theta) = basis @ theta per pose.

    ``basis`` has shape (N, p_em, P): error-vector columns for every parameter, with
    joint-side offsets dq placed in the drive slice (``q + dq`` is a drive offset).
    ``g`` (N, 3, P) is the TCP position sensitivity (error Jacobian chained with it).
    """

    def __init__(self, effect, em: ErrorModel, obs: Observations, jac_x: np.ndarray):
        self.effect = effect
        self.name = effect.name
        self.names = list(effect.parameter_names())
        self.scales = np.asarray(effect.parameter_scales(), dtype=float)
        self.units = list(effect.parameter_units())
        n, k = len(obs), len(self.names)
        maps = effect.parameter_jacobian(np.zeros(k), obs.q, obs.context)
        basis = np.zeros((n, em.size, k))
        if maps.x is not None:
            basis += maps.x if maps.x.ndim == 3 else maps.x[None]
        if maps.dq is not None:
            basis[:, em.drive_slice, :] += maps.dq
        self.basis = basis
        self.relinearise(jac_x)
        # linear effects only: check perturb against the map at one point
        probe = self.scales * np.linspace(-1.0, 1.0, k) if k > 1 else self.scales
        out = effect.perturb(probe, obs.q, obs.context)
        total = np.zeros((n, em.size))
        if out.x is not None:
            total += out.x
        if out.dq is not None:
            total[:, em.drive_slice] += out.dq
        size = max(float(np.abs(total).max()), 1e-300)
        self.nonlinearity = float(np.abs(total - basis @ probe).max() / size)

    def relinearise(self, jac_x: np.ndarray) -> None:
        """TCP sensitivity (N, 3, P) for error Jacobians jac_x (N, 3, p_em)."""
        self.g = np.einsum("nip,npk->nik", jac_x, self.basis)


def _instantiate_effects(robot: RobotModel, names):
    """Adapter over :mod:`tcr_accuracy.effects`: effect objects by name."""
    return [make_effect(name, robot) for name in names]


# ---------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------
def _position_jacobians(robot: RobotModel, q: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
    """Error Jacobians (N, 3, p_em) of the TCP position at error vector x (Pinocchio)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", JointLimitWarning)
        _, jx = error_jacobians(robot, q, x)
    return np.ascontiguousarray(jx[:, :3])


def _register(nominal: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t with measured ~ R nominal + t (Kabsch, scipy)."""
    mn, mm = nominal.mean(axis=0), measured.mean(axis=0)
    rot, _ = Rotation.align_vectors(measured - mm, nominal - mn)
    r = rot.as_matrix()
    return r, mm - r @ mn


# ---------------------------------------------------------------------------------------
# The fitting engine
# ---------------------------------------------------------------------------------------
class _Engine:
    """Linearised effects over one data set; fits and k-fold held-out errors."""

    def __init__(self, robot, em, q, target, bases, folds, rank_tol=1e-6, min_motion=0.0):
        self.robot, self.em, self.q, self.target = robot, em, q, target
        self.bases = bases  # name -> _EffectBasis
        self.folds = folds  # list of (train, test)
        self.rank_tol, self.min_motion = rank_tol, min_motion
        self._full_cache: dict = {}
        self._keep_cache: dict = {}
        self._last: dict = {}  # effect -> last fitted full-length scaled parameters
        self.n_fits = 0

    def identify(self, effects) -> tuple[dict, dict]:
        """Identifiable columns of each effect *within this set* (vocabulary order), and the report.

        Per set, not once for the whole vocabulary: an effect that is not in the model
        must not take columns away from one that is (sin q of transmission against s q of
        encoder_scale, say).
        """
        key = tuple(effects)
        if key not in self._keep_cache:
            # vocabulary convention: geometry is what frames and joint offsets cannot
            # express, so joint-axis rotations stay joint offsets even when joint_offsets
            # is not (yet) in the model
            order = list(effects)
            borrowed = "geometry" in order and "joint_offsets" not in order and "joint_offsets" in self.bases
            if borrowed:
                order = _ordered(order + ["joint_offsets"])
            keep, report = identifiability({e: self.bases[e] for e in order}, order, self.rank_tol,
                                           self.min_motion)
            if borrowed:
                keep.pop("joint_offsets")
                report["effects"].pop("joint_offsets")
                report["note"] = "geometry excludes rotations about the joint axes (the joint_offsets effect)"
                cols = [(self.bases[e].g * self.bases[e].scales)[:, :, keep[e]].reshape(-1, keep[e].size)
                        for e in effects]
                mat = np.concatenate(cols, axis=1)
                mat = mat / np.linalg.norm(mat, axis=0)
                sv = np.linalg.svd(mat, compute_uv=False)
                report["rank"] = int(mat.shape[1])
                report["condition_number"] = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
                report["smallest_singular_value"] = float(sv[-1])
            self._keep_cache[key] = (keep, report)
        return self._keep_cache[key]

    def columns(self, effects):
        keep = self.identify(effects)[0]
        basis = np.concatenate([self.bases[e].basis[:, :, keep[e]] for e in effects], axis=2)
        g = np.concatenate([self.bases[e].g[:, :, keep[e]] for e in effects], axis=2)
        scale = np.concatenate([self.bases[e].scales[keep[e]] for e in effects])
        return basis, g, scale

    def predict(self, basis, theta, rows):
        x = basis[rows] @ theta
        return tcp_poses(self.robot, self.q[rows], x, self.em).position

    def fit(self, basis, g, scale, rows, start=None):
        """Scaled parameters phi (theta = phi * scale) minimising the position residual on rows."""
        self.n_fits += 1
        b, gr, target, q = basis[rows], g[rows] * scale, self.target[rows], self.q[rows]
        jac = gr.reshape(-1, gr.shape[2])
        bs = b * scale

        def residual(phi):
            return (tcp_poses(self.robot, q, bs @ phi, self.em).position - target).ravel()

        if start is None:
            start = np.zeros(jac.shape[1])
        # one Gauss-Newton step from the warm start: the model is nearly linear, so this
        # lands next to the optimum and least_squares only polishes
        r0 = residual(start)
        step = start + np.linalg.lstsq(jac, -r0, rcond=None)[0]
        if np.sum(residual(step) ** 2) < np.sum(r0**2):
            start = step
        fit = least_squares(residual, start, jac=lambda phi: jac, method="lm", x_scale="jac", xtol=1e-7, ftol=1e-7,
                            max_nfev=30)
        return fit.x, fit.fun.reshape(-1, 3)

    def evaluate(self, effects):
        """Full-data fit and k-fold out-of-fold residuals for a set of effects."""
        key = tuple(effects)
        if key in self._full_cache:
            return self._full_cache[key]
        basis, g, scale = self.columns(effects)
        every = np.arange(self.q.shape[0])
        keep = self.identify(effects)[0]
        # warm start: each effect's last fitted values, zeros for an effect new to the model
        start = np.concatenate([self._last.get(e, np.zeros(len(self.bases[e].names)))[keep[e]] for e in effects])
        phi, train_res = self.fit(basis, g, scale, every, start=start)
        offset = 0
        for e in effects:
            full = np.zeros(len(self.bases[e].names))
            full[keep[e]] = phi[offset:offset + keep[e].size]
            self._last[e] = full
            offset += keep[e].size
        oof = np.empty_like(self.target)
        for train, test in self.folds:
            phi_k, _ = self.fit(basis, g, scale, train, start=phi)
            oof[test] = self.predict(basis, phi_k * scale, test) - self.target[test]
        result = {"phi": phi, "scale": scale, "train_residual": train_res, "heldout_residual": oof,
                  "n_parameters": int(scale.size), "keep": keep}
        self._full_cache[key] = result
        return result


def _paired_z(before: np.ndarray, after: np.ndarray) -> float:
    """z of the mean cut in per-measurement squared held-out errors (one-sided, paired)."""
    d = np.sum(before**2, axis=1) - np.sum(after**2, axis=1)
    sd = d.std(ddof=1)
    if sd == 0:
        return 0.0 if d.mean() == 0 else math.copysign(math.inf, d.mean())
    return float(d.mean() / (sd / math.sqrt(d.size)))


# ---------------------------------------------------------------------------------------
# Identifiability
# ---------------------------------------------------------------------------------------
def identifiability(bases: dict, order, rank_tol: float = 1e-6, min_motion: float = 0.0) -> tuple[dict, dict]:
    """Kept columns per effect and a report of what was removed and why.

    Each parameter's column of the identification Jacobian (N poses x 3 rows) is taken
    at the parameter's typical scale, so its RMS norm over the poses is the TCP motion
    that parameter causes at its typical size. Effects are taken in ``order``; each
    block is projected off the span already kept and reduced by QR with column pivoting
    (as FIGAROH does): the pivot is the motion of the part of the column that no earlier
    column explains. A column is unidentifiable when that independent motion is below
    ``min_motion`` [m RMS] (the measurements cannot resolve it) or below ``rank_tol``
    times the column's own motion (a numerical duplicate).
    """
    kept_q = None  # orthonormal basis of the kept span, (3N, r)
    kept_cols, kept_names = [], []  # normalised kept columns and names, for naming duplicates
    keep: dict = {}
    report: dict = {"rank_tol": rank_tol, "min_motion_mm": min_motion * 1e3, "effects": {}}
    for name in order:
        b = bases[name]
        n_pose = max(b.g.shape[0], 1)
        cols = (b.g * b.scales).reshape(-1, len(b.names))
        norms = np.linalg.norm(cols, axis=0)
        proj = cols if kept_q is None else cols - kept_q @ (kept_q.T @ cols)
        removed, kept_local = [], []
        qmat, rmat, piv = linalg.qr(proj, mode="economic", pivoting=True)
        diag = np.abs(np.diag(rmat))
        independent = np.zeros(len(b.names))
        independent[piv[:diag.size]] = diag
        rank = 0
        for k in range(diag.size):
            col = piv[k]
            if diag[k] / math.sqrt(n_pose) > min_motion and diag[k] > rank_tol * norms[col]:
                rank += 1
            else:
                break
        kept_local = sorted(piv[:rank].tolist())
        unit_all = cols / np.where(norms > 0, norms, 1.0)
        mat = np.stack(kept_cols + [unit_all[:, k] for k in kept_local], axis=1) if (kept_cols or kept_local) \
            else np.zeros((cols.shape[0], 0))
        span_names = kept_names + [b.names[k] for k in kept_local]
        for k in piv[rank:]:
            motion = norms[k] / math.sqrt(n_pose)
            if motion < 1e-12:
                removed.append({"parameter": b.names[k], "reason": "does not move the TCP position",
                                "duplicates": []})
                continue
            dup = []
            if mat.shape[1]:
                coef = np.linalg.lstsq(mat, unit_all[:, k], rcond=None)[0]
                dup = [span_names[t] for t in np.argsort(-np.abs(coef))[:3] if abs(coef[t]) > 1e-2]
            free = independent[k] / math.sqrt(n_pose)
            if free < 1e-3 * motion and dup:
                reason = "linear combination of " + ", ".join(dup)
            else:
                reason = (f"only {free * 1e6:.3g} um RMS of its {motion * 1e6:.3g} um TCP motion (at its typical "
                          f"size) is its own: below what the measurements resolve"
                          + (f"; the rest duplicates {', '.join(dup)}" if dup else ""))
            removed.append({"parameter": b.names[k], "reason": reason, "duplicates": dup})
        if rank:
            new_q = qmat[:, :rank]
            kept_q = new_q if kept_q is None else np.hstack([kept_q, new_q])
            kept_cols += [unit_all[:, k] for k in kept_local]
            kept_names += [b.names[k] for k in kept_local]
        keep[name] = np.asarray(kept_local, dtype=int)
        report["effects"][name] = {"n_parameters": len(b.names), "n_identifiable": len(kept_local),
                                   "removed": removed}
    if kept_cols:
        mat = np.stack(kept_cols, axis=1)
        sv = np.linalg.svd(mat, compute_uv=False)
        report["rank"] = int(mat.shape[1])
        report["condition_number"] = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
        report["smallest_singular_value"] = float(sv[-1])
    return keep, report


# ---------------------------------------------------------------------------------------
# Where the gap lies
# ---------------------------------------------------------------------------------------
def _binned(values: np.ndarray, residual: np.ndarray, n_bins: int = 5) -> dict:
    """Quantile bins of values (N,): count, mean residual vector and RMS norm per bin [mm]."""
    finite = np.isfinite(values)
    levels = np.unique(values[finite])
    if levels.size <= n_bins:  # a few distinct values (payload on/off): one bin each
        if levels.size < 2:
            return {"bins": [], "spread_mm": 0.0}
        edges = None
        which = np.searchsorted(levels, values)
    else:
        edges = np.unique(np.quantile(values[finite], np.linspace(0, 1, n_bins + 1)))
        which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, edges.size - 2)
    bins = []
    n_out = levels.size if edges is None else edges.size - 1
    for b in range(n_out):
        sel = which == b
        if not sel.any():
            continue
        r = residual[sel]
        low, high = (levels[b], levels[b]) if edges is None else (edges[b], edges[b + 1])
        bins.append({"low": float(low), "high": float(high), "count": int(sel.sum()),
                     "mean_mm": (r.mean(axis=0) * 1e3).tolist(),
                     "rms_mm": float(np.sqrt(np.mean(np.sum(r**2, axis=1))) * 1e3)})
    means = np.array([b["mean_mm"] for b in bins])
    spread = float(np.linalg.norm(means.max(axis=0) - means.min(axis=0))) if len(bins) > 1 else 0.0
    return {"bins": bins, "spread_mm": spread}


def _correlations(values: np.ndarray, residual: np.ndarray) -> list:
    out = []
    for c in range(3):
        if np.std(values) == 0 or np.std(residual[:, c]) == 0:
            out.append(0.0)
        else:
            out.append(float(np.corrcoef(values, residual[:, c])[0, 1]))
    return out


def where_analysis(robot: RobotModel, q: np.ndarray, nominal: np.ndarray, residual: np.ndarray,
                   tau: np.ndarray, context: dict, n_bins: int = 5, rng=None):
    """Breakdown of the residual (N, 3) [m]; returns (JSON-able dict, semivariograms)."""
    norm = np.linalg.norm(residual, axis=1)
    where: dict = {}
    where["per_axis"] = {ax: {"mean_mm": float(residual[:, c].mean() * 1e3),
                              "rms_mm": float(np.sqrt(np.mean(residual[:, c] ** 2)) * 1e3),
                              "max_abs_mm": float(np.abs(residual[:, c]).max() * 1e3)}
                         for c, ax in enumerate("xyz")}
    centre = np.median(nominal, axis=0)
    octant = ((nominal - centre) > 0).astype(int) @ np.array([4, 2, 1])
    regions = []
    for o in range(8):
        sel = octant == o
        if sel.any():
            label = "".join(("+" if (o >> (2 - c)) & 1 else "-") + "xyz"[c] for c in range(3))
            regions.append({"region": label, "count": int(sel.sum()),
                            "mean_mm": float(norm[sel].mean() * 1e3),
                            "rms_mm": float(np.sqrt(np.mean(norm[sel] ** 2)) * 1e3)})
    where["octants"] = {"centre_m": centre.tolist(), "regions": regions}
    where["radius"] = _binned(np.hypot(nominal[:, 0], nominal[:, 1]), residual, n_bins)
    where["height"] = _binned(nominal[:, 2], residual, n_bins)
    joints = {}
    for j, name in enumerate(robot.joint_names):
        joints[name] = {"unit": "rad" if robot.joint_kinds[j] == "revolute" else "m",
                        "correlation_xyz": _correlations(q[:, j], residual), **_binned(q[:, j], residual, n_bins)}
    where["joints"] = joints
    loaded = np.ptp(tau, axis=0) > 1e-6 * max(float(np.abs(tau).max()), 1e-300)
    where["gravity_torque"] = {name: ({"correlation_xyz": _correlations(tau[:, j], residual),
                                       **_binned(tau[:, j], residual, n_bins)} if loaded[j]
                                      else {"loaded": False})
                               for j, name in enumerate(robot.joint_names)}
    for key in ("payload_kg", "temperature_c"):
        if key in context and np.std(context[key]) > 0:
            where[key] = {"correlation_xyz": _correlations(context[key], residual),
                          **_binned(context[key], residual, n_bins)}
    if "direction" in context:
        direction = {}
        for j, name in enumerate(robot.joint_names):
            d = context["direction"][:, j]
            plus, minus = d > 0, d < 0
            if plus.any() and minus.any():
                diff = residual[plus].mean(axis=0) - residual[minus].mean(axis=0)
                direction[name] = {"count_plus": int(plus.sum()), "count_minus": int(minus.sum()),
                                   "mean_plus_minus_minus_mm": (diff * 1e3).tolist(),
                                   "difference_norm_mm": float(np.linalg.norm(diff) * 1e3)}
        where["approach_direction"] = direction
    # along which joints does the error vary? Per-joint semivariograms (standardised:
    # 1 = no similarity) at short lag, and the share of the residual variance that the
    # k nearest neighbours along that joint alone predict (out of sample: self excluded)
    from sklearn.neighbors import NearestNeighbors

    semis = per_joint_semivariograms(q, residual, n_bins=12, rng=rng)
    centred = residual - residual.mean(axis=0)
    total = float(np.sum(centred**2)) or 1.0
    along = {}
    for j, name in enumerate(robot.joint_names):
        if np.std(q[:, j]) == 0:
            continue
        s = semis[j]
        short = s.lags <= np.quantile(s.lags, 0.25)
        gamma_short = (s.semivariance[short] * s.counts[short, None]).sum(axis=0) / s.counts[short].sum()
        k = min(10, q.shape[0] - 1)
        idx = NearestNeighbors(n_neighbors=k + 1).fit(q[:, [j]]).kneighbors(q[:, [j]], return_distance=False)[:, 1:]
        share = 1.0 - float(np.sum((centred - centred[idx].mean(axis=1)) ** 2)) / total
        along[name] = {"short_lag_semivariance_xyz": gamma_short.tolist(), "knn_explained_share": share}
    where["along_joints"] = along
    where["varies_along"] = [n for n in sorted(along, key=lambda n: -along[n]["knn_explained_share"])
                             if along[n]["knn_explained_share"] > 0.05][:3]
    qs, _, _ = standardize(q)
    names = [n for n in robot.joint_names if n in along]
    pairs = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            cols = [robot.joint_names.index(names[a]), robot.joint_names.index(names[b])]
            k = min(10, q.shape[0] - 1)
            idx = NearestNeighbors(n_neighbors=k + 1).fit(qs[:, cols]).kneighbors(
                qs[:, cols], return_distance=False)[:, 1:]
            share = 1.0 - float(np.sum((centred - centred[idx].mean(axis=1)) ** 2)) / total
            pairs.append({"joints": [names[a], names[b]], "knn_explained_share": share})
    pairs.sort(key=lambda r: -r["knn_explained_share"])
    where["along_joint_pairs"] = pairs
    return where, semis


def _nugget_ratio(semi, column) -> float:
    try:
        return float(fit_gaussian_variogram(semi, column).nugget_ratio)
    except (ValueError, np.linalg.LinAlgError):
        return 1.0


# ---------------------------------------------------------------------------------------
# Structure and scatter of the final residual
# ---------------------------------------------------------------------------------------
def _smooth_features(q: np.ndarray, kinds) -> np.ndarray:
    """Smooth functions of the joints (N, F): per joint sin/cos of q and 2q (standardised
    value and its square for prismatic joints) and the pairwise products of the first
    harmonics, which is what a serial chain's kinematics is made of."""
    first, cols = [], []
    for j, kind in enumerate(kinds):
        v = q[:, j]
        if kind == "revolute":
            a = [np.sin(v), np.cos(v)]
            cols += a + [np.sin(2 * v), np.cos(2 * v)]
        else:
            z = (v - v.mean()) / (v.std() or 1.0)
            a = [z]
            cols += [z, z**2]
        first.append(a)
    for i in range(len(first)):
        for k in range(i + 1, len(first)):
            cols += [u * w for u in first[i] for w in first[k]]
    return np.stack(cols, axis=1)


def structure_test(q: np.ndarray, residual: np.ndarray, rng: np.random.Generator, kinds=None, k: int = 10,
                   n_permutations: int = 100, alpha: float = 1e-3, min_explained: float = 0.05,
                   folds: int = 5) -> dict:
    """Is the residual (N, 3) still predictable from the joint values?

    Two predictors, each judged out of sample:

    * local: each residual predicted by the mean of its k nearest neighbours in
      standardised joint space (scikit-learn), over all joints, each joint and each
      pair of joints, compared with the same statistic after shuffling residuals over
      poses (z against the permutation distribution, Bonferroni over the subsets);
    * global: ridge regression (scikit-learn ``RidgeCV``) on smooth joint features
      (:func:`_smooth_features`), k-fold cross-validated predictions, with a one-sided
      paired z-test of the cut in squared residuals.

    Structure remains when either predictor explains more than ``min_explained`` of the
    residual variance beyond chance (p < alpha, resp. z above the matching quantile).
    """
    from sklearn.linear_model import RidgeCV
    from sklearn.model_selection import KFold, cross_val_predict
    from sklearn.neighbors import NearestNeighbors
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    qs, _, _ = standardize(q)
    centred = residual - residual.mean(axis=0)
    total = np.sum(centred**2)
    # an unmodelled effect often depends on a few joints: in all of joint space 6-D
    # neighbours are far apart, along one joint or a pair they are close. Test all
    # joints, each joint and each pair; Bonferroni over the subsets.
    n_j = q.shape[1]
    moving = [j for j in range(n_j) if np.std(q[:, j]) > 0]
    subsets = [tuple(moving)] + [(j,) for j in moving]
    subsets += [(a, b) for i, a in enumerate(moving) for b in moving[i + 1:]]
    m = len(subsets)
    perms = [rng.permutation(len(centred)) for _ in range(n_permutations)]
    best = None
    for subset in subsets:
        nn = NearestNeighbors(n_neighbors=k + 1).fit(qs[:, subset])
        idx = nn.kneighbors(qs[:, subset], return_distance=False)[:, 1:]

        def explained(r, idx=idx):
            return 1.0 - np.sum((r - r[idx].mean(axis=1)) ** 2) / total

        actual = explained(centred)
        null = np.array([explained(centred[perm]) for perm in perms])
        gain = float(actual - null.mean())
        # a few hundred permutations cannot resolve small p by counting: use their spread
        z_sub = gain / max(float(null.std(ddof=1)), 1e-12)
        row = {"joints": list(subset), "explained_share": float(actual), "null_mean": float(null.mean()),
               "null_std": float(null.std(ddof=1)), "gain": gain, "z": z_sub}
        if best is None or z_sub > best["z"]:
            best = row
    z_knn = best["z"]
    gain = best["gain"]
    p_knn = float(min(1.0, stats.norm.sf(z_knn) * m))
    local = bool(p_knn < alpha and gain > min_explained)
    actual, null_mean, null_std = best["explained_share"], best["null_mean"], best["null_std"]

    kinds = kinds if kinds is not None else ["revolute"] * q.shape[1]
    features = _smooth_features(q, kinds)
    model = make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-3, 3, 13)))
    split = KFold(n_splits=folds, shuffle=True, random_state=int(rng.integers(2**31 - 1)))
    predicted = cross_val_predict(model, features, centred, cv=split)
    ridge_share = float(1.0 - np.sum((centred - predicted) ** 2) / total)
    d = np.sum(centred**2, axis=1) - np.sum((centred - predicted) ** 2, axis=1)
    z = float(d.mean() / (d.std(ddof=1) / math.sqrt(d.size))) if d.std() > 0 else 0.0
    z_crit = float(stats.norm.isf(alpha))
    global_ = bool(z > z_crit and ridge_share > min_explained)

    semi = empirical_semivariogram(q, residual, n_bins=12, rng=rng)
    ratios = [_nugget_ratio(semi, c) for c in range(3)]
    return {"statistic": "share of residual variance predicted out of sample from the joint values: "
                         "k-NN (permutation test) and ridge on smooth joint features (paired z-test)",
            "k": k, "explained_share": float(actual), "null_mean": null_mean, "null_std": null_std,
            "z": z_knn, "p_value": p_knn, "gain_over_null": gain, "n_subsets": m,
            "along_joints": best["joints"],
            "ridge_explained_share": ridge_share, "ridge_z": z, "z_critical": z_crit,
            "alpha": alpha, "min_explained": min_explained,
            "semivariogram_nugget_ratio_xyz": ratios,
            "local": local, "global": global_,
            "remains": bool(local or global_)}


def scatter_test(residual: np.ndarray, n_parameters: int, tracker_noise: float, alpha: float = 1e-3,
                 min_ratio: float = 1.1) -> dict:
    """Random scatter beyond the tracker noise (chi-square on the in-sample residual)."""
    dof = max(residual.size - n_parameters, 1)
    rss = float(np.sum(residual**2))
    sigma = math.sqrt(rss / dof)
    chi2_stat = rss / tracker_noise**2 if tracker_noise > 0 else math.inf
    p = float(stats.chi2.sf(chi2_stat, dof)) if tracker_noise > 0 else 0.0
    ratio = sigma / tracker_noise if tracker_noise > 0 else math.inf
    extra = math.sqrt(max(sigma**2 - tracker_noise**2, 0.0))
    return {"estimated_noise_per_axis_mm": sigma * 1e3, "tracker_noise_per_axis_mm": tracker_noise * 1e3,
            "ratio": ratio, "p_value": p, "extra_per_axis_mm": extra * 1e3,
            "detected": bool(p < alpha and ratio > min_ratio)}


# ---------------------------------------------------------------------------------------
# The diagnosis
# ---------------------------------------------------------------------------------------
def diagnose(robot: RobotModel, measurements, *, effects=None, folds: int = 5, seed: int = 0,
             tracker_noise: float = 2e-5, selection_z: float = 3.0, min_relative_gain: float = 0.002,
             rank_tol: float = 1e-6, progress=None) -> Diagnosis:
    """Diagnose the gap between the nominal robot and its measurements.

    Parameters
    ----------
    robot : RobotModel
        The nominal model.
    measurements : MeasurementSet or Observations
        q (N, n_joints) [rad, m], position (N, 3) [m] in the tracker frame, context.
    effects : list of str, optional
        Effects to consider (vocabulary order is used; ``frames`` is always in).
    folds : int
        k of the k-fold cross-validation (>= 2).
    seed : int
        Seeds the fold split and the permutation tests.
    tracker_noise : float
        Per-axis standard deviation of the tracker [m]; noise floor = sqrt(3) times it.
    selection_z : float
        One-sided z the paired held-out test must exceed for an effect to enter.
    min_relative_gain : float
        And the held-out RMS must drop by at least this fraction.
    rank_tol : float
        Identifiability tolerance on normalised pivots (see :func:`identifiability`).
    progress : callable(str), optional
        Called with a short message as the work advances (the CLI's progress bar).
    """
    # The least-squares problems here are small (3N x ~60): multi-threaded BLAS only adds
    # synchronisation, and on a shared machine it was 50-100x slower than one thread.
    # threadpoolctl (a scikit-learn dependency) limits it for the duration of the call.
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(robot, measurements, effects=effects, folds=folds, seed=seed,
                         tracker_noise=tracker_noise, selection_z=selection_z,
                         min_relative_gain=min_relative_gain, rank_tol=rank_tol, progress=progress)


def _diagnose(robot, measurements, *, effects, folds, seed, tracker_noise, selection_z, min_relative_gain,
              rank_tol, progress) -> Diagnosis:
    from sklearn.model_selection import KFold

    obs = observations_from(measurements)
    n = len(obs)
    say = progress or (lambda message: None)
    if folds < 2:
        raise InputError(f"--folds {folds}: need at least 2")
    if obs.q.ndim != 2 or obs.q.shape[1] != robot.n_joints:
        raise InputError(f"measurements have {obs.q.shape[-1]} joint columns, {robot.name} has {robot.n_joints}")
    if n < max(3 * folds, 12):
        raise InputError(f"{n} measurements are too few to diagnose with {folds}-fold cross-validation "
                         f"(need at least {max(3 * folds, 12)})")
    rng = np.random.default_rng(seed)
    words = vocabulary()
    names = [e for e in words if effects is None or e in effects or e == "frames"]
    if effects is not None:
        unknown = [e for e in effects if e not in words]
        if unknown:
            raise InputError(f"--effects: unknown effect(s) {', '.join(unknown)} (vocabulary: {', '.join(words)})")
    em = ErrorModel(robot)
    notes: list = []
    if getattr(measurements, "quaternion", None) is not None:
        notes.append("orientation columns were read; the fit uses the measured positions only")

    # 1. register the tracker frame, then work in the robot's base frame
    say("registering the tracker frame")
    nominal = tcp_poses(robot, obs.q).position
    rot, trans = _register(nominal, obs.position)
    target = (obs.position - trans) @ rot  # R^T (p - t), row-wise
    jac_x = _position_jacobians(robot, obs.q)
    tau = gravity_torque(robot, obs.q, obs.context.payload_kg, outside_q=obs.context.outside_q)

    # effects as linear maps, and which can be tried at all
    say("building effect models")
    bases: dict = {}
    candidates: dict = {}
    stochastic = []
    for effect in _instantiate_effects(robot, names):
        if getattr(effect, "stochastic", False):
            stochastic.append(effect.name)
            candidates[effect.name] = {"tried": False, "why": "stochastic: tested as extra scatter, not fitted"}
            continue
        missing = [c for c in effect.context_columns if c in CONTEXT_FIELDS and CONTEXT_FIELDS[c] not in obs.measured]
        if missing and effect.requires_context:
            candidates[effect.name] = {"tried": False, "why": f"needs the {', '.join(missing)} column"}
            continue
        try:
            basis = _EffectBasis(effect, em, obs, jac_x)
        except InputError as exc:
            candidates[effect.name] = {"tried": False, "why": f"not testable on these data: {exc}"}
            continue
        if basis.nonlinearity > 1e-6:
            notes.append(f"{effect.name} is nonlinear in its parameters (relative {basis.nonlinearity:.1e}); "
                         "it is fitted in its linearisation about zero")
        bases[effect.name] = basis
    if "frames" not in bases:
        raise AnalysisError("the frames effect could not be built")
    order = _ordered(bases)
    # a TCP offset of centimetres changes which directions duplicate one another:
    # linearise about the frames-only fit, not the nominal model
    frames = bases["frames"]
    pre = _Engine(robot, em, obs.q, target, {"frames": frames}, [], rank_tol=0.0)
    phi, _ = pre.fit(*pre.columns(["frames"]), np.arange(n))
    x_frames = frames.basis[0] @ (phi * frames.scales)
    jac_x = _position_jacobians(robot, obs.q, x_frames)
    for b in bases.values():
        b.relinearise(jac_x)
    kfold = KFold(n_splits=folds, shuffle=True, random_state=int(rng.integers(2**31 - 1)))
    split = [(np.asarray(a), np.asarray(b)) for a, b in kfold.split(np.arange(n))]
    engine = _Engine(robot, em, obs.q, target, bases, split, rank_tol, min_motion=0.1 * tracker_noise)
    _, ident_all = engine.identify(order)
    testable = []
    for name in order:
        if name != "frames" and engine.identify(("frames", name))[0][name].size == 0:
            candidates[name] = {"tried": False, "why": "no identifiable parameter on these data (beyond frames)"}
        elif name != "frames":
            testable.append(name)

    # 2. gap after frames
    say("fitting frames")
    current = ["frames"]
    result = engine.evaluate(current)
    gap_residual = result["train_residual"]
    gap = ErrorStats.of(gap_residual)
    steps = [Step("frames", ("frames",), result["n_parameters"], ErrorStats.of(result["train_residual"]).rms,
                  ErrorStats.of(result["heldout_residual"]), None)]

    # 3. forward selection on held-out error
    pool = list(testable)
    first_gain: dict = {}
    while pool:
        trials = {}
        for e in pool:
            say(f"step {len(steps)}: trying {e}")
            trials[e] = engine.evaluate(_ordered(current + [e]))
        prev = engine.evaluate(_ordered(current))
        prev_rms = ErrorStats.of(prev["heldout_residual"]).rms
        if len(current) == 1:
            for e, r in trials.items():
                rms = ErrorStats.of(r["heldout_residual"]).rms
                z = _paired_z(prev["heldout_residual"], r["heldout_residual"])
                first_gain[e] = prev_rms - rms
                candidates[e] = {"tried": True, "heldout_rms_mm_with_frames": rms * 1e3,
                                 "gain_mm": (prev_rms - rms) * 1e3, "z": z,
                                 "n_parameters": r["n_parameters"] - prev["n_parameters"]}
        best = min(trials, key=lambda e: ErrorStats.of(trials[e]["heldout_residual"]).rms)
        r = trials[best]
        rms = ErrorStats.of(r["heldout_residual"]).rms
        z = _paired_z(prev["heldout_residual"], r["heldout_residual"])
        if not (z > selection_z and rms < prev_rms * (1.0 - min_relative_gain)):
            break
        current.append(best)
        pool.remove(best)
        steps.append(Step(best, tuple(_ordered(current)), r["n_parameters"],
                          ErrorStats.of(r["train_residual"]).rms, ErrorStats.of(r["heldout_residual"]), z))
    forward_order = list(current)

    # backward elimination: an effect that no longer earns its place once the others are
    # in (e.g. a flexible one picked early that later effects explain better) goes out
    eliminated = []
    while True:
        chosen = [e for e in current if e != "frames"]
        final = engine.evaluate(_ordered(current))
        loo = []
        for e in chosen:
            say(f"leave-one-out: {e}")
            r = engine.evaluate(_ordered([s for s in current if s != e]))
            held = ErrorStats.of(r["heldout_residual"])
            final_rms = ErrorStats.of(final["heldout_residual"]).rms
            loo.append({"dropped": e, "heldout_rms_mm": held.rms * 1e3, "heldout_mean_mm": held.mean * 1e3,
                        "heldout_max_mm": held.max * 1e3, "increase_mm": (held.rms - final_rms) * 1e3,
                        "z": _paired_z(r["heldout_residual"], final["heldout_residual"])})
        weakest = min(loo, key=lambda row: row["z"]) if loo else None
        if weakest is None or weakest["z"] > selection_z:
            break
        eliminated.append({"effect": weakest["dropped"], "z": weakest["z"],
                           "increase_mm": weakest["increase_mm"]})
        current.remove(weakest["dropped"])
    selected = [e for e in forward_order if e in current]
    chosen = [e for e in selected if e != "frames"]
    # the primary effect: the one whose removal from the final model costs the most
    primary = max(loo, key=lambda row: row["increase_mm"])["dropped"] if loo else None
    if eliminated:  # rebuild the shrink table along the forward order of what stayed
        steps = steps[:1]
        for k in range(1, len(selected)):
            r = engine.evaluate(_ordered(selected[:k + 1]))
            p_ = engine.evaluate(_ordered(selected[:k]))
            steps.append(Step(selected[k], tuple(_ordered(selected[:k + 1])), r["n_parameters"],
                              ErrorStats.of(r["train_residual"]).rms, ErrorStats.of(r["heldout_residual"]),
                              _paired_z(p_["heldout_residual"], r["heldout_residual"])))
        notes.append("dropped again after forward selection (no significant held-out loss without them): "
                     + ", ".join(f"{e['effect']} (z = {e['z']:.1f})" for e in eliminated))

    # where (on the frames-only residual), structure and scatter (on the final residual)
    say("where the gap lies")
    measured = {k: np.asarray(getattr(obs.context, k), dtype=float) for k in obs.measured}
    where, semis = where_analysis(robot, obs.q, nominal, gap_residual, tau, measured, rng=rng)
    say("testing the final residual")
    structure = structure_test(obs.q, final["train_residual"], rng, kinds=robot.joint_kinds)
    scatter = scatter_test(final["train_residual"], final["n_parameters"], tracker_noise)
    if stochastic:
        scatter["stochastic_effects"] = stochastic
    if scatter["detected"] and not structure["remains"]:
        scatter["named"] = "clearance" if "clearance" in stochastic or effects is None else "random scatter"
        notes.append(f"random scatter beyond the tracker noise: {scatter['estimated_noise_per_axis_mm']:.4f} mm "
                     f"per axis vs {tracker_noise * 1e3:.4f} mm, without spatial structure: joint play "
                     "(clearance) or a noisier instrument")

    # fitted parameters, as-built geometry, tracker frame
    theta = final["phi"] * final["scale"]
    keep, ident = engine.identify(tuple(_ordered(selected)))
    ident = {**ident, "all_effects": ident_all}
    parameters, units, full_parameters = {}, {}, {}
    as_built = np.zeros(em.size)
    offset = 0
    for e in _ordered(selected):
        b = bases[e]
        full = np.zeros(len(b.names))
        full[keep[e]] = theta[offset:offset + keep[e].size]
        offset += keep[e].size
        parameters[e] = {b.names[k]: full[k] for k in keep[e]}
        full_parameters[e] = full
        units[e] = {b.names[k]: b.units[k] for k in keep[e]}
        if effect_class(e).geometric:
            as_built += b.basis[0] @ full
    # how much of the gap each chosen effect accounts for: the TCP motion its fitted
    # parameters cause, after taking out what a rigid frame change could absorb
    frames_cols = bases["frames"].g.reshape(-1, len(bases["frames"].names))
    contribution = {}
    for e in chosen:
        x_e = bases[e].basis @ full_parameters[e]
        motion = (tcp_poses(robot, obs.q, x_e, em).position - nominal).ravel()
        rigid = frames_cols @ np.linalg.lstsq(frames_cols, motion, rcond=None)[0]
        contribution[e] = float(np.sqrt(np.mean((motion - rigid) ** 2) * 3))
    base_twist = as_built[em.base_slice].copy()
    as_built[em.base_slice] = 0.0  # the base twist belongs to the tracker frame, not the robot
    tracker = np.eye(4)
    tracker[:3, :3], tracker[:3, 3] = rot, trans
    tracker = tracker @ pin.exp6(base_twist).homogeneous

    return Diagnosis(
        robot_name=robot.name, n_measurements=n, folds=folds, gap=gap, where=where, identifiability=ident,
        candidates=candidates, steps=steps, selected_effects=selected, primary_effect=primary,
        leave_one_out=loo, noise_floor=math.sqrt(3.0) * tracker_noise, tracker_noise=tracker_noise,
        scatter=scatter, structure=structure, parameters=parameters, parameter_units=units,
        as_built_x=as_built, tracker_transform=tracker, final_residual=final["train_residual"],
        heldout_residual=final["heldout_residual"], gap_residual=gap_residual, q=obs.q,
        nominal_position=nominal, gravity_torque=tau, notes=notes, semivariograms=semis,
        effect_parameters=full_parameters, registration=(rot, trans), eliminated=eliminated,
        n_fits=engine.n_fits, contribution=contribution,
    )


def _ordered(effects) -> list:
    """The effects in vocabulary order."""
    return [e for e in vocabulary() if e in effects]
