"""What a diagnosis finds: :class:`Diagnosis`, every stage's result and the views of them that
reports, plots and the JSON form read.

:class:`Diagnosis` holds each stage's typed, frozen result (:class:`DiagnosisStages`, SI units
inside) and the figures of the data it ran on; its other attributes are views of those results,
computed when read. :meth:`Diagnosis.to_dict` is the JSON form (mm, unit-suffixed keys);
``tcr_accuracy.diagnosis_summary(diagnosis)`` the printed summary.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..effects import make_effect, predict_positions
from ..model.context import MeasurementContext
from ..model.robot import RobotModel
from .records import ErrorStats, Step
from .stages.attribute import Attribution, FirstOrder
from .stages.parameters import FittedParameters
from .stages.register import RegisteredMeasurements
from .stages.residual import ResidualAnalysis
from .stages.select import Selection
from .stages.candidates import CandidateSet

__all__ = ["Diagnosis", "DiagnosisStages", "ErrorStats", "Step"]


@dataclass(frozen=True)
class DiagnosisStages:
    """Every stage's result, in the order they ran (see :mod:`tcr_accuracy.diagnosis.stages`)."""

    register: RegisteredMeasurements
    candidates: CandidateSet
    select: Selection
    attribute: Attribution
    residual: ResidualAnalysis
    parameters: FittedParameters
    first_order: FirstOrder


