"""Stage 4: attribute the gap -- the primary effect (or the group the data cannot rank apart),
the shrink table in the order the chosen effects explain the data, how stable the selection is,
what the data fit only outside physics, and where the first-order effect models end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..attribution import contributions, fixed_point_check, tied_own_shares
from ..fitting import FitEngine, ordered, paired_z
from ..records import ErrorStats, Step
from ..uncertainty import difference_interval, outside_physics, selection_frequency
from .candidates import CandidateSet
from .select import Selection


@dataclass(frozen=True)
class Attribution:
    """What stage 4 found.

    Attributes
    ----------
    primary_effect : str or None
        The chosen effect with the largest own share, None when the data cannot single it out.
    primary_group : tuple of str
        The primary effect and what stands in for it or ties with it.
    primary_tied : tuple of str
        The largest own share and those not ranked below it by the held-out rows.
    steps : tuple of Step
        The shrink table in the order of explanation (with each step's gain and interval).
    stability : dict
        How often bootstrap replays of the selection choose each effect (JSON form).
    outside_physics : tuple of dict
        What the data fit only with parameters outside an effect's physical range (JSON form).
    notes : tuple of str
    """

    primary_effect: str | None
    primary_group: tuple
    primary_tied: tuple
    steps: tuple
    stability: dict
    outside_physics: tuple
    notes: tuple


def attribute_effects(candidate_set: CandidateSet, selection: Selection, *, selection_z: float,
                      min_relative_gain: float, stability_replays: int, seed: int,
                      say=lambda message: None) -> Attribution:
    """Stage 4 of the diagnosis.

    Parameters
    ----------
    candidate_set, selection : the results of stages 2 and 3
    selection_z, min_relative_gain : the selection test (see :func:`~.select.select_effects`)
    stability_replays : int
        Bootstrap replays of the selection.
    seed : int
        Seeds the replays (their own stream).
    """
    engine = candidate_set.engine
    current = list(selection.selected)
    loo = [r.to_dict() for r in selection.leave_one_out]
    notes: list = []
    # the largest own share and those it does not clear, compared on the same held-out rows (paired: the
    # two shares' own intervals overlap more than their difference's does)
    tied = tied_own_shares(engine, current, loo, selection_z)
    primary = tied[0] if tied else None
    primary_group = [r["effect"] for r in selection.groups.get(primary, [])] or ([primary] if primary else [])
    primary_group += [e for e in tied[1:] if e not in primary_group]
    if len(primary_group) > 1:
        primary = None  # the data cannot say which of the group it is
        primary_group = ordered(primary_group)
    # the shrink table in the order the chosen effects explain the data
    steps = explanation_ladder(engine, current, selection.forward_steps[0])
    say("selection stability")
    testable = list(selection.testable)
    stability = selection_frequency(engine, testable, selection_z, min_relative_gain, stability_replays,
                                    np.random.default_rng([seed, 2]), say,
                                    late=[e for e in selection.late if e in testable])
    say("what the data fit only outside physics")
    beyond = outside_physics(engine, current, testable, selection_z, min_relative_gain)
    # an effect in the model that the data fit significantly better beyond its physics is not named as the cause
    flagged = [f["effect"] for f in beyond if f["effect"] in current]
    if flagged and (set(flagged) & set(primary_group)):
        primary_group = [e for e in primary_group if e not in flagged]
        if not primary_group:
            shares = {r["dropped"]: r["own_share_increase_mm"] for r in loo if r["dropped"] not in flagged}
            primary_group = [max(shares, key=shares.get)] if shares else []
        primary = primary_group[0] if len(primary_group) == 1 else None
        tied = [e for e in tied if e not in flagged]
        notes.append(f"{', '.join(flagged)} stays in the model only at its physical bound and is not named as the "
                     "cause: see what the data fit outside physics")
    return Attribution(primary_effect=primary, primary_group=tuple(primary_group), primary_tied=tuple(tied),
                       steps=tuple(steps), stability=stability, outside_physics=tuple(beyond), notes=tuple(notes))


@dataclass(frozen=True)
class FirstOrder:
    """How far the first-order effect models reach (SI units).

    Attributes
    ----------
    contribution : dict
        effect -> RMS TCP motion its fitted parameters cause beyond a rigid frame change [m].
    fixed_point_step_rms, fixed_point_step_max : float
        How far one fixed-point step of the joint deflections would move the TCP [m].
    over_noise_floor : float or None
        The RMS step over the noise floor.
    within_range : bool
        The step is at most a quarter of the noise floor: first order is enough.
    notes : tuple of str
    """

    contribution: dict
    fixed_point_step_rms: float
    fixed_point_step_max: float
    over_noise_floor: float | None
    within_range: bool
    notes: tuple

    def to_dict(self) -> dict:
        return {"fixed_point_step_rms_mm": self.fixed_point_step_rms * 1e3,
                "fixed_point_step_max_mm": self.fixed_point_step_max * 1e3,
                "over_noise_floor": self.over_noise_floor, "within_range": self.within_range}


def first_order_reach(part, bases: dict, chosen, full_parameters: dict, nominal: np.ndarray,
                      noise_floor: float) -> FirstOrder:
    """What each chosen effect's fit moves the TCP by, and whether one fixed-point step of the
    deflections stays within a quarter of the noise floor [m]."""
    contribution = contributions(part, bases, chosen, full_parameters, nominal)
    rms, largest, note = fixed_point_check(part, bases, full_parameters, noise_floor)
    return FirstOrder(contribution=contribution, fixed_point_step_rms=rms, fixed_point_step_max=largest,
                      over_noise_floor=rms / noise_floor if noise_floor else None,
                      within_range=bool(rms <= 0.25 * noise_floor), notes=(note,) if note else ())


def explanation_ladder(engine: FitEngine, selected, first: Step) -> list[Step]:
    """The shrink table in the order of explanation: from frames, each step adds the chosen
    effect that lowers the held-out error most given those before it, with its gain and
    the gain's 95 % interval."""
    steps, current = [first], ["frames"]
    previous = engine.evaluate(["frames"])
    remaining = [e for e in selected if e != "frames"]
    while remaining:
        trials = {e: engine.evaluate(ordered(current + [e])) for e in remaining}
        best = min(trials, key=lambda e: ErrorStats.heldout(trials[e]).rms)
        r = trials[best]
        current.append(best)
        remaining.remove(best)
        steps.append(Step(best, tuple(ordered(current)), r["n_parameters"], ErrorStats.of(r["train_residual"]).rms,
                          ErrorStats.heldout(r),
                          paired_z(previous["heldout_squares"], r["heldout_squares"]),
                          difference_interval(previous["heldout_squares"], r["heldout_squares"])))
        previous = r
    return steps
