"""The uncertainty budget of every figure a calibration report states, from its results.

:func:`figure_budgets` gives, for the figures the report's page 1 judges (a diagnosis' k-fold
held-out TCP error, each exported form's error on held-out and measured poses, an ISO 9283 test's
largest AP_P and RP_l), an :class:`~tcr_accuracy.frames.uncertainty_budget.UncertaintyBudget`;
:func:`parameter_budgets` one per fitted parameter. The contributions (their arithmetic in
:mod:`tcr_accuracy.frames.uncertainty_budget`):

* **instrument MPE** (type B): ``a + b L`` from the campaign file (``instrument.mpe_um``) or the
  diagnosis' instrument; L the distance of the measured points from the instrument, which
  stands at the origin of the measurements' frame (the tracker frame) unless the campaign file
  places it (``instrument.position_mm``); read as rectangular (``MPE / sqrt 3``) and, a systematic
  error of the instrument not averaging out over the poses, taken at the poses' RMS distance for a
  mean or RMS and at their farthest for a max;
* **measurement noise** (type A): the per-axis scatter the data's redundancy shows (repeated poses,
  several reflectors, or the residual's nugget: :class:`~tcr_accuracy.frames.noise.NoiseEstimate`),
  independent between poses, so ``sigma / sqrt N`` for a mean or RMS and ``sigma`` for a max;
* **frame registration** (type A): the tracker frame fitted on the measured poses, at the poses a
  figure is on (first order, from the fitted points' moments); for a k-fold figure the frame is
  fitted with the model and is in the fit's line;
* **temperature** (type B), where a range is stated: the robot's expansion over it at its reach;
* **fit** (type A): the model's own uncertainty at the poses, ``sigma sqrt(p / m)`` of its p
  parameters fitted to m coordinates.

Lengths in m.
"""

from __future__ import annotations

import math

import numpy as np

from ..frames.uncertainty_budget import (TYPE_A, TYPE_B, Contribution, PointSet, UncertaintyBudget, axis_sigma,
                                         fit_uncertainty, mpe_uncertainty, registration_uncertainty,
                                         statistic_noise, temperature_uncertainty)

#: The contributions, in the order every budget lists them.
SOURCES = ("instrument MPE", "measurement noise", "frame registration", "temperature", "fit")
#: Parameters of the rigid frame a form's tracker frame is (Kabsch: rotation and translation).
RIGID_PARAMETERS = 6


def instrument_mpe(facts, d) -> tuple | None:
    """(a [m], b [m/m], what it is) of the instrument's MPE, the larger of across and along the
    beam per term: the campaign file's, else the diagnosis' instrument; None if neither states one."""
    if facts is not None and facts.instrument_mpe_um is not None:
        pairs = [facts.instrument_mpe_um] + ([facts.instrument_radial_mpe_um] if facts.instrument_radial_mpe_um else [])
        a, b = (max(p[k] for p in pairs) * 1e-6 for k in (0, 1))
        return a, b, f"MPE {a * 1e6:g} um + {b * 1e6:g} um/m"
    spec = (d or {}).get("instrument") or {}
    if spec:
        pairs = [spec["transverse_mpe_um"], spec["radial_mpe_um"]]
        a, b = (max(p[k] for p in pairs) * 1e-6 for k in (0, 1))
        return a, b, f"MPE {a * 1e6:g} um + {b * 1e6:g} um/m"
    return None


def instrument_position(facts) -> tuple[np.ndarray, str]:
    """Where the instrument stands in the measurements' frame [m], and how that is known."""
    if facts is not None and facts.instrument_position_mm is not None:
        return np.asarray(facts.instrument_position_mm) * 1e-3, "where the campaign file places it"
    return np.zeros(3), "at the origin of the measurements' frame"


def _mpe(statistic: str, points: PointSet | None, mpe, facts) -> Contribution:
    if mpe is None:
        return Contribution("instrument MPE", None, "not evaluated: no MPE stated (instrument.mpe_um in the campaign "
                                                    "file, or the diagnosis' instrument)")
    if points is None:
        return Contribution("instrument MPE", None, f"not evaluated: {mpe[2]}, but the result records no measured "
                                                    "points to take the distance L of")
    origin, where = instrument_position(facts)
    rms, least, largest = points.distance(origin)
    distance = largest if statistic == "max" else rms
    u = float(mpe_uncertainty(mpe[:2], distance))
    return Contribution("instrument MPE", u, f"{mpe[2]} at L = {distance:.2f} m ({'farthest' if statistic == 'max' else 'RMS'}"
                                            f" of {least:.2f}-{largest:.2f} m from the tracker {where}), / sqrt 3 "
                                            "(rectangular); systematic", TYPE_B)


