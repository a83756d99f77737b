"""Stage 3: select the effects -- forward selection on k-fold held-out error, the effects of last
resort where the others leave structure, identifiability at the fitted sizes, the
one-standard-error swaps, backward elimination, and what the data cannot tell apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..ambiguity import ambiguity_report, settle_swaps, swap_alternatives, within_reach
from ..fitting import FitEngine
from ..bases import ordered
from ..paired import entry_z, paired_z
from ..records import ErrorStats, Step
from ..uncertainty import implausibility
from ..bases import position_jacobians
from .candidates import NOT_IDENTIFIABLE, Candidate, CandidateSet, build_bases, identifiable_alone, relinearise, \
    untried
from .register import RegisteredMeasurements
from .search import SearchReport, harmful_effect, search_sets


@dataclass(frozen=True)
class LeaveOneOut:
    """The final model without one chosen effect (SI units).

    Attributes
    ----------
    effect : str
        The effect left out.
    heldout : ErrorStats
        Held-out errors without it, the others refitted and free to take its place.
    increase : float
        How much the held-out RMS rises without it [m] (others refitted).
    z : float
        Paired z of the final model against the one without it.
    own_share_heldout : ErrorStats
        Held-out errors without it, the others held to their own parameters.
    own_share_increase : float
        Its own share: how much the held-out RMS rises then [m] (its 95 % interval is stage 4's,
        :attr:`~.attribute.Attribution.own_shares`, on the same bootstrap as the other shares).
    """

    effect: str
    heldout: ErrorStats
    increase: float
    z: float
    own_share_heldout: ErrorStats
    own_share_increase: float

    def to_dict(self) -> dict:
        return {"dropped": self.effect, "heldout_rms_mm": self.heldout.rms * 1e3,
                "heldout_mean_mm": self.heldout.mean * 1e3,
                "heldout_max_mm": self.heldout.max * 1e3, "increase_mm": self.increase * 1e3, "z": self.z,
                "own_share_heldout_rms_mm": self.own_share_heldout.rms * 1e3,
                "own_share_heldout_mean_mm": self.own_share_heldout.mean * 1e3,
                "own_share_increase_mm": self.own_share_increase * 1e3}


@dataclass(frozen=True)
class Elimination:
    """An effect backward elimination dropped: its z and what the held-out RMS gained [m]."""

    effect: str
    z: float
    increase: float

    def to_dict(self) -> dict:
        return {"effect": self.effect, "z": self.z, "increase_mm": self.increase * 1e3}


@dataclass(frozen=True)
class Selection:
    """What stage 3 found.

    Attributes
    ----------
    selected : tuple of str
        The chosen effects, ``frames`` first, in the order they were chosen (swaps in place).
    forward_steps : tuple of Step
        The shrink table in the order forward selection took the effects.
    candidates : tuple of Candidate
        Every effect as a candidate: why not tried, or its first trial (report order).
    testable : tuple of str
        The effects tried (the late ones included when they were).
    late : tuple of str
        The effects of last resort that were tried.
    rivals : tuple of str
        The effects that explain the gap on their own (they may stand in for a chosen one); of the
        effects of last resort, those forward selection took.
    swaps : tuple of dict
        One-standard-error swaps made after forward selection (JSON form, mm keys).
    leave_one_out : tuple of LeaveOneOut
        The final model without each chosen effect.
    eliminated : tuple of Elimination
        What backward elimination dropped.
    groups : dict
        Chosen effect -> its stand-ins (rows of :func:`~tcr_accuracy.diagnosis.ambiguity.swap_alternatives`).
    ambiguous : tuple of dict
        The groups of effects the data cannot tell apart (JSON form, mm keys).
    search : SearchReport
        The search beyond the greedy path: what it tried, the best set on another path.
    gap_residual : ndarray of shape (N, 3) or (n_parts, N, 3)
        The residual after frames alone [m] (the gap), as fitted before anything else.
    notes : tuple of str
    """

    selected: tuple
    forward_steps: tuple
    candidates: tuple
    testable: tuple
    late: tuple
    rivals: tuple
    swaps: tuple
    leave_one_out: tuple
    eliminated: tuple
    groups: dict
    ambiguous: tuple
    search: SearchReport
    gap_residual: np.ndarray
    notes: tuple

    def decision_notes(self) -> list[str]:
        """Notes on what the selection undid: backward eliminations and swaps; what the search tried."""
        notes = [self.search.note()]
        if self.eliminated:
            notes.append("dropped again after forward selection (no significant held-out loss without them): "
                         + ", ".join(f"{e.effect} (z = {e.z:.1f})" for e in self.eliminated))
        for swap in self.swaps:
            notes.append(f"{swap['in']} replaces {swap['out']} (one-standard-error rule: held-out RMS "
                         f"{swap['heldout_rms_mm'][swap['in']]:.4g} mm with {swap['n_parameters'][swap['in']]} "
                         f"parameters against {swap['heldout_rms_mm'][swap['out']]:.4g} mm with "
                         f"{swap['n_parameters'][swap['out']]})")
        return notes


def select_effects(registered: RegisteredMeasurements, candidate_set: CandidateSet, *, selection_z: float,
                   min_relative_gain: float, say=lambda message: None) -> Selection:
    """Stage 3 of the diagnosis.

    Parameters
    ----------
    registered, candidate_set : the results of stages 1 and 2
    selection_z : float
        One-sided z the paired held-out test must exceed for an effect to enter.
    min_relative_gain : float
        And the held-out RMS must drop by at least this fraction.
    say : callable(str)
        Progress messages.
    """
    engine = candidate_set.engine
    candidates = {c.effect: c for c in candidate_set.untried}
    testable = list(candidate_set.testable)
    notes: list = []
    result = engine.evaluate(["frames"], exact=True)  # the gap: the exact kinematics' residual after frames
    steps = [Step("frames", ("frames",), result["n_parameters"], result["train_stats"].rms,
                  ErrorStats.heldout(result), None)]
    current = _forward(engine, testable, steps, candidates, say, selection_z, min_relative_gain)
    # a flexible effect of last resort is tried only where the others leave structure in joint space: the test's
    # verdict alone, as the power probe reads it (its first 30 shuffles, no semivariogram), where the whole test
    # (100 shuffles and a semivariogram of 2 x 10^6 pairs, both thrown away) was 1.5 s of CPU at 10^4 poses
    say("testing what the first selection leaves")
    late = []
    late_names = candidate_set.late_names
    if late_names and candidate_set.detector.remains(_first_frame(engine.evaluate(ordered(current))["train_residual"])):
        late_bases, late_rejected, _ = build_bases(list(registered.parts), late_names, registered.measured_context,
                                                   notes, registered.session_labels)
        relinearise(late_bases, candidate_set.linearised())
        engine.add_bases(late_bases)
        candidates.update({c.effect: c for c in late_rejected})
        for name in ordered(late_bases):
            if identifiable_alone(engine, name):
                late.append(name)
            else:
                candidates[name] = untried(name, NOT_IDENTIFIABLE)
        testable += late
        current = _forward(engine, testable, steps, candidates, say, selection_z, min_relative_gain, current)
    else:
        for e in late_names:
            candidates[e] = untried(e, "tried only when the other effects leave structure in joint space, and they "
                                       "left none")
    _judge_at_fitted_sizes(engine, current, notes)
    # a stand-in must explain the gap on its own, as an effect entering first would have to
    # (its paired z against frames alone at the first step): the rest cannot replace anything. An effect
    # of last resort that forward selection tried late and left out is no stand-in either, as the search
    # below does not take it: it had its chance against the set it would join, and its fits cost the most
    # (16 of the 35 swap fits at 10^4 poses were a fine angle table's, ~4 s of CPU)
    rivals = [e for e in testable if (candidates[e].z or 0.0) > selection_z and (e in current or e not in late)]
    reference = engine.evaluate(ordered(current))["heldout_squares"]  # the best model forward selection found
    current, swaps = settle_swaps(engine, current, rivals, selection_z, say, reference)
    current, loo, eliminated = _backward(engine, current, say, selection_z, reference)
    # stepwise: what backward elimination and the swaps left may again take an effect forward selection
    # would add (a chain of swaps can end on a worse set); repeat until the set stands, each set once
    seen = {frozenset(current)}
    for _ in range(4):
        grown = _forward(engine, testable, [], candidates, say, selection_z, min_relative_gain, current)
        if set(grown) == set(current):
            break
        grown, more_swaps = settle_swaps(engine, grown, rivals, selection_z, say, reference)
        grown, grown_loo, more_eliminated = _backward(engine, grown, say, selection_z, reference)
        if frozenset(grown) in seen:
            break
        seen.add(frozenset(grown))
        current, loo, swaps, eliminated = grown, grown_loo, swaps + more_swaps, eliminated + more_eliminated
    # sets the greedy path cannot reach (geometry once transmission has taken its place), on the Gram blocks
    searched, search = search_sets(
        engine, current, steps[1].effect if len(steps) > 1 else None,
        [e for e in testable if e in current or e not in late], selection_z=selection_z, min_relative_gain=min_relative_gain, say=say,
        forward=lambda pool, start: _forward(engine, pool, [], candidates, say, selection_z, min_relative_gain, start),
        prune=lambda effects: _backward(engine, list(effects), say, selection_z)[0])
    if set(searched) != set(current):
        current, loo, more_eliminated = _backward(engine, [e for e in current if e in searched] +
                                                  [e for e in searched if e not in current], say, selection_z)
        eliminated = eliminated + more_eliminated
    relinearised = _relinearise_at_fit(engine, current, registered, candidate_set, notes)
    if relinearised:  # the chosen set judged again at the new linearisation
        current, loo, more_eliminated = _backward(engine, current, say, selection_z)
        eliminated = eliminated + more_eliminated
    # every step helps: no chosen effect whose own held-out share, or rung of the ladder, is a loss
    while (harmful := harmful_effect(engine, current, loo)) is not None:
        row = next((r for r in loo if r.effect == harmful), None)
        eliminated = eliminated + [Elimination(harmful, row.z if row else 0.0, row.increase if row else 0.0)]
        current, loo, more_eliminated = _backward(engine, [e for e in current if e != harmful], say, selection_z)
        eliminated = eliminated + more_eliminated
    groups = swap_alternatives(engine, current, rivals, selection_z)
    return Selection(selected=tuple(current), forward_steps=tuple(steps), candidates=tuple(candidates.values()),
                     testable=tuple(testable), late=tuple(late), rivals=tuple(rivals), swaps=tuple(swaps),
                     leave_one_out=tuple(loo), eliminated=tuple(eliminated), groups=groups,
                     ambiguous=tuple(ambiguity_report(groups)), search=search, gap_residual=result["train_residual"],
                     notes=tuple(notes))


def _forward(engine: FitEngine, testable, steps: list, candidates: dict, say, selection_z: float,
             min_relative_gain: float, start=None) -> list:
    """Forward selection from ``start`` (default frames alone) over the testable effects;
    each effect's first trial is recorded in ``candidates`` (against frames alone, or
    against the model it was first tried on)."""
    current = ["frames"] if start is None else list(start)
    pool = [e for e in testable if e not in current]
    fresh = [e for e in pool if not (e in candidates and candidates[e].tried)]
    while pool:
        trials = {}
        for e in pool:
            say(f"step {len(steps)}: trying {e}")
            trials[e] = engine.evaluate(ordered(current + [e]))
        prev = engine.evaluate(ordered(current))
        prev_rms = ErrorStats.heldout(prev).rms
        for e in fresh:
            r = trials[e]
            rms = ErrorStats.heldout(r).rms
            candidates[e] = Candidate(e, True, heldout_rms=rms, gain=prev_rms - rms,
                                      z=paired_z(prev["heldout_squares"], r["heldout_squares"]),
                                      n_parameters=r["n_parameters"] - prev["n_parameters"],
                                      added_to=tuple(current) if len(current) > 1 else ())
        fresh = []
        best = _plausible_best(engine, trials)
        r = trials[best]
        rms = ErrorStats.heldout(r).rms
        z = entry_z(prev["heldout_squares"], r["heldout_squares"])
        if not (z > selection_z and rms < prev_rms * (1.0 - min_relative_gain)):
            break
        current.append(best)
        pool.remove(best)
        steps.append(Step(best, tuple(ordered(current)), r["n_parameters"],
                          r["train_stats"].rms, ErrorStats.heldout(r), z))
    return current


def _plausible_best(engine: FitEngine, trials: dict) -> str:
    """The candidate to take: of those whose held-out errors the rows do not rank more than one
    standard error above the best's (paired), one whose parameters its own physics explains
    (:func:`~tcr_accuracy.diagnosis.uncertainty.implausibility` at most 1), then the first in the
    vocabulary (the more basic cause: an encoder offset before a dead band that mimics it), then
    the lower error. An effect that explains the data only at sizes far from its own physics loses
    to one that explains them as well at typical sizes (gravity sag through degrees of gear
    harmonics, say), and a stand-in does not win a step by a hair."""
    rms = {e: ErrorStats.heldout(r).rms for e, r in trials.items()}
    best = min(rms, key=rms.get)
    near = [e for e in trials if e == best or paired_z(trials[e]["heldout_squares"], trials[best]["heldout_squares"])
            < 1.0]
    order = {e: k for k, e in enumerate(ordered(list(trials)))}  # the vocabulary's: the more basic cause first
    return min(near, key=lambda e: (implausibility(trials[e], engine.bases, e) > 1.0, order[e], rms[e]))


def _backward(engine: FitEngine, current: list, say, selection_z: float, reference: np.ndarray | None = None):
    """Backward elimination: an effect that no longer earns its place once the others are
    in (a flexible one picked early that later effects explain better) goes out, unless the
    model without it is significantly worse than ``reference`` (the per-row held-out squared
    errors of the best model seen): one by one, eliminations must not add up to a worse model."""
    eliminated = []
    while True:
        chosen = [e for e in current if e != "frames"]
        final = engine.evaluate(ordered(current))
        final_rms = ErrorStats.heldout(final).rms
        keep = engine.kept(tuple(ordered(current)))
        loo = []
        for e in chosen:
            say(f"leave-one-out: {e}")
            rest = ordered([s for s in current if s != e])
            r = engine.evaluate(rest)
            own = engine.evaluate(rest, keep={s: keep[s] for s in rest})
            held, held_own = ErrorStats.heldout(r), ErrorStats.heldout(own)
            loo.append(LeaveOneOut(effect=e, heldout=held, increase=held.rms - final_rms,
                                   z=entry_z(r["heldout_squares"], final["heldout_squares"]),
                                   own_share_heldout=held_own, own_share_increase=held_own.rms - final_rms))
        weakest = min(loo, key=lambda row: row.z) if loo else None
        if weakest is None or weakest.z > selection_z or (reference is not None and not within_reach(
                engine.evaluate(ordered([s for s in current if s != weakest.effect]))["heldout_squares"],
                reference, selection_z)):
            return current, loo, eliminated
        eliminated.append(Elimination(weakest.effect, weakest.z, weakest.increase))
        current.remove(weakest.effect)


def _relinearise_at_fit(engine: FitEngine, current, registered: RegisteredMeasurements, candidate_set: CandidateSet,
                        notes: list, tolerance: float = 1.05) -> bool:
    """The engine's Jacobian is taken once, at the frames-only fit; where the chosen effects turn
    the joints by degrees (a gear ratio off by percents) that Jacobian no longer points to the
    optimum and the fit stops short of it: its training error then exceeds its held-out error,
    which a converged fit never does. Then every effect is linearised again at the fitted robot
    (each pose at its own fitted joint values and placements) and the model refitted; the new
    linearisation is kept where it lowers the training error."""
    final = engine.evaluate(ordered(current), exact=True)  # the linear model cannot see its own linearisation
    if final["train_stats"].rms <= tolerance * ErrorStats.heldout(final).rms:
        return False
    theta = final["phi"] * final["scale"]
    cols = engine.columns(ordered(current), final["keep"])
    jacobians = []
    for p, part in enumerate(registered.parts):
        basis, _, idx = cols.per_part[p]
        x = basis.errors(theta[idx])  # (N, p_em): each pose's fitted error vector, joint-side offsets included
        em = engine.ems[p]
        q_fitted = part.q + x[:, em.drive_slice]
        x[:, em.drive_slice] = 0.0
        jacobians.append(position_jacobians(part.robot, q_fitted, x, part.orientation_weight
                                            if part.target_rotation is not None else None))
    before = final["cost"]
    state = engine.checkpoint()
    relinearise(engine.bases, jacobians)
    engine.reset(anchor=ordered(current))  # the linear model taken at the fitted robot
    after = engine.evaluate(ordered(current), exact=True)["cost"]
    if after < before * 0.99:
        notes.append(f"the chosen effects turn the joints far enough that the Jacobian was taken again at the fitted "
                     f"robot: training RMS {np.sqrt(before / final['n_observations']) * 1e3:.4g} -> "
                     f"{np.sqrt(after / final['n_observations']) * 1e3:.4g} mm per coordinate")
        return True
    relinearise(engine.bases, candidate_set.linearised())  # no better: back to the frames-only linearisation
    engine.restore(state)  # and to the fits made on it
    return False


def _judge_at_fitted_sizes(engine: FitEngine, current, notes: list, factor: float = 2.0) -> bool:
    """Identifiability was judged at typical sizes; an effect fitted at more than ``factor``
    times its typical size is re-judged at its fitted size (RMS of its scaled parameters), so
    that columns too small to resolve at the typical size but not at the fitted one come back."""
    final = engine.evaluate(ordered(current))
    factors, offset = {}, 0
    for e in ordered(current):
        size = final["keep"][e].size
        phi = final["phi"][offset:offset + size]
        offset += size
        if e != "frames" and size and float(np.sqrt(np.mean(phi**2))) > factor:
            factors[e] = float(np.sqrt(np.mean(phi**2)))
    before = {e: tuple(v) for e, v in engine.kept(tuple(ordered(current))).items()}
    if not engine.resize(factors):
        return False
    after = {e: tuple(v) for e, v in engine.kept(tuple(ordered(current))).items()}
    if after != before:
        notes.append("identifiability re-judged at the fitted sizes ("
                      + ", ".join(f"{e} {f:.3g} x typical" for e, f in factors.items())
                      + f"): {sum(len(v) for v in after.values()) - sum(len(v) for v in before.values()):+d} "
                      "parameters")
        return True
    return False


def _first_frame(residual: np.ndarray) -> np.ndarray:
    """The first measured frame's (N, 3) rows of a (N, 3) or (n_parts, N, 3) residual."""
    return residual if residual.ndim == 2 else residual[0]