@dataclass(frozen=True, repr=False)
class Diagnosis:
    """Everything :func:`~tcr_accuracy.diagnosis.diagnose.diagnose` found. Lengths in m inside;
    :meth:`to_dict` gives mm.

    The stages' results are in :attr:`stages` (typed, SI). The other attributes are read-only
    views of them: numbers and arrays in SI (``gap``, ``steps``, ``noise_floor``,
    ``tracker_noise``, the residuals in m), and the JSON-form dicts the reports read, whose keys
    carry their unit (``where_mm``, ``candidates``, ``leave_one_out``, ``scatter``,
    ``structure``, ``sessions``, ``drift``: ``rms_mm``, ``gain_mm``).

    Arrays of the residual (``gap_residual``, ``final_residual``, ``heldout_residual``), ``q``
    and ``nominal_position`` are those of the first measured frame; with several,
    ``frames_measured`` names them and ``heldout_by_frame`` gives each one's figures.

    Attributes
    ----------
    robot_name : str
    n_measurements : int
    folds : int
        k of the k-fold cross-validation.
    stages : DiagnosisStages
    n_fits : int
        Least-squares fits the diagnosis ran.
    joint_names : list of str
        The robot's joints, in q's column order.
    source : str
        Where the measurements came from (file names).
    """

    robot_name: str
    n_measurements: int
    folds: int
    stages: DiagnosisStages
    n_fits: int
    joint_names: list
    source: str = ""

    # -- views of the stages -------------------------------------------------------------
    @property
    def gap(self) -> ErrorStats:
        """Errors after fitting the frames [m]."""
        return self.stages.residual.gap

    @property
    def where_mm(self) -> dict:
        """Where the gap lies (JSON form, keys suffixed with their unit, mostly _mm)."""
        return self.stages.residual.where_mm

    @property
    def where(self) -> dict:
        """Deprecated alias of :attr:`where_mm` (until 0.2): the name now says its unit."""
        return self.where_mm

    @property
    def identifiability(self) -> dict:
        return self.stages.parameters.identifiability

    @property
    def candidates(self) -> dict:
        """effect -> first-step held-out result or why it was not tried (JSON form)."""
        return {c.effect: c.to_dict() for c in self.stages.select.candidates}

    @property
    def steps(self) -> list:
        """The shrink table (:class:`Step`, SI) in the order the effects explain the data."""
        return list(self.stages.attribute.steps)

    @property
    def selected_effects(self) -> list:
        return list(self.stages.select.selected)

    @property
    def primary_effect(self) -> str | None:
        return self.stages.attribute.primary_effect

    @property
    def primary_group(self) -> list:
        """The primary effect and what stands in for it."""
        return list(self.stages.attribute.primary_group)

    @property
    def primary_tied(self) -> list:
        """The largest own share and those not ranked below it."""
        return list(self.stages.attribute.primary_tied)

    @property
    def leave_one_out(self) -> list:
        """The final model without each chosen effect (JSON form, mm): the others refitted, and held to
        their own parameters (its own share, with stage 4's 95 % interval)."""
        own = self.stages.attribute.own_shares
        return [{**r.to_dict(), **({"own_share_increase_mm": own[r.effect][0] * 1e3,
                                    "own_share_interval_mm": [own[r.effect][1] * 1e3, own[r.effect][2] * 1e3]}
                                   if r.effect in own else {})}
                for r in self.stages.select.leave_one_out]

    @property
    def eliminated(self) -> list:
        return [e.to_dict() for e in self.stages.select.eliminated]

    @property
    def swaps(self) -> list:
        """One-standard-error swaps made after forward selection."""
        return list(self.stages.select.swaps)

    @property
    def search(self) -> dict:
        """The search beyond the greedy path: sets fitted, where each path ended, the best set on
        another path and whether the chosen set beats it by more than a standard error."""
        return self.stages.select.search.to_dict()

    @property
    def ambiguous(self) -> list:
        """Groups of effects the data cannot tell apart."""
        return list(self.stages.select.ambiguous)

    @property
    def noise(self):
        """The instrument's per-axis noise [m] and where that figure came from (NoiseEstimate)."""
        return self.stages.residual.noise

    @property
    def noise_floor(self) -> float:
        """RMS norm of the measurement noise [m]."""
        return self.stages.residual.noise_floor

    @property
    def tracker_noise(self) -> float:
        """Per-axis standard deviation of the measurement noise [m]."""
        return self.stages.residual.noise.per_axis

    @property
    def scatter(self) -> dict:
        return self.stages.residual.scatter

    @property
    def structure(self) -> dict:
        return self.stages.residual.structure

    @property
    def parameters(self) -> dict:
        """effect -> {name: value SI} (identifiable parameters)."""
        return self.stages.parameters.values

    @property
    def parameter_units(self) -> dict:
        return self.stages.parameters.units

    @property
    def parameter_table(self) -> dict:
        """effect -> values, std, interval, range, pinned [SI]."""
        return self.stages.parameters.table

    @property
    def effect_parameters(self) -> dict:
        """effect -> full (k,) vector [SI], first measured frame."""
        return self.stages.parameters.full_vectors

    @property
    def effect_options(self) -> dict:
        return self.stages.parameters.effect_options

    @property
    def physics(self) -> dict:
        """effect -> why its parameters lie in their range."""
        return self.stages.parameters.physics

    @property
    def joint_function_bands(self) -> dict:
        """effect -> joint -> {"angle_rad", "value_rad", "std_rad"} (M,) arrays: the fitted
        function of each joint's own angle with its standard error (effects with joint_basis)."""
        return self.stages.parameters.joint_function_bands

    @property
    def as_built_x(self) -> np.ndarray:
        return self.stages.parameters.as_built_x

    @property
    def trackerMbase(self) -> np.ndarray:
        """(4, 4) the robot's base in the tracker frame (fitted base twist included)."""
        return self.stages.parameters.trackerMbase

    @property
    def tracker_transform(self) -> np.ndarray:
        """(4, 4) robot base -> tracker: :attr:`trackerMbase` (its JSON key)."""
        return self.trackerMbase

    @property
    def registration(self) -> tuple:
        """(R, t) the first session's closed-form tracker frame: tracker = R robot + t."""
        return self.stages.register.stations[0]

    @property
    def final_residual(self) -> np.ndarray:
        """(N, 3) in-sample residual of the final model [m]."""
        return self.stages.residual.final_residual

    @property
    def heldout_residual(self) -> np.ndarray:
        """(N, 3) out-of-fold residual of the final model [m]."""
        return self.stages.residual.heldout_residual

    @property
    def gap_residual(self) -> np.ndarray:
        """(N, 3) residual after frames only [m]."""
        return self.stages.residual.gap_residual

    @property
    def semivariograms(self) -> list:
        return self.stages.residual.semivariograms

    @property
    def q(self) -> np.ndarray:
        return self.stages.register.measurements.q

    @property
    def nominal_position(self) -> np.ndarray:
        return self.stages.register.nominal[0].position

    @property
    def gravity_torque(self) -> np.ndarray:
        return self.stages.register.gravity_torque

    @property
    def frames_measured(self) -> list:
        return [p.label for p in self.stages.register.parts]

    @property
    def heldout_by_frame(self) -> dict:
        return self.stages.residual.heldout_by_frame

    @property
    def orientation(self) -> dict:
        o = self.stages.residual.orientation
        return {} if o is None else o.to_dict()

    @property
    def sessions(self) -> list:
        """Per session: label, rows, gap and held-out stats, temperature (JSON form)."""
        return [s.to_dict() for s in self.stages.residual.sessions]

    @property
    def drift(self) -> list:
        """Per session: the tracker's drift seen by base references (JSON form)."""
        return list(self.stages.register.drift)

    @property
    def selection(self) -> dict:
        """How often each effect is chosen over bootstrap replays."""
        return self.stages.attribute.stability

    @property
    def mechanisms(self) -> list:
        """For every chosen effect, the mechanism its fitted sign and size fit (JSON form)."""
        return [m.to_dict() for m in self.stages.attribute.mechanisms]

    @property
    def families(self) -> list:
        """Every family with a chosen effect and its share, largest first (JSON form, mm)."""
        return [f.to_dict() for f in self.stages.attribute.families]

    @property
    def own_share_ranking(self) -> list:
        """The largest own share against each other the primary effect was chosen among: the
        difference, its 95 % interval (paired, the same bootstrap replicates) and whether the held-out
        rows rank the two apart (JSON form, mm; the families' are in :attr:`families`, ``below_largest``)."""
        return [c.to_dict() for c in self.stages.attribute.own_share_ranking]

    @property
    def primary_family(self) -> str | None:
        """The family with the largest share, when the held-out rows rank it above the others."""
        return self.stages.attribute.primary_family

    @property
    def outside_physics(self) -> list:
        """The chosen effects whose fitted values another mechanism than their own physics explains
        (a controller's compensation, the instrument), with its words."""
        return [{"effect": m.effect, "description": m.mechanism, "physical": m.physical,
                 "n_outside": sum(1 for p in m.parameters if not p["textbook"])}
                for m in self.stages.attribute.mechanisms if not m.textbook and m.effect != "frames"]

    @property
    def geometry_checks(self) -> list:
        """The fitted geometry against what the robot's class allows (axis tilts, the tool frame's
        displacement and rotation, the fitted TCP offset against a given one), JSON form (mm, deg)."""
        return [c.to_dict() for c in self.stages.parameters.geometry_checks]

    @property
    def contribution(self) -> dict:
        """effect -> RMS TCP motion of its fit beyond frames [m]."""
        return self.stages.first_order.contribution

    @property
    def second_order(self) -> dict:
        """What one fixed-point step of the deflections adds (JSON form)."""
        return self.stages.first_order.to_dict()

    @property
    def notes(self) -> list:
        """Every stage's notes, in the order the stages found them."""
        s = self.stages
        return [*s.register.notes, *s.candidates.notes, *s.select.notes, *s.attribute.notes,
                *s.select.decision_notes(), *s.residual.notes, *s.parameters.notes, *s.first_order.notes]

    def __repr__(self) -> str:
        last = self.steps[-1].heldout.rms if self.steps else float("nan")
        return (f"Diagnosis({self.robot_name!r}, {self.n_measurements} measurements, "
                f"gap RMS {self.gap.rms * 1e3:.4g} mm, selected [{', '.join(self.selected_effects)}], "
                f"primary {self.primary_effect!r}, held-out RMS {last * 1e3:.4g} mm, "
                f"noise floor {self.noise_floor * 1e3:.4g} mm)")

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
            "search": self.search,
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
            "physical": {e: {"plausible": bool(getattr(self.stages.attribute.mechanism_of(e), "physical", True)),
                             "range": dict(t["range"]), "fit_range": dict(t["fit_range"]),
                             "pinned": list(t["pinned"]), "reason": self.physics.get(e, "")}
                         for e, t in self.parameter_table.items()},
            "outside_physics": list(self.outside_physics),
            "mechanisms": self.mechanisms,
            "families": self.families,
            "primary_family": self.primary_family,
            "own_share_ranking": self.own_share_ranking,
            "interval_method": self.stages.attribute.interval_method,
            "plausibility": {"tolerance": (None if self.stages.parameters.tolerance is None
                                           else self.stages.parameters.tolerance.to_dict()),
                             "checks": self.geometry_checks},
            "confounding": [c.to_dict() for c in self.stages.attribute.confounding],
            "instrument": (None if self.stages.register.instrument is None
                           else self.stages.register.instrument.to_dict()),
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