def _noise(statistic: str, n: int, d) -> Contribution:
    noise = (d or {}).get("noise") or {}
    sigma = noise.get("per_axis_mm")
    if sigma is None:
        return Contribution("measurement noise", None, "not evaluated: no noise figure in the results", TYPE_A)
    u = statistic_noise(sigma * 1e-3, n, statistic)
    said = {"repeated poses": "repeated poses", "residual nugget": "the residual's nugget, an upper bound",
            "rigid frames": "reflectors on one body", "given": "given for the instrument",
            "residual": "the final residual, an upper bound"}.get(noise.get("source", ""), noise.get("source", "data"))
    return Contribution("measurement noise", u, f"{sigma * 1e3:.1f} um per axis ({said})"
                                                + (", one pose's" if statistic == "max" else f" / sqrt {n}"), TYPE_A)


def _temperature(facts, d, reach: float | None) -> Contribution:
    """The robot's expansion over the stated temperature range where the measurements did not sample
    it: a figure measured across the range holds its effect in its own scatter, and a fitted thermal
    effect holds it in the model; what is left is the part of the range the measurements did not span."""
    stated = facts.temperature_c if facts is not None and facts.temperature_c is not None else None
    bins = (((d or {}).get("where") or {}).get("temperature_c") or {}).get("bins") or []
    measured = (bins[0]["low"], bins[-1]["high"]) if bins else None
    span = stated or measured
    if span is None:
        return Contribution("temperature", None, "not evaluated: no temperature range stated (temperature_c in the "
                                                 "campaign file or the measurements)")
    if "thermal" in ((d or {}).get("selected_effects") or []):
        return Contribution("temperature", 0.0, f"the fitted thermal effect holds it over {span[0]:.1f} to "
                                                f"{span[1]:.1f} degC", TYPE_B)
    unsampled = (span[1] - span[0]) - ((measured[1] - measured[0]) if measured else 0.0)
    if unsampled <= 0:
        return Contribution("temperature", 0.0, f"measured across {measured[0]:.1f} to {measured[1]:.1f} degC: the "
                                                "figures hold its effect in their scatter", TYPE_B)
    if reach is None:
        return Contribution("temperature", None, f"not evaluated: {span[0]:.1f} to {span[1]:.1f} degC stated, the "
                                                 "robot's reach not recorded")
    u = temperature_uncertainty((0.0, unsampled), reach)
    said = "not sampled by the measurements (no temperature column)" if measured is None else \
        f"of the stated range beyond the measured {measured[0]:.1f} to {measured[1]:.1f} degC"
    return Contribution("temperature", u, f"23 ppm/K (aluminium, conservative) x {unsampled:.1f} K {said} x reach "
                                          f"{reach:.2f} m, / sqrt 12 (rectangular)", TYPE_B)


def _fit(d, folds: int | None) -> Contribution:
    steps = (d or {}).get("steps") or []
    if not steps:
        return Contribution("fit", None, "not evaluated: no diagnosis given with this result", TYPE_A)
    last, n = steps[-1], d["n_measurements"]
    p = int(last["n_parameters"])
    train = n * (folds - 1) // folds if folds else n
    sigma = axis_sigma(last["train_rms_mm"] * 1e-3, n, p)
    u = fit_uncertainty(sigma, p, 3 * train)
    return Contribution("fit", u, f"{p} parameters fitted to {3 * train} coordinates, residual {sigma * 1e6:.1f} um per "
                                  "axis: sigma sqrt(p / m)", TYPE_A)


def reach_of(d, export) -> float | None:
    """The farthest measured point from the robot's base [m]: the export's, else a bound from the
    diagnosis' measured points (their box's corners mapped by its ``trackerMbase``)."""
    if export is not None and export.reach is not None:
        return export.reach
    points, transform = (d or {}).get("measured_points"), (d or {}).get("trackerMbase")
    if points is None or transform is None:
        return None
    m = np.asarray(transform, dtype=float)
    corners = (PointSet.from_dict(points).corners() - m[:3, 3]) @ m[:3, :3]
    return float(np.max(np.linalg.norm(corners, axis=1)))


def _points(doc, key="measured_points") -> PointSet | None:
    value = (doc or {}).get(key)
    return None if value is None else PointSet.from_dict(value)


def _statistics(value_of) -> list:
    return [(s, value_of(s)) for s in ("mean", "rms", "max")]


