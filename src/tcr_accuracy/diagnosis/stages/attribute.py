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
from ..attribution import contributions, fixed_point_check, tied_own_shares
from ..confounding import confounded_variables
from ..error_map import column_rms
from ..fitting import FitEngine
from ..bases import ordered
from ..paired import entry_z, paired_z
from ..records import ErrorStats, Step
from ..uncertainty import difference_interval, selection_frequency
from .candidates import CandidateSet
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
        The share's 95 % interval [m].
    heldout_without : ErrorStats
        Held-out errors without the family.
    stand_ins : tuple of str
        Unchosen effects the data cannot tell from its members, in the model beside them while the
        shares are measured and removed with the family.
    """

    family: str
    effects: tuple
    share: float
    interval: tuple
    heldout_without: ErrorStats
    stand_ins: tuple = ()

    def to_dict(self) -> dict:
        return {"family": self.family, "effects": list(self.effects), "share_mm": self.share * 1e3,
                "interval_mm": [self.interval[0] * 1e3, self.interval[1] * 1e3],
                "heldout_rms_without_mm": self.heldout_without.rms * 1e3, "what": FAMILIES.get(self.family, ""),
                "stand_ins": list(self.stand_ins)}


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
        The family with the largest share, when the held-out rows rank it above the others.
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
    loo = [r.to_dict() for r in selection.leave_one_out]
    notes: list = []
    confounding = confounded_variables(registered.robot.joint_names, registered.measurements.q,
                                       registered.parts[0].context, measured_context(registered.measurements))
    mechanisms = tuple(_with_confounding(m, confounding) for m in fitted_mechanisms(engine, current))
    unexplained = [m.effect for m in mechanisms if not m.physical]
    confounded = [m.effect for m in mechanisms if m.confounded]
    stand_ins = stand_ins_of(selection.groups)
    families = family_shares(engine, current, stand_ins)
    top_families = _tied_families(engine, current, families, selection_z)
    primary_family = top_families[0] if len(top_families) == 1 else None
    # within the primary family (or among every chosen effect when no family stands out): the member
    # with the largest own share and those the held-out rows do not rank below it
    members = [e for e in current if e != "frames"]
    if primary_family is not None:
        members = [e for e in members if _family(engine, e) == primary_family]
    tied = tied_own_shares(engine, current, [r for r in loo if r["dropped"] in members], selection_z)
    primary = tied[0] if tied else None
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
    steps = explanation_ladder(engine, current, selection.forward_steps[0])
    say("selection stability")
    testable = list(selection.testable)
    stability = selection_frequency(engine, testable, selection_z, min_relative_gain, stability_replays,
                                    np.random.default_rng([seed, 2]), say,
                                    late=[e for e in selection.late if e in testable])
    return Attribution(primary_effect=primary, primary_group=tuple(primary_group), primary_tied=tuple(tied),
                       primary_family=primary_family, families=tuple(families), mechanisms=mechanisms,
                       confounding=tuple(confounding), steps=tuple(steps), stability=stability, notes=tuple(notes))


def _with_confounding(reading: MechanismReading, confounding) -> MechanismReading:
    """The reading, said to be indistinguishable from a drift in time where a variable its
    resolved parameters grow with follows the measurement order."""
    why = []
    for c in confounding:
        if reading.effect not in c.effects:
            continue
        if c.variable.startswith("joint ") and not any(
                p["parameter"].split(".")[1] == c.variable[len("joint "):] for p in reading.parameters):
            continue
        why.append(c.to_dict()["why"])
    if not why:
        return reading
    return dataclasses.replace(reading, mechanism=reading.mechanism + "; or a drift in time, which the data cannot "
                               "tell it from: " + "; ".join(why), confounded=tuple(why))


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


def family_shares(engine: FitEngine, current, stand_ins: dict | None = None) -> list[FamilyShare]:
    """Every family with a chosen member and its own share: how much the held-out RMS rises
    without all its members (the other effects held to their parameters), largest first.

    The shares are measured in the chosen model joined by the stand-ins (``stand_ins``: chosen
    effect -> the unchosen effects the data cannot tell from it), and a family leaves with its
    members' stand-ins: which of two effects the data cannot tell apart was chosen (an encoder
    scale or a transmission error on 250 poses, say) must not decide how the rest of the gap is
    shared between the other families, since each takes a different part of them."""
    members = _family_members(engine, current, stand_ins or {})
    joined = _joined(current, [extra for _, extra in members.values()])
    final = engine.evaluate(joined)
    final_rms = ErrorStats.heldout(final).rms
    out = []
    for family, (effects, extra) in members.items():
        without = _without(engine, joined, effects + extra)
        held = ErrorStats.heldout(without)
        _, low, high = difference_interval(without["heldout_squares"], final["heldout_squares"])
        out.append(FamilyShare(family, effects, held.rms - final_rms, (low, high), held, extra))
    out.sort(key=lambda f: -f.share)
    return out


def _tied_families(engine: FitEngine, current, families: list, selection_z: float) -> list:
    """The first family and those whose removal the held-out rows do not rank below its removal
    (the selection's test, :func:`~..paired.entry_z`, on the rows without each, in the model the
    shares were measured in)."""
    if not families:
        return []
    joined = _joined(current, [f.stand_ins for f in families])
    removed = {f.family: f.effects + f.stand_ins for f in families}
    top = _without(engine, joined, removed[families[0].family])["heldout_squares"]
    return [families[0].family] + [f.family for f in families[1:]
                                   if entry_z(top, _without(engine, joined, removed[f.family])["heldout_squares"])
                                   < selection_z]


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
    """The shrink table in the order of explanation (:func:`~.search.explanation_order`), with
    each step's figures, its gain and the gain's 95 % interval on the exact kinematics."""
    steps = [first]
    rungs = explanation_order(engine, selected)
    for (_, previous), (effect, r) in zip(rungs, rungs[1:]):
        steps.append(Step(effect, tuple(r["effects"]), r["n_parameters"], r["train_stats"].rms,
                          ErrorStats.heldout(r),
                          paired_z(previous["heldout_squares"], r["heldout_squares"]),
                          difference_interval(previous["heldout_squares"], r["heldout_squares"])))
    return steps
