"""Stage 4: attribute the gap -- what mechanism each chosen effect's fitted signature stands for,
the families of effects and their shares, the primary family and, where the data tell the members
apart, the primary effect; the shrink table in the order the chosen effects explain the data, how
stable the selection is, and where the first-order effect models end.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ...effects.mechanisms import FAMILIES, MechanismReading, read_mechanism
from ..attribution import ShareComparison, contributions, fixed_point_check, rank_largest
from ..confounding import confounded_variables, reproduced_share
from ..error_map import column_rms
from ..fitting import FitEngine
from ..bases import ordered
from ..paired import paired_z
from ..records import ErrorStats, Step
from ..uncertainty import PoseBootstrap, bootstrap_for, selection_frequency
from .candidates import CandidateSet, build_bases, relinearise
from .register import RegisteredMeasurements, measured_context
from .search import explanation_order
from .select import Selection


@dataclass(frozen=True)
class FamilyShare:
    """A family of chosen effects and what it accounts for (SI units).

    Attributes
    ----------
    family : str
    effects : tuple of str
        Its chosen members.
    share : float
        How much the held-out RMS rises without the whole family (and what stands in for its
        members), the other effects held to their parameters [m].
    interval : (float, float)
        The share's 95 % interval [m] (the pose bootstrap's, :class:`~..uncertainty.PoseBootstrap`).
    heldout_without : ErrorStats
        Held-out errors without the family.
    stand_ins : tuple of str
        Unchosen effects the data cannot tell from its members, in the model beside them while the
        shares are measured and removed with the family.
    below_largest : ShareComparison or None
        The largest family's share against this one's (paired, the same replicates): by how much it
        is larger, and whether the held-out rows rank the two apart; None for the largest itself.
    """

    family: str
    effects: tuple
    share: float
    interval: tuple
    heldout_without: ErrorStats
    stand_ins: tuple = ()
    below_largest: ShareComparison | None = None

    def to_dict(self) -> dict:
        out = {"family": self.family, "effects": list(self.effects), "share_mm": self.share * 1e3,
               "interval_mm": [self.interval[0] * 1e3, self.interval[1] * 1e3],
               "heldout_rms_without_mm": self.heldout_without.rms * 1e3, "what": FAMILIES.get(self.family, ""),
               "stand_ins": list(self.stand_ins)}
        if self.below_largest is not None:
            out["below_largest"] = self.below_largest.to_dict()
        return out


@dataclass(frozen=True)
class Attribution:
    """What stage 4 found.

    Attributes
    ----------
    primary_effect : str or None
        The chosen effect the data single out as the largest cause, None where they cannot
        tell it from another (then :attr:`primary_family` is the answer).
    primary_group : tuple of str
        The primary effect and what stands in for it or ties with it.
    primary_tied : tuple of str
        The largest own share and those not ranked below it by the held-out rows.
    primary_family : str or None
        The family with the largest share, when the held-out rows rank it above the others (the
        selection's paired test above ``selection_z`` and the 95 % interval of the difference of the
        two shares above zero, each family's ``below_largest``).
    families : tuple of FamilyShare
        Every family with a chosen member, largest share first.
    mechanisms : tuple of MechanismReading
        For every chosen effect, the mechanism its fitted sign and size fit.
    confounding : tuple of Confounding
        Variables that follow the measurement order (the effects they confound).
    steps : tuple of Step
        The shrink table in the order of explanation (with each step's gain and interval).
    stability : dict
        How often bootstrap replays of the selection choose each effect (JSON form).
    notes : tuple of str
    own_shares : dict
        Chosen effect -> (own share, low, high) [m]: how much the held-out RMS rises without it, the
        others held to their own parameters, with its 95 % interval.
    own_share_ranking : tuple of ShareComparison
        The largest own share against the others the primary effect was chosen among.
    interval_method : str
        How every held-out interval here was made (the pose bootstrap, in words).
    """

    primary_effect: str | None
    primary_group: tuple
    primary_tied: tuple
    primary_family: str | None
    families: tuple
    mechanisms: tuple
    confounding: tuple
    steps: tuple
    stability: dict
    notes: tuple
    own_shares: dict = dataclasses.field(default_factory=dict)
    own_share_ranking: tuple = ()
    interval_method: str = ""

    def mechanism_of(self, effect: str) -> MechanismReading | None:
        return next((m for m in self.mechanisms if m.effect == effect), None)


def attribute_effects(registered: RegisteredMeasurements, candidate_set: CandidateSet, selection: Selection, *,
                      selection_z: float, min_relative_gain: float, stability_replays: int, seed: int,
                      say=lambda message: None) -> Attribution:
    """Stage 4 of the diagnosis.

    Parameters
    ----------
    registered, candidate_set, selection : the results of stages 1-3
    selection_z, min_relative_gain : the selection test (see :func:`~.select.select_effects`)
    stability_replays : int
        Bootstrap replays of the selection.
    seed : int
        Seeds the replays (their own stream).
    """
    engine = candidate_set.engine
    current = list(selection.selected)
    notes: list = []
    confounding = confounded_variables(registered.robot.joint_names, registered.measurements.q,
                                       registered.parts[0].context, measured_context(registered.measurements))
    confounding = judged_on_signatures(registered, candidate_set, current, confounding)
    mechanisms = tuple(_with_assumptions(_with_confounding(m, confounding), engine, registered.measurements.time_s)
                       for m in fitted_mechanisms(engine, current))
    notes += [f"{m.effect}: {assumed}" for m in mechanisms for assumed in m.assumed]
    unexplained = [m.effect for m in mechanisms if not m.physical]
    confounded = [m.effect for m in mechanisms if m.confounded]
    stand_ins = stand_ins_of(selection.groups)
    # one bootstrap over the poses for every held-out interval and comparison below (its own stream)
    bootstrap = bootstrap_for(engine, np.random.default_rng([seed, 3]))
    families = _family_table(engine, current, stand_ins, bootstrap, selection_z)
    top_families = [f.family for f in families if f.below_largest is None or not f.below_largest.ranked]
    primary_family = top_families[0] if len(top_families) == 1 else None
    sizes = motion_sizes(engine, current, {**{e: [e] for e in current if e != "frames"},
                                           **{_FAMILY + f.family: list(f.effects) for f in families}})
    if primary_family is not None:
        larger = larger_motion(sizes, _FAMILY + primary_family, [_FAMILY + f.family for f in families], selection_z)
        if larger:
            notes.append(_motion_note(sizes, _FAMILY + primary_family, larger, "family"))
            primary_family = None
    own_table, own_shares = _own_shares(engine, current, bootstrap)
    # within the primary family (or among every chosen effect when no family stands out): the member
    # with the largest own share and those the held-out rows do not rank below it
    members = [e for e in current if e != "frames" and e in own_shares]
    if primary_family is not None:
        members = [e for e in members if _family(engine, e) == primary_family]
    own_share_ranking = rank_largest(*own_table, members, "final", selection_z)
    tied = [own_share_ranking[0].larger] + [c.smaller for c in own_share_ranking if not c.ranked] \
        if own_share_ranking else members[:1]
    primary = tied[0] if tied else None
    if primary is not None:  # and those of another family whose fitted motion is larger, beyond doubt (within
        # a family, how the motion is split between its members is the identifiable columns' partition: a
        # joint placement's turn about its axis is a joint offset)
        others = [e for e in members if _family(engine, e) != _family(engine, primary)]
        larger = [e for e in larger_motion(sizes, primary, others, selection_z) if e not in tied]
        if larger:
            notes.append(_motion_note(sizes, primary, larger, "effect"))
            tied += larger
    primary_group = group_members(selection.groups, primary)
    primary_group += [e for e in tied[1:] if e not in primary_group]
    if primary is not None and any(_family(engine, e) != primary_family for e in primary_group) and \
            primary_family is not None:
        primary_family = None  # a stand-in from another family: not even the family is resolved
    if confounded and set(confounded) & set(primary_group):
        notes.append(f"{', '.join(confounded)}: cannot be told from a drift in time ("
                     + "; ".join(c for m in mechanisms for c in m.confounded) + "); not named as the cause: measure "
                     "in an order that does not follow the joints (tcr-accuracy plan-poses writes one)")
        primary_group = ordered(set(primary_group) | {"drift"})
        primary_family = None
    if unexplained and set(unexplained) & set(primary_group):
        notes.append(f"{', '.join(unexplained)}: fitted values that no known mechanism explains; not named as the "
                     "cause (see the mechanisms)")
        primary_group = [e for e in primary_group if e not in unexplained]
    if len(primary_group) != 1:
        primary = None  # the data cannot say which of the group it is
        primary_group = ordered(primary_group)
    else:
        primary = primary_group[0]
    # the shrink table in the order the chosen effects explain the data
    steps = explanation_ladder(engine, current, selection.forward_steps[0], bootstrap)
    say("selection stability")
    testable = list(selection.testable)
    stability = selection_frequency(engine, testable, selection_z, min_relative_gain, stability_replays,
                                    np.random.default_rng([seed, 2]), say,
                                    late=[e for e in selection.late if e in testable])
    return Attribution(primary_effect=primary, primary_group=tuple(primary_group), primary_tied=tuple(tied),
                       primary_family=primary_family, families=tuple(families), mechanisms=mechanisms,
                       confounding=tuple(confounding), steps=tuple(steps), stability=stability, notes=tuple(notes),
                       own_shares=own_shares, own_share_ranking=tuple(own_share_ranking),
                       interval_method=bootstrap.method)


def judged_on_signatures(registered: RegisteredMeasurements, candidate_set: CandidateSet, current,
                         confounding) -> list:
    """Each variable that follows the measurement order, with the share of every chosen effect's
    signature it may confound that the drift model reproduces on these poses
    (:func:`~tcr_accuracy.diagnosis.confounding.reproduced_share`: the effect's fitted TCP errors fitted
    by the drift's and the tracker frame's columns, least squares over the poses)."""
    chosen = [e for c in confounding for e in c.effects if e in current]
    if not chosen:
        return list(confounding)
    engine = candidate_set.engine
    drift = engine.bases.get("drift")
    if drift is None:  # not in the vocabulary asked for: linearised here, as the other effects were
        built, _, _ = build_bases(list(registered.parts), ["drift"], registered.measured_context, [],
                                  registered.session_labels)
        if "drift" not in built:
            return list(confounding)
        relinearise(built, candidate_set.linearised())
        drift = built["drift"]
    final = engine.evaluate(ordered(current), exact=True)
    theta = final["phi"] * final["scale"]
    signatures, offset = {}, 0
    for e in ordered(current):
        kept = final["keep"][e]
        basis = engine.bases[e]
        full = np.zeros(len(basis.names))
        full[kept] = theta[offset:offset + kept.size]
        offset += kept.size
        if e in chosen:  # the main measured frame's TCP errors this effect's fitted values make
            part = basis.per_part[0]
            signatures[e] = np.einsum("nrk,k->nr", part.g[0:part.g.shape[0]][:, :3], full[basis.index[0]])
    frames_g = engine.bases["frames"].per_part[0].g
    frames_g = frames_g[0:frames_g.shape[0]][:, :3]
    drift_g = drift.per_part[0].g
    drift_g = drift_g[0:drift_g.shape[0]][:, :3]
    return [dataclasses.replace(c, reproduced={e: reproduced_share(signatures[e], drift_g, frames_g)
                                               for e in c.effects if e in signatures}) for c in confounding]


def _with_confounding(reading: MechanismReading, confounding) -> MechanismReading:
    """The reading, said to be indistinguishable from a drift in time where a variable its
    resolved parameters grow with follows the measurement order and the drift model reproduces
    most of its signature (:meth:`~tcr_accuracy.diagnosis.confounding.Confounding.confounds`)."""
    why = []
    for c in confounding:
        if not c.confounds(reading.effect):
            continue
        if c.variable.startswith("joint ") and not any(
                p["parameter"].split(".")[1] == c.variable[len("joint "):] for p in reading.parameters):
            continue
        why.append(c.to_dict()["why"])
    if not why:
        return reading
    return dataclasses.replace(reading, mechanism=reading.mechanism + "; or a drift in time, which the data cannot "
                               "tell it from: " + "; ".join(why), confounded=tuple(why))


def _with_assumptions(reading: MechanismReading, engine: FitEngine, time_s) -> MechanismReading:
    """The reading, with what its fit assumed: an effect of time (drift) fitted on the measurement order
    because the rows carry no time (``time_s`` absent, constant or incomplete) took that order for time."""
    effect = engine.bases[reading.effect].per_part[0].effect
    if getattr(effect, "time_axis", None) != "order":
        return reading
    why = "no time_s column" if time_s is None else "a time_s column that does not vary (or has gaps)"
    return dataclasses.replace(reading, assumed=reading.assumed + (
        f"fitted on the measurement order: the rows carry {why}, so their order was taken for time (each row one "
        "equal step after the one before)",))


def _family(engine: FitEngine, effect: str) -> str:
    return engine.bases[effect].per_part[0].effect.family


def fitted_mechanisms(engine: FitEngine, current) -> list[MechanismReading]:
    """Each chosen effect's mechanism, read from its fitted values and standard errors (the main
    measured frame's parameters)."""
    final = engine.evaluate(ordered(current), exact=True)
    theta = final["phi"] * final["scale"]
    std = final["phi_std"] * final["scale"]
    out, offset = [], 0
    for e in ordered(current):
        basis = engine.bases[e]
        kept = final["keep"][e]
        values, spread = np.zeros(len(basis.names)), np.full(len(basis.names), np.inf)
        pinned = np.zeros(len(basis.names), dtype=bool)
        values[kept] = theta[offset:offset + kept.size]
        spread[kept] = std[offset:offset + kept.size]
        pinned[kept] = final["at_bound"][offset:offset + kept.size] & np.isfinite(final["lower"][offset:offset + kept.size])
        offset += kept.size
        effect = basis.per_part[0].effect
        index = basis.index[0]
        motion = column_rms(basis.per_part[0].g, slice(0, 3))  # TCP position motion per unit of each parameter
        out.append(read_mechanism(effect, values[index], spread[index], [basis.names[i] for i in index], motion,
                                  pinned[index]))
    return out


def _without(engine: FitEngine, current, dropped) -> dict:
    """The final model without some effects, the others held to their own parameters."""
    keep = engine.kept(tuple(ordered(current)))
    rest = ordered([s for s in current if s not in dropped])
    return engine.evaluate(rest, keep={s: keep[s] for s in rest})


def group_members(groups: dict, chosen: str | None) -> list:
    """The chosen effect and every effect of what stands in for it, one name each (a stand-in with
    a companion, ``lateral_compliance+joint_offsets``, gives both its effects); [] for None."""
    if chosen is None:
        return []
    return list(dict.fromkeys([chosen] + [e for row in groups.get(chosen, []) for e in row["effects"]]))


def stand_ins_of(groups: dict) -> dict:
    """Chosen effect -> the unchosen effects that stand in for it (the swap alternatives the
    held-out rows do not rank below it)."""
    return {chosen: tuple(dict.fromkeys(e for row in rows[1:] for e in row["effects"] if e != chosen))
            for chosen, rows in groups.items()}


def _family_members(engine: FitEngine, current, stand_ins: dict) -> dict:
    """family -> (chosen members, their stand-ins), in the vocabulary's order."""
    members: dict = {}
    for e in ordered(current):
        if e != "frames":
            members.setdefault(_family(engine, e), []).append(e)
    return {family: (tuple(effects), tuple(dict.fromkeys(
        s for e in effects for s in stand_ins.get(e, ()) if s not in current)))
        for family, effects in members.items()}


def _joined(current, stand_ins: list) -> list:
    """The model the family shares are measured in: the chosen effects and every stand-in."""
    return ordered(set(current) | {s for extra in stand_ins for s in extra})


def family_shares(engine: FitEngine, current, stand_ins: dict | None = None,
                  bootstrap: PoseBootstrap | None = None, selection_z: float = 3.0) -> list[FamilyShare]:
    """Every family with a chosen member and its own share: how much the held-out RMS rises
    without all its members (the other effects held to their parameters), largest first, with its
    95 % interval from ``bootstrap`` (None: a pose bootstrap of the engine's rows, seed 0).

    The shares are measured in the chosen model joined by the stand-ins (``stand_ins``: chosen
    effect -> the unchosen effects the data cannot tell from it), and a family leaves with its
    members' stand-ins: which of two effects the data cannot tell apart was chosen (an encoder
    scale or a transmission error on 250 poses, say) must not decide how the rest of the gap is
    shared between the other families, since each takes a different part of them. Each family below
    the largest is compared with it (``below_largest``: ranked apart where the selection's paired test
    exceeds ``selection_z`` and the difference's 95 % interval lies above zero)."""
    return _family_table(engine, current, stand_ins or {}, bootstrap or bootstrap_for(engine, 0), selection_z)


def _family_table(engine: FitEngine, current, stand_ins: dict, bootstrap: PoseBootstrap,
                  selection_z: float) -> list[FamilyShare]:
    """:func:`family_shares`: every share and difference read on the same bootstrap replicates."""
    members = _family_members(engine, current, stand_ins)
    joined = _joined(current, [extra for _, extra in members.values()])
    squares = {"final": engine.evaluate(joined)["heldout_squares"]}
    held = {}
    for family, (effects, extra) in members.items():
        without = _without(engine, joined, effects + extra)
        squares[family], held[family] = without["heldout_squares"], ErrorStats.heldout(without)
    table = bootstrap.read(squares)
    out = []
    for family, (effects, extra) in members.items():
        share = table.difference(family, "final")
        out.append(FamilyShare(family, effects, share.value, (share.low, share.high), held[family], extra))
    out.sort(key=lambda f: -f.share)
    below = {c.smaller: c for c in rank_largest(table, squares, [f.family for f in out], "final", selection_z)}
    return [dataclasses.replace(f, below_largest=below.get(f.family)) for f in out]


def _own_shares(engine: FitEngine, current, bootstrap: PoseBootstrap) -> tuple:
    """((the bootstrap table of the final model and of it without each chosen effect, the others held
    to their own parameters, and their per-row squared errors); effect -> its own share (value, low,
    high) [m])."""
    keep = engine.kept(tuple(ordered(current)))
    squares = {"final": engine.evaluate(ordered(current))["heldout_squares"]}
    for e in current:
        if e != "frames":
            rest = ordered([s for s in current if s != e])
            squares[e] = engine.evaluate(rest, keep={s: keep[s] for s in rest})["heldout_squares"]
    table = bootstrap.read(squares)
    return (table, squares), {e: tuple(table.difference(e, "final")) for e in squares if e != "final"}


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


def explanation_ladder(engine: FitEngine, selected, first: Step, bootstrap: PoseBootstrap | None = None) -> list[Step]:
    """The shrink table in the order of explanation (:func:`~.search.explanation_order`: from frames,
    each step adds the chosen effect that lowers the held-out error most given those before it, on
    the engine's linear model), with its figures on the exact kinematics, its gain and the gain's
    95 % interval (``bootstrap``'s; None: a pose bootstrap of the engine's rows, seed 0)."""
    bootstrap = bootstrap or bootstrap_for(engine, 0)
    rungs = explanation_order(engine, selected)
    chain = [(first, rungs[0][1])]
    for effect, r in rungs[1:]:
        chain.append((Step(effect, tuple(r["effects"]), r["n_parameters"], r["train_stats"].rms,
                           ErrorStats.heldout(r), paired_z(chain[-1][1]["heldout_squares"], r["heldout_squares"])),
                      r))
    table = bootstrap.read({k: r["heldout_squares"] for k, (_, r) in enumerate(chain)})
    return [first] + [dataclasses.replace(step, gain=tuple(table.difference(k - 1, k)))
                      for k, (step, _) in enumerate(chain) if k > 0]


_FAMILY = "family "  # the key of a family's motion in :func:`motion_sizes`, beside the effects'


def larger_motion(sizes: "MotionSizes", name: str, others, threshold: float) -> list:
    """Those of ``others`` whose motion is larger than ``name``'s by more than ``threshold`` standard
    errors of the difference: the held-out share ranked ``name`` first, the TCP motion its fitted
    parameters cause does not, and the data cannot say which of the two is the larger cause."""
    out = []
    for other in others:
        if other != name:
            difference, se = sizes.difference(other, name)
            if difference > threshold * se:
                out.append(other)
    return out


def _motion_note(sizes: "MotionSizes", name: str, larger: list, level: str) -> str:
    """The note that the held-out share and the fitted motion rank ``name`` and ``larger`` differently."""
    def label(key):
        return key[len(_FAMILY):] if key.startswith(_FAMILY) else key

    others = "; ".join(f"{label(o)} {sizes.size[o] * 1e3:.4g} mm (larger by {sizes.difference(o, name)[0] * 1e3:.3g} "
                       f"+- {sizes.difference(o, name)[1] * 1e3:.2g} mm)" for o in larger)
    return (f"the {level} with the largest held-out share, {label(name)}, moves the TCP by {sizes.size[name] * 1e3:.4g} mm "
            f"RMS beyond the frames, less than {others}: the share and the motion rank them apart in opposite "
            f"orders, so the {level} is not named apart from {', '.join(label(o) for o in larger)}")


@dataclass(frozen=True)
class MotionSizes:
    """How large the TCP motion of groups of a model's parameters is beyond what a change of the
    frames could absorb, on the fit's own rows and metric (SI units), with the delta method's
    covariance of those sizes.

    Attributes
    ----------
    size : dict
        name -> RMS per row of the group's motion after the frames' best fit to it [m].
    gradient : dict
        name -> (k,) the size's derivative in the model's scaled parameters phi.
    covariance : numpy.ndarray
        (k, k) the covariance of phi (the training residual's variance times the inverse of the
        Gram matrix).
    """

    size: dict
    gradient: dict
    covariance: np.ndarray

    def difference(self, larger: str, smaller: str) -> tuple[float, float]:
        """(size of ``larger`` less size of ``smaller``, its standard error) [m]."""
        g = self.gradient[larger] - self.gradient[smaller]
        return self.size[larger] - self.size[smaller], float(np.sqrt(max(g @ self.covariance @ g, 0.0)))


def motion_sizes(engine: FitEngine, current, groups: dict) -> MotionSizes:
    """The size of each group's motion (``groups``: name -> effects of ``current``) in the chosen
    model's linear fit, after the frames (the Schur complement of the frames' columns in the Gram
    matrix: what the frames can fit is taken out, as the benchmark and the contribution table take
    a rigid frame change out), and what the data say of it: its gradient and the parameters'
    covariance, so that two sizes can be compared with the standard error of their difference.

    Every number here comes from the engine's total Gram matrix (no per-row array is made).
    """
    effects = ordered(current)
    fit = engine.evaluate(effects)
    keep = fit["keep"]
    store = engine.grams()
    index = store.layout.indices(effects, keep)
    gram = store.total[np.ix_(index, index)]
    phi = np.asarray(fit["phi"], dtype=float)
    at, spans = 0, {}
    for e in effects:
        spans[e] = np.arange(at, at + len(keep[e]))
        at += len(keep[e])
    frames = spans.get("frames", np.zeros(0, dtype=int))
    rest = np.setdiff1d(np.arange(index.size), frames)
    # S = G_rr - G_rf G_ff^+ G_fr: the Gram matrix of the columns after the frames are fitted out
    schur = gram[np.ix_(rest, rest)]
    if frames.size:
        schur = schur - gram[np.ix_(rest, frames)] @ np.linalg.pinv(gram[np.ix_(frames, frames)],
                                                                   hermitian=True) @ gram[np.ix_(frames, rest)]
    variance = fit["cost"] / max(fit["n_observations"] - index.size, 1)
    covariance = variance * np.linalg.pinv(gram, hermitian=True)
    where = {c: i for i, c in enumerate(rest)}
    n_rows = engine.n_rows * len(engine.parts)  # every measured frame's rows
    size, gradient = {}, {}
    for name, members in groups.items():
        cols = np.concatenate([spans[e] for e in members if e in spans and e != "frames"] or [np.zeros(0, int)])
        local = np.array([where[c] for c in cols], dtype=int)
        v = np.zeros(rest.size)
        v[local] = phi[cols]
        sv = schur @ v
        square = float(v @ sv) / n_rows
        size[name] = float(np.sqrt(max(square, 0.0)))
        g = np.zeros(index.size)
        mask = np.zeros(rest.size, dtype=bool)
        mask[local] = True
        g[rest[mask]] = sv[mask] / (n_rows * max(size[name], 1e-300))
        gradient[name] = g
    return MotionSizes(size, gradient, covariance)