def figure_budgets(d, exports, isos, facts) -> list[tuple[dict, UncertaintyBudget]]:
    """Every judged figure's budget, as (where, budget) with ``where`` naming it: ``form``, ``on``
    ("k-fold held-out", "held-out", "measured", "iso"), ``statistic`` ("mean", "rms", "max", "ap", "rp").

    Parameters
    ----------
    d : dict or None
        The diagnosis (the last one given).
    exports : list of ExportResult
        The export results (the last one is judged).
    isos : list of (source, dict)
        ISO 9283 results.
    facts : CampaignFacts or None
    """
    export = exports[-1] if exports else None
    mpe = instrument_mpe(facts, d)
    temperature = _temperature(facts, d, reach_of(d, export))
    out = []
    if d is not None and export is None:
        last = d["steps"][-1]
        for statistic, value in _statistics(lambda s: last[f"heldout_{s}_mm"] * 1e-3):
            out.append(({"form": "full model", "on": "k-fold held-out", "statistic": statistic},
                        _kfold_budget(d, statistic, value, mpe, temperature, facts, _points(d))))
    if export is not None:
        measured = export.point_sets.get("measured")
        for record in export.accuracy:
            if record.form == "nominal":
                continue
            for statistic, value in _statistics(lambda s: getattr(record, s)):
                where = {"form": record.form, "on": record.on, "statistic": statistic}
                if record.on == "k-fold held-out" and d is not None:
                    out.append((where, _kfold_budget(d, statistic, value, mpe, temperature, facts, measured)))
                    continue
                points = export.point_sets.get(record.on)
                if measured is not None and points is not None and record.frame_rms is not None:
                    sigma = axis_sigma(record.frame_rms, measured.n, RIGID_PARAMETERS)
                    rms, largest = registration_uncertainty(measured, sigma, points)
                    registration = Contribution(
                        "frame registration", largest if statistic == "max" else rms,
                        f"Kabsch frame on {measured.n} poses, residual {sigma * 1e6:.1f} um per axis, at the "
                        f"{points.n} {record.on} poses ({'farthest' if statistic == 'max' else 'RMS'}; first order)",
                        TYPE_A)
                else:
                    registration = Contribution("frame registration", None, "not evaluated: not recorded", TYPE_A)
                out.append((where, UncertaintyBudget(
                    f"{record.form}, {statistic} on {record.n} {record.on} poses", value, "m",
                    (_mpe(statistic, points, mpe, facts), _noise(statistic, record.n, d), registration, temperature,
                     _fit(d, None)))))
    for source, iso in isos:
        out += _iso_budgets(source, iso, d, mpe, temperature, facts)
    return out


def _kfold_budget(d, statistic, value, mpe, temperature, facts, points) -> UncertaintyBudget:
    n = d["n_measurements"]
    return UncertaintyBudget(
        f"full model, {statistic} k-fold held-out ({n} poses)", value, "m",
        (_mpe(statistic, points, mpe, facts), _noise(statistic, n, d),
         Contribution("frame registration", 0.0, "fitted with the model: in the fit's line", TYPE_A),
         temperature, _fit(d, d.get("folds"))))


#: How an ISO result's frame was obtained (its ``frame_source``) when it is given, not fitted.
_GIVEN_FRAMES = ("base",)


def _iso_registration(iso) -> Contribution:
    """The ISO test's frame registration: from its residual and point count where the result records
    them (``frame_residual_rms_mm``, ``frame_n_points``), conservatively at a pose up to twice the
    registration points' radius of gyration from their centroid (``sigma sqrt(5 / n)``)."""
    source = iso.get("frame_source") or iso.get("frame") or ""
    rms, n = iso.get("frame_residual_rms_mm"), iso.get("frame_n_points")
    if source in _GIVEN_FRAMES:
        return Contribution("frame registration", 0.0, "the base frame given: nothing fitted", TYPE_B)
    if rms is None or not n:
        return Contribution("frame registration", None, "not evaluated: the ISO result does not record its frame fit's "
                                                        "residual and points (AP may be off by the frame's error)",
                            TYPE_A)
    sigma = axis_sigma(rms * 1e-3, int(n), RIGID_PARAMETERS)
    return Contribution("frame registration", sigma * math.sqrt(5.0 / n),
                        f"frame fitted on {n} points ({source}), residual {sigma * 1e6:.1f} um per axis; at a pose up "
                        "to twice their radius of gyration from their centroid: sigma sqrt(5 / n) (conservative)",
                        TYPE_A)


