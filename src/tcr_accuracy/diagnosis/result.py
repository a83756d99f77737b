"""What a diagnosis reads and what it finds: the observations, the shrink table and the result.

:class:`Diagnosis` holds everything :func:`tcr_accuracy.diagnosis.diagnose.diagnose` found, SI inside;
:meth:`Diagnosis.to_dict` is its JSON form (mm, unit-suffixed keys).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.context import MeasurementContext
from ..effects import make_effect, predict_positions
from .fitting import stacked
from .residuals import NoiseEstimate
from ..model.robot import RobotModel


# ---------------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------------
@dataclass
class Observations:
    """Measurements in the form the diagnosis needs (one measured frame).

    q : (N, n_joints) commanded joint values [rad, m]
    position : (N, 3) measured position in the tracker frame [m]
    context : MeasurementContext (payload, temperature, directions, other joints)
    measured : names of the context fields actually measured (``payload_kg``,
        ``temperature_c``, ``direction``)
    quaternion : (N, 4) measured orientation (w, x, y, z) in the tracker frame, or None
    """

    q: np.ndarray
    position: np.ndarray
    context: MeasurementContext
    measured: tuple = ()
    quaternion: np.ndarray | None = None
    session_labels: tuple = ()  # the sessions' labels (context.session numbers them); () for one session

    def __len__(self) -> int:
        return self.q.shape[0]


def observations_from(measurements) -> Observations:
    """Adapter from :class:`tcr_accuracy.io.measurements.MeasurementSet` (or Observations)."""
    if isinstance(measurements, Observations):
        return measurements
    measured = tuple(k for k in ("payload_kg", "temperature_c", "direction")
                     if getattr(measurements, k, None) is not None)
    return Observations(np.asarray(measurements.q, dtype=float), np.asarray(measurements.position, dtype=float),
                        measurements.context, measured, getattr(measurements, "quaternion", None),
                        tuple(getattr(measurements, "session_labels", ()) or ()))


# ---------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ErrorStats:
    """Mean, RMS and max of position error norms [m], over ``count`` measured points."""

    mean: float
    rms: float
    max: float
    count: int

    @staticmethod
    def of(errors: np.ndarray) -> "ErrorStats":
        norm = np.linalg.norm(stacked(errors), axis=1)
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
    #: (gain, low, high) [m]: how much this step lowers the held-out RMS, with its 95 % interval
    gain: tuple | None = None

    def to_dict(self) -> dict:
        out = {"effect": self.effect, "effects": list(self.effects), "n_parameters": self.n_parameters,
               "train_rms_mm": self.train_rms * 1e3, "heldout_rms_mm": self.heldout.rms * 1e3,
               "heldout_mean_mm": self.heldout.mean * 1e3, "heldout_max_mm": self.heldout.max * 1e3,
               "z_vs_previous": self.z_statistic}
        if self.gain is not None:
            out["gain_heldout_rms_mm"] = self.gain[0] * 1e3
            out["gain_interval_mm"] = [self.gain[1] * 1e3, self.gain[2] * 1e3]
        return out


@dataclass(repr=False)
class Diagnosis:
    """Everything :func:`diagnose` found. Lengths in m inside; :meth:`to_dict` gives mm.

    Units: every number and array attribute is SI (``gap``, ``steps``, ``noise_floor``,
    ``tracker_noise``, the residuals are in m). The dict attributes that are already the
    JSON form (``where_mm``, ``candidates``, ``leave_one_out``, ``scatter``, ``structure``,
    ``sessions``, ``drift``) carry the unit in every key (``rms_mm``, ``gain_mm``).
    :meth:`summary` is the text ``tcr-accuracy diagnose`` prints.

    Arrays of the residual (``gap_residual``, ``final_residual``, ``heldout_residual``),
    ``q`` and ``nominal_position`` are those of the first measured frame; with several,
    ``frames_measured`` names them and ``heldout_by_frame`` gives each one's figures.
    """

    robot_name: str
    n_measurements: int
    folds: int
    gap: ErrorStats  # after fitting the frames [m]
    where_mm: dict  # where the gap lies, JSON form (keys suffixed with their unit, mostly _mm)
    identifiability: dict
    candidates: dict  # effect -> first-step held-out result or why it was not tried
    steps: list
    selected_effects: list
    primary_effect: str | None
    leave_one_out: list
    noise_floor: float  # RMS norm of the measurement noise [m]
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
    effect_parameters: dict = field(default_factory=dict)  # effect -> full (k,) vector [SI], first frame
    registration: tuple = (np.eye(3), np.zeros(3))  # (R, t): tracker = R robot + t
    noise: NoiseEstimate | None = None
    frames_measured: list = field(default_factory=list)
    heldout_by_frame: dict = field(default_factory=dict)
    orientation: dict = field(default_factory=dict)
    ambiguous: list = field(default_factory=list)  # groups of effects the data cannot tell apart
    swaps: list = field(default_factory=list)  # one-standard-error swaps made after forward selection
    primary_group: list = field(default_factory=list)  # the primary effect and what stands in for it
    primary_tied: list = field(default_factory=list)  # the largest own share and those not ranked below it
    second_order: dict = field(default_factory=dict)  # what one fixed-point step of the deflections adds
    parameter_table: dict = field(default_factory=dict)  # effect -> values, std, interval, range, pinned [SI]
    selection: dict = field(default_factory=dict)  # how often each effect is chosen over bootstrap replays
    outside_physics: list = field(default_factory=list)  # what the data fit only outside an effect's physics
    physics: dict = field(default_factory=dict)  # effect -> why its parameters lie in their range
    effect_options: dict = field(default_factory=dict)  # effect -> the options it was fitted with
    sessions: list = field(default_factory=list)  # per session: label, rows, gap and held-out stats, temperature
    drift: list = field(default_factory=list)  # per session: the tracker's drift seen by base references
    #: effect -> joint -> {"angle_rad", "value_rad", "std_rad"} (M,) arrays: the fitted function of
    #: each joint's own angle over its measured range with its standard error (effects with joint_basis)
    joint_function_bands: dict = field(default_factory=dict)
    joint_names: list = field(default_factory=list)  # the robot's joints, in q's column order
    source: str = ""  # where the measurements came from (file names)

    @property
    def where(self) -> dict:
        """Deprecated alias of :attr:`where_mm` (until 0.2): the name now says its unit."""
        return self.where_mm

    def __repr__(self) -> str:
        last = self.steps[-1].heldout.rms if self.steps else float("nan")
        return (f"Diagnosis({self.robot_name!r}, {self.n_measurements} measurements, "
                f"gap RMS {self.gap.rms * 1e3:.4g} mm, selected [{', '.join(self.selected_effects)}], "
                f"primary {self.primary_effect!r}, held-out RMS {last * 1e3:.4g} mm, "
                f"noise floor {self.noise_floor * 1e3:.4g} mm)")

    def summary(self, source: str | None = None) -> str:
        """The summary ``tcr-accuracy diagnose`` prints (mm and deg, labelled).

        Parameters
        ----------
        source : str, default=None
            What the first line names as the measurements; None: :attr:`source`.

        Returns
        -------
        str
            Several lines, in the order gap, where, which effect, how far it shrinks.
        """
        from .summary import format_summary

        return format_summary(None, self, self.source if source is None else source)

    def predict(self, robot: RobotModel, q: np.ndarray, context: MeasurementContext | None = None) -> np.ndarray:
        """TCP positions (N, 3) in the tracker frame [m] that the fitted model predicts
        (the first measured frame's robot)."""
        effects = [make_effect(e, robot, **self.effect_options.get(e, {})) for e in self.effect_parameters]
        position = predict_positions(robot, effects, list(self.effect_parameters.values()), q, context)
        rot, trans = self.registration
        return position @ rot.T + trans

    @property
    def structure_remains(self) -> bool:
        return bool(self.structure.get("remains", False))

    def to_dict(self, robot: RobotModel | None = None) -> dict:
        """JSON form (mm, unit-suffixed keys). With the robot, also ``effect_parameters``: every
        effect's full parameter vector by name [SI] (the first measured frame's chain), what
        ``tcr-accuracy export`` rebuilds the fitted model from."""
        last = self.steps[-1]
        out = {
            "robot": self.robot_name,
            "n_measurements": self.n_measurements,
            "folds": self.folds,
            "gap": self.gap.to_dict(),
            "where": self.where_mm,
            "identifiability": self.identifiability,
            "candidates": self.candidates,
            "steps": [s.to_dict() for s in self.steps],
            "selected_effects": list(self.selected_effects),
            "primary_effect": self.primary_effect,
            "primary_group": list(self.primary_group),
            "primary_tied": list(self.primary_tied),
            "ambiguous": self.ambiguous,
            "swaps": self.swaps,
            "second_order": self.second_order,
            "leave_one_out": self.leave_one_out,
            "backward_eliminated": self.eliminated,
            "noise_floor_mm": self.noise_floor * 1e3,
            "tracker_noise_mm": self.tracker_noise * 1e3,
            "noise": self.noise.to_dict() if self.noise is not None else None,
            "final_heldout_rms_mm": last.heldout.rms * 1e3,
            "final_over_noise": last.heldout.rms / self.noise_floor if self.noise_floor > 0 else None,
            "extra_scatter": self.scatter,
            "structure_remains": self.structure_remains,
            "structure_verdict": self.structure.get("verdict"),
            "structure": self.structure,
            "parameters": {e: {k: float(v) for k, v in p.items()} for e, p in self.parameters.items()},
            "parameter_std": {e: {k: (v if np.isfinite(v) else None) for k, v in t["std"].items()}
                              for e, t in self.parameter_table.items()},
            "parameter_interval_95": {e: dict(t["interval"]) for e, t in self.parameter_table.items()},
            "parameter_units": self.parameter_units,
            "physical": {e: {"plausible": e not in {f["effect"] for f in self.outside_physics},
                             "range": dict(t["range"]), "pinned": list(t["pinned"]),
                             "reason": self.physics.get(e, "")}
                         for e, t in self.parameter_table.items()},
            "outside_physics": list(self.outside_physics),
            "sessions": list(self.sessions),
            "drift": list(self.drift),
            "effect_options": {e: {k: (v.tolist() if isinstance(v, np.ndarray) else
                                       list(v) if isinstance(v, tuple) else v) for k, v in o.items()}
                               for e, o in self.effect_options.items()},
            "joint_functions": {e: {j: {k: np.asarray(v).tolist() for k, v in band.items()}
                                    for j, band in joints.items()}
                                for e, joints in self.joint_function_bands.items()},
            "selection_frequency": dict(self.selection.get("frequency", {})),
            "selection": {k: v for k, v in self.selection.items() if k != "frequency"},
            "tracker_transform": self.tracker_transform.tolist(),
            "notes": list(self.notes),
            "n_fits": self.n_fits,
            "contribution_mm": {e: v * 1e3 for e, v in self.contribution.items()},
        }
        if robot is not None:
            out["effect_parameters"] = {
                e: dict(zip(make_effect(e, robot, **self.effect_options.get(e, {})).parameter_names(),
                            (float(v) for v in vector)))
                for e, vector in self.effect_parameters.items()}
            out["effect_parameters_units"] = "SI (m, rad, rad/Nm, m/N, 1/K)"
        if len(self.frames_measured) > 1:
            out["frames_measured"] = list(self.frames_measured)
            out["heldout_by_frame"] = {f: s.to_dict() for f, s in self.heldout_by_frame.items()}
        if self.orientation:
            out["orientation"] = self.orientation
        return out
