"""Stage 3, the search beyond the greedy path: effect sets that forward steps, single swaps and
backward elimination cannot reach, compared on the repeated k-fold held-out error.

Forward selection takes the largest single gain first; an effect that fits the data best alone
(a transmission error's harmonics standing in for geometry plus joint compliance, say) can take
the place of two that explain them together, and neither a swap (one effect for one) nor
backward elimination (which only removes) brings them back. Two searches leave that path, each
model fitted on the engine's Gram sub-blocks (no exact fit until the answer is chosen):

* **restarts**: forward selection again from frames alone, each chosen effect left out in turn
  (it may come back once the others are in), then backward elimination;
* **beam**: forward selection keeping the best few sets of each size (by held-out error) whose
  last step passes the selection's entry test, not only the best one.

Every set each path ends on is pruned by backward elimination and compared with the greedy
path's set by the **one-standard-error rule** on the per-row held-out squared errors (paired
over the same rows and fold assignments): the greedy set stays when it is within one standard
error of the best set found (the tie, said); else, of the sets within one standard error of the
best, the one whose fitted sizes its physics explains, then with the fewest parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..ambiguity import one_standard_error_choice
from ..bases import ordered
from ..fitting import FitEngine
from ..paired import entry_z, row_squares
from ..records import ErrorStats
from ..uncertainty import implausibility

#: sets kept at each size by the beam (0: no beam). Off: on the blind benchmark (seed 0, 40
#: scenarios), Justin and the UR5 it never ended on a better set than the greedy path, and it
#: costs a quarter of Justin's diagnosis
BEAM_WIDTH = 0
#: which chosen effects the restarts leave out: "first" (the one forward selection took first, the
#: largest single gain: the path's one way to shut out the effects it stands in for) or "all".
#: "first": restarts without each of the others never ended on a better set on the blind benchmark
#: (seed 0), Justin or the UR5, and cost 4 times as much
RESTARTS = "first"


@dataclass(frozen=True)
class SearchPath:
    """Where one path of the search ended (SI units).

    Attributes
    ----------
    path : str
        ``greedy``, ``beam`` or ``restart without <effect>``.
    effects : tuple of str
        The set it ended on, pruned by backward elimination.
    heldout : ErrorStats
        Its held-out errors (pooled over the fold assignments).
    n_parameters : int
    """

    path: str
    effects: tuple
    heldout: ErrorStats
    n_parameters: int

    def to_dict(self) -> dict:
        return {"path": self.path, "effects": list(self.effects), "heldout_rms_mm": self.heldout.rms * 1e3,
                "n_parameters": self.n_parameters}


@dataclass(frozen=True)
class SearchReport:
    """What the search beyond the greedy path tried and what it chose (SI units).

    Attributes
    ----------
    n_sets : int
        Models the whole selection fitted on the Gram sub-blocks (forward steps, swaps,
        eliminations, own shares and the search).
    paths : tuple of SearchPath
        Where each path ended, the greedy one first.
    chosen_path : str
        The path the chosen set came from (the first that ended on it).
    chosen : tuple of str
    alternative : SearchPath or None
        The best set another path ended on (not the chosen set), or None when every path ended
        on the chosen one.
    margin : float
        Held-out mean squared error of the alternative less the chosen's [m^2] (per row).
    margin_se : float
        Standard error of that paired difference [m^2].
    """

    n_sets: int
    paths: tuple
    chosen_path: str
    chosen: tuple
    alternative: SearchPath | None
    margin: float
    margin_se: float

    @property
    def beats_alternative(self) -> bool:
        """Whether the chosen set is better than the best other one by more than a standard error."""
        return self.alternative is None or self.margin > self.margin_se

    def to_dict(self) -> dict:
        return {"sets_evaluated": self.n_sets, "chosen_path": self.chosen_path, "chosen": list(self.chosen),
                "paths": [p.to_dict() for p in self.paths],
                "alternative": None if self.alternative is None else self.alternative.to_dict(),
                "alternative_margin_mm2": self.margin * 1e6, "alternative_margin_se_mm2": self.margin_se * 1e6,
                "beats_alternative": self.beats_alternative}

    def note(self) -> str:
        """One sentence: what the search tried and how clearly the chosen set wins."""
        text = (f"search beyond the greedy path: {self.n_sets} models fitted, {len(self.paths)} paths "
                f"compared; chosen [{', '.join(self.chosen)}] from the {self.chosen_path} path")
        if self.alternative is None:
            return text + "; every path ended on it"
        other = (f"the best set on another path, [{', '.join(self.alternative.effects)}] "
                 f"({self.alternative.path}), held-out RMS {self.alternative.heldout.rms * 1e3:.4g} mm")
        if self.beats_alternative:
            return text + f"; it beats {other}, by more than one standard error"
        return text + f"; a tie with {other}: within one standard error, the held-out rows cannot rank them"


def search_sets(engine: FitEngine, greedy: list, first: str | None, testable: list, *, forward, prune,
                selection_z: float, min_relative_gain: float, width: int | None = None, restarts: str | None = None,
                say=lambda message: None) -> tuple[list, SearchReport]:
    """Search beyond the greedy path; the set to keep and what was tried.

    Parameters
    ----------
    engine : FitEngine
    greedy : list of str
        The set the greedy path (forward selection, swaps, eliminations) ended on.
    first : str or None
        The effect forward selection took first (the largest single gain), None if none.
    testable : list of str
        The effects that may enter (the penalised ones of last resort only where the greedy path
        took them: their fits cost the most).
    forward : callable(pool, start) -> list of str
        The selection's forward step: from the set ``start``, over the effects of ``pool``.
    prune : callable(list of str) -> list of str
        The selection's backward elimination.
    selection_z, min_relative_gain : float
        The selection's entry test (see :func:`~.select.select_effects`): each step of the beam passes it.
    width : int, default :data:`BEAM_WIDTH`
        Sets kept at each size by the beam (0: no beam).
    restarts : {"first", "all"}, default :data:`RESTARTS`
        Restart without the effect taken first, or without each chosen effect in turn.
    """
    width = BEAM_WIDTH if width is None else width
    restarts = RESTARTS if restarts is None else restarts
    paths = [_ended(engine, "greedy", greedy)]
    left_out = [s for s in greedy if s != "frames"] if restarts == "all" else []
    if first is not None and first not in left_out:  # the path that never takes the largest single gain
        left_out.insert(0, first)
    for e in left_out:
        say(f"search: forward again without {e}")
        started = forward([s for s in testable if s != e], ["frames"])
        regrown = forward(testable, started)  # it may come back once the others are in
        paths.append(_ended(engine, f"restart without {e}", prune(regrown)))
    if width:
        say("search: beam over effect sets")
        paths.append(_ended(engine, "beam", prune(beam(engine, testable, width=width, entry=lambda before, after:
                                                       _entry_passes(before, after, selection_z, min_relative_gain)))))
    rows = {}
    for p in paths:  # one row per distinct set, the first path that ended on it
        rows.setdefault(frozenset(p.effects), _row(engine, p))
    best = min(rows.values(), key=lambda r: r["_squares"].mean())
    greedy_row = rows[frozenset(paths[0].effects)]
    chosen_row = greedy_row if _within_one_se(greedy_row, best) else one_standard_error_choice(
        [r for r in rows.values() if _within_one_se(r, best)])
    chosen = list(chosen_row["effects"])
    others = [r for r in rows.values() if r is not chosen_row]
    alternative = min(others, key=lambda r: r["_squares"].mean()) if others else None
    margin = se = 0.0
    if alternative is not None:
        d = alternative["_squares"] - chosen_row["_squares"]
        margin, se = float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.size)) if d.size > 1 else 0.0
    report = SearchReport(n_sets=engine.n_fits, paths=tuple(paths), chosen_path=chosen_row["path"].path,
                          chosen=tuple(ordered(chosen)), alternative=None if alternative is None else alternative["path"],
                          margin=margin, margin_se=se)
    return chosen, report


def beam(engine: FitEngine, testable: list, *, entry, width: int) -> list:
    """Forward selection keeping the ``width`` best sets of each size whose last step passes
    ``entry(before, after)`` (two fits) (the selection's entry test); the best set seen, by held-out
    mean squared error (the frontier ordered by it, sizes their physics explains first)."""
    frontier = [("frames",)]
    best = ("frames",)
    best_key = _rank(engine, best)[1]
    seen = {frozenset(best)}
    while frontier:
        grown = {}
        for parent in frontier:
            before = engine.evaluate(ordered(list(parent)))
            for e in testable:
                child = frozenset(parent + (e,))
                if e in parent or child in seen:
                    continue
                seen.add(child)
                after = engine.evaluate(ordered(list(child)))
                if entry(before, after):
                    grown[child] = tuple(ordered(list(child)))
        ranked = sorted(grown.values(), key=lambda s: _rank(engine, s))[:width]
        for s in ranked:  # the best by held-out error: sizes beyond physics only order the frontier
            if _rank(engine, s)[1] < best_key:
                best, best_key = s, _rank(engine, s)[1]
        frontier = ranked
    return list(best)


def _entry_passes(before: dict, after: dict, selection_z: float, min_relative_gain: float) -> bool:
    return entry_z(before["heldout_squares"], after["heldout_squares"]) > selection_z and \
        ErrorStats.heldout(after).rms < ErrorStats.heldout(before).rms * (1.0 - min_relative_gain)


def _rank(engine: FitEngine, effects) -> tuple:
    r = engine.evaluate(ordered(list(effects)))
    plausible = all(implausibility(r, engine.bases, e) <= 1.0 for e in effects if e != "frames")
    return (not plausible, float(np.mean(r["heldout_squares"])))


def _ended(engine: FitEngine, path: str, effects) -> SearchPath:
    r = engine.evaluate(ordered(list(effects)))
    return SearchPath(path, tuple(ordered(list(effects))), ErrorStats.heldout(r), r["n_parameters"])


def _row(engine: FitEngine, path: SearchPath) -> dict:
    r = engine.evaluate(ordered(list(path.effects)))
    beyond = max((implausibility(r, engine.bases, e) for e in path.effects if e != "frames"), default=0.0)
    return {"path": path, "effects": list(path.effects), "n_parameters": path.n_parameters,
            "size_over_physics": beyond, "_squares": row_squares(r["heldout_squares"])}


def _within_one_se(row: dict, best: dict) -> bool:
    d = row["_squares"] - best["_squares"]
    return d.size < 2 or d.mean() <= d.std(ddof=1) / math.sqrt(d.size)


def explanation_order(engine: FitEngine, selected) -> list:
    """The chosen effects in the order they explain the data: from frames, each step the effect
    that lowers the held-out error most given those before it (on the engine's linear model).
    Returns ``[(effect, exact fit of the set up to it)]``, frames first (the ladder's rungs)."""
    current = ["frames"]
    rungs = [("frames", engine.evaluate(["frames"], exact=True))]
    remaining = [e for e in selected if e != "frames"]
    while remaining:
        trials = {e: engine.evaluate(ordered(current + [e])) for e in remaining}
        best = min(trials, key=lambda e: ErrorStats.heldout(trials[e]).rms)
        current.append(best)
        remaining.remove(best)
        rungs.append((best, engine.evaluate(ordered(current), exact=True)))
    return rungs


def harmful_effect(engine: FitEngine, selected, leave_one_out) -> str | None:
    """A chosen effect that does not help: its own held-out share below zero (the held-out error
    falls without it, the others held to their parameters, or refitted), or its rung of the
    ladder (exact kinematics) raising the held-out error. The worst such, or None."""
    worst, by = None, 0.0
    for row in leave_one_out:
        change = min(row.own_share_increase, row.increase)
        if change < by:
            worst, by = row.effect, change
    if worst is not None:
        return worst
    rungs = explanation_order(engine, selected)
    for (_, before), (effect, after) in zip(rungs, rungs[1:]):
        change = ErrorStats.heldout(before).rms - ErrorStats.heldout(after).rms
        if change < by:  # by is 0 here and falls: a rung that raised the error, the worst such
            worst, by = effect, change
    return worst