def _iso_budgets(source, iso, d, mpe, temperature, facts) -> list:
    """AP_P and RP_l of the worst pose over the test's conditions, each with its budget."""
    poses = [p for block in (iso.get("conditions") or [iso]) for p in block["poses"]]
    name = str(iso.get("measurements") or source).split("/")[-1]
    ap = max(poses, key=lambda p: p["ap_mm"])
    n = int(ap["n"])
    if n >= 2 and ap.get("s_l_mm") is not None:
        mean_square = ap["l_mean_mm"] ** 2 + ap["s_l_mm"] ** 2 * (n - 1) / n  # of the readings' distances l_j
        sigma = math.sqrt(mean_square / 3.0) * 1e-3
        noise = Contribution("measurement noise", sigma / math.sqrt(n),
                             f"the pose's {n} readings' scatter, {sigma * 1e6:.1f} um per axis, / sqrt {n} for their "
                             "barycentre", TYPE_A)
    else:
        noise = _noise("mean", n, d)
    points = _points(d)
    mpe_line = _mpe("max", points, mpe, facts)
    if mpe_line.standard_uncertainty is not None:
        mpe_line = Contribution(mpe_line.source, mpe_line.standard_uncertainty, mpe_line.how.replace(
            "points,", "points of the calibration (the ISO result records no positions),", 1), TYPE_B)
    predicted = any((b.get("compensated") or {}).get("summary") for b in (iso.get("conditions") or [iso]))
    fit = _fit(d, None) if predicted else Contribution("fit", 0.0, "as measured: no model in the figure", TYPE_A)
    out = [({"form": name, "on": "iso", "statistic": "ap"}, UncertaintyBudget(
        f"AP_P, pose {ap['pose_id']} of {name} ({n} readings)", ap["ap_mm"] * 1e-3, "m",
        (mpe_line, noise, _iso_registration(iso), temperature, fit)))]
    rp = [p for p in poses if p.get("rp_mm") is not None and int(p["n"]) >= 2]
    if rp:
        worst = max(rp, key=lambda p: p["rp_mm"])
        m = int(worst["n"])
        out.append(({"form": name, "on": "iso", "statistic": "rp"}, UncertaintyBudget(
            f"RP_l, pose {worst['pose_id']} of {name} ({m} readings)", worst["rp_mm"] * 1e-3, "m",
            (Contribution("instrument MPE", 0.0, "RP is a scatter: the MPE's systematic part cancels, its random part "
                                                 "is in the readings", TYPE_B),
             Contribution("measurement noise", 3.0 * worst["s_l_mm"] * 1e-3 / math.sqrt(2.0 * (m - 1)),
                          f"the scatter's own uncertainty from {m} readings: 3 S_l / sqrt(2 (n - 1))", TYPE_A),
             Contribution("frame registration", 0.0, "RP is frame-free (distances about the barycentre)", TYPE_B),
             Contribution("temperature", 0.0, "within the readings of one pose", TYPE_B),
             Contribution("fit", 0.0, "as measured: no model in the figure", TYPE_A)))))
    return out


def parameter_budgets(d, facts) -> dict:
    """Per fitted parameter (effect -> name -> UncertaintyBudget, SI units): the fit's standard error
    (type A, from the fit's covariance: the residual's scatter, the instrument's random part within it)
    and the instrument's MPE propagated as the fit propagates its scatter (``std x u_MPE / sigma``)."""
    if d is None or not d.get("parameter_std"):
        return {}
    mpe = instrument_mpe(facts, d)
    last, n = d["steps"][-1], d["n_measurements"]
    sigma = axis_sigma(last["train_rms_mm"] * 1e-3, n, int(last["n_parameters"]))
    points = _points(d)
    inst = None
    if mpe is not None and points is not None:
        origin, _ = instrument_position(facts)
        inst = float(mpe_uncertainty(mpe[:2], points.distance(origin)[0]))
    out: dict = {}
    for effect, values in d["parameters"].items():
        for name, value in values.items():
            std = d["parameter_std"].get(effect, {}).get(name)
            unit = d.get("parameter_units", {}).get(effect, {}).get(name, "")
            fit = Contribution("fit", std, "standard error from the fit's covariance", TYPE_A)
            if std is None or inst is None or sigma <= 0:
                instrument = Contribution("instrument MPE", None, "not evaluated: no MPE stated or no points recorded")
            else:
                instrument = Contribution("instrument MPE", std * inst / sigma,
                                          f"the standard error scaled by u_MPE / sigma = {inst / sigma:.2f}", TYPE_B)
            out.setdefault(effect, {})[name] = UncertaintyBudget(name, value, unit, (fit, instrument))
    return out


__all__ = ["SOURCES", "figure_budgets", "instrument_mpe", "instrument_position", "parameter_budgets", "reach_of"]
