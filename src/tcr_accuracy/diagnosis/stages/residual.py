"""Stage 5: what is left -- where the gap lies (on the frames-only residual), the instrument's
noise, whether structure or random scatter remains in the final residual and whether the test
could have seen it, and the held-out figures per session and per measured frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...frames.noise import NoiseEstimate
from ...frames.rigid import homogeneous
from ..ambiguity import stand_in_shapes
from ..bases import ordered
from ..paired import stacked
from ..residuals import noise_from_residual, where_analysis
from ..records import ErrorStats
from ..structure import name_scatter, scatter_beyond_noise, smallest_detectable_structure, smooth_shape, \
    structure_verdict
from .candidates import CandidateSet
from .register import RegisteredMeasurements, measured_context
from .select import Selection


@dataclass(frozen=True)
class SessionFigures:
    """One measurement session: its rows, its gap and final held-out errors, its temperature
    range [degC] and its own tracker frame ``trackerMbase`` (4, 4)."""

    label: str
    n_measurements: int
    gap: ErrorStats
    heldout: ErrorStats
    temperature_c: tuple
    trackerMbase: np.ndarray

    def to_dict(self) -> dict:
        return {"session": self.label, "n_measurements": self.n_measurements, "gap": self.gap.to_dict(),
                "heldout": self.heldout.to_dict(), "temperature_c": list(self.temperature_c),
                "registration_base_to_tracker": self.trackerMbase.tolist()}


@dataclass(frozen=True)
class OrientationFigures:
    """Held-out orientation errors [rad] and the weight [m/rad] orientation rows had in the fit."""

    weight: float
    heldout_mean: float
    heldout_rms: float
    heldout_max: float

    def to_dict(self) -> dict:
        return {"weight_m_per_rad": self.weight, "heldout_mean_deg": math.degrees(self.heldout_mean),
                "heldout_rms_deg": math.degrees(self.heldout_rms), "heldout_max_deg": math.degrees(self.heldout_max)}


@dataclass(frozen=True)
class ResidualAnalysis:
    """What stage 5 found.

    Attributes
    ----------
    gap : ErrorStats
        The gap: errors after frames only, every measured frame [m].
    gap_residual : ndarray of shape (N, 3)
        The main frame's residual after frames only [m].
    final_residual : ndarray of shape (N, 3)
        The final model's in-sample residual [m].
    heldout_residual : ndarray of shape (N, 3)
        The final model's out-of-fold residual [m] (the first fold assignment).
    heldout_repeats : tuple of ndarray of shape (N, 3)
        The out-of-fold residual of every fold assignment [m] (the held-out figures pool them).
    where_mm : dict
        Where the gap lies (JSON form: keys carry their unit, mostly mm).
    semivariograms : list
        Per-joint semivariograms of the gap (for the plots).
    noise : NoiseEstimate
        The instrument's per-axis noise [m] and where it came from.
    structure : dict
        The structure test on the final residual, its power and verdict (JSON form).
    scatter : dict
        The test for scatter beyond the instrument (JSON form).
    sessions : tuple of SessionFigures
    heldout_by_frame : dict
        Measured frame -> ErrorStats of its held-out errors (several frames only).
    orientation : OrientationFigures or None
    notes : tuple of str
    """

    gap: ErrorStats
    gap_residual: np.ndarray
    final_residual: np.ndarray
    heldout_residual: np.ndarray
    heldout_repeats: tuple
    where_mm: dict
    semivariograms: list
    noise: NoiseEstimate
    structure: dict
    scatter: dict
    sessions: tuple
    heldout_by_frame: dict
    orientation: OrientationFigures | None
    notes: tuple

    @property
    def noise_floor(self) -> float:
        """RMS norm of the measurement noise [m]: sqrt(3) times the per-axis figure."""
        return math.sqrt(3.0) * self.noise.per_axis


def analyse_residual(registered: RegisteredMeasurements, candidate_set: CandidateSet, selection: Selection, *,
                     tracker_noise: float | None, rng: np.random.Generator, seed: int,
                     say=lambda message: None) -> ResidualAnalysis:
    """Stage 5 of the diagnosis.

    Parameters
    ----------
    registered, candidate_set, selection : the results of stages 1-3
    tracker_noise : float or None
        The instrument's per-axis noise [m] when given.
    rng : numpy.random.Generator
        The main stream (the semivariograms' draws).
    seed : int
        Seeds the power probe (its own stream).
    """
    engine, detector = candidate_set.engine, candidate_set.detector
    current = ordered(selection.selected)
    measurements = registered.measurements
    robot = registered.robot
    notes: list = []
    final = engine.evaluate(current, exact=True)
    gap_residual = _first_frame(selection.gap_residual)
    say("where the gap lies")
    context_values = {k: np.asarray(getattr(registered.parts[0].context, k), dtype=float)
                      for k in measured_context(measurements)}
    where, semis = where_analysis(robot, measurements.q, registered.nominal[0].position, gap_residual,
                                  registered.gravity_torque, context_values, rng=rng,
                                  knn_shares=detector.shares if detector.rows is None else None)
    say("testing the final residual")
    final_train = _first_frame(final["train_residual"])
    structure = detector.test(final_train, rng)
    if tracker_noise is not None:
        noise = NoiseEstimate(float(tracker_noise), "given", True, "the instrument's figure, as given")
    elif candidate_set.instrument_noise is not None:
        noise = candidate_set.instrument_noise
        if noise.source == "instrument specification":  # the data's own figure beside the specification's
            own = noise_from_residual(measurements.q, final_train, final["n_parameters"], structure["remains"])
            noise = NoiseEstimate(noise.per_axis, noise.source, True,
                                  f"{noise.detail}; the data's own estimate ({own.source}): {own.per_axis * 1e3:.4g} mm "
                                  "per axis")
    else:
        noise = noise_from_residual(measurements.q, final_train, final["n_parameters"], structure["remains"])
    scatter = scatter_beyond_noise(noise, final, candidate_set.stochastic)
    say("probing the structure test's power")
    probe_rng = np.random.default_rng([seed, 1])
    shapes = stand_in_shapes(engine, current, list(selection.testable), probe_rng) or \
        {"smooth joint function": smooth_shape(detector, probe_rng)}
    structure["power"] = smallest_detectable_structure(detector, shapes, noise.per_axis, probe_rng)
    leftover = math.sqrt(3.0) * (scatter["estimated_noise_per_axis_mm"] * 1e-3 if scatter["tested"]
                                 else float(np.sqrt(np.mean(final_train**2))))
    structure.update(structure_verdict(structure, structure["power"], scatter, math.sqrt(3.0) * noise.per_axis,
                                       leftover))
    context = registered.parts[0].context
    along = {k: context_values[k] for k in ("temperature_c", "payload_kg") if k in context_values}
    if "direction" in context_values:
        along["approach directions"] = context_values["direction"]
    along["measurement order"] = np.asarray(context.order if context.order is not None
                                            else np.arange(registered.n_rows), dtype=float)
    if context.time_s is not None:
        along["time_s"] = np.asarray(context.time_s, dtype=float)
    name_scatter(scatter, structure, candidate_set.stochastic, noise, notes, detector, final_train, along)

    repeats = [_first_frame(h) for h in final["heldout_repeats"]]

    def pooled(rows) -> ErrorStats:  # a subset's held-out errors over every fold assignment
        stats = ErrorStats.of(np.concatenate([h[rows] for h in repeats]))
        return ErrorStats(stats.mean, stats.rms, stats.max, int(np.size(rows)))

    sessions = []
    temperature = np.asarray(registered.parts[0].context.temperature_c, dtype=float)
    for s, label in enumerate(registered.session_labels):
        rows = np.flatnonzero(registered.session_of == s)
        sessions.append(SessionFigures(label, int(rows.size), ErrorStats.of(gap_residual[rows]), pooled(rows),
                                       (float(temperature[rows].min()), float(temperature[rows].max())),
                                       homogeneous(*registered.stations[s])))
    by_frame = {}
    if len(registered.parts) > 1:
        by_frame = {}
        for p, part in enumerate(registered.parts):
            stats = ErrorStats.of(np.concatenate([h[p] for h in final["heldout_repeats"]]))
            by_frame[part.label] = ErrorStats(stats.mean, stats.rms, stats.max, registered.n_rows)
    orientation = None
    if final["heldout_orientation"] is not None:
        angle = np.linalg.norm(stacked(final["heldout_orientation"]), axis=1)
        orientation = OrientationFigures(registered.orientation_weight, float(angle.mean()),
                                         float(np.sqrt(np.mean(angle**2))), float(angle.max()))
    return ResidualAnalysis(gap=ErrorStats.of(selection.gap_residual), gap_residual=gap_residual, final_residual=final_train,
                            heldout_residual=_first_frame(final["heldout_residual"]),
                            heldout_repeats=tuple(repeats), where_mm=where, semivariograms=semis, noise=noise,
                            structure=structure, scatter=scatter, sessions=tuple(sessions),
                            heldout_by_frame=by_frame, orientation=orientation, notes=tuple(notes))


def _first_frame(residual: np.ndarray) -> np.ndarray:
    """The first measured frame's (N, 3) rows of a (N, 3) or (n_parts, N, 3) residual."""
    return residual if residual.ndim == 2 else residual[0]
