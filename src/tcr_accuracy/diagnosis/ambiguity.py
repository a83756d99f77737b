"""Which chosen effects the data cannot tell from an unchosen one, and which of them to keep.

Forward selection takes, at each step, the effect that cuts the held-out error most; an
effect that can mimic another over the measured poses (an offset and two harmonics of a
joint against a scale error on it, over a short range) may enter first and leave the
other nothing to explain. Here every chosen effect is swapped for every unchosen one and
the model refitted (the engine's k-fold held-out errors, same folds):

* an alternative *stands in* for a chosen effect when the model with it is not
  significantly worse (paired one-sided z of the per-measurement squared held-out errors
  below ``selection_z``) yet explains significantly more than the model without either
  (z above ``selection_z``);
* the chosen effect and its stand-ins form an ambiguity group, reported with each
  member's held-out figures;
* within a group the **one-standard-error rule** picks the member to keep: of those whose
  held-out mean squared error is within one standard error (of the paired difference) of
  the group's best, the one with the fewest parameters; a swap the rule asks for is made
  and the check repeated.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import linalg

from ..effects import effect_class
from .fitting import FitEngine
from .bases import ordered
from .fit_columns import ChainedJacobian
from .gram import sensitivity_times
from .identifiability import QR_CHUNK
from .paired import entry_z, paired_z, row_squares
from .records import ErrorStats
from .uncertainty import implausibility


def swap_alternatives(engine: FitEngine, current: list, pool, selection_z: float) -> dict:
    """For each chosen effect (not ``frames``), what stands in for it among the unchosen
    effects of ``pool``: one effect, or one effect with a companion (an encoder scale error
    needs the joint offsets that a transmission error's terms bring along). Returns chosen
    effect -> list of rows (the chosen effect itself first), each with ``effects`` (what
    replaces it), its held-out figures [mm], the model's parameter count and the two z values."""
    final = engine.evaluate(ordered(current))
    unchosen = [u for u in pool if u not in current]
    groups = {}
    for chosen in [e for e in current if e != "frames"]:
        rest = [s for s in current if s != chosen]
        without = engine.evaluate(ordered(rest))

        def judged(replacement):
            swapped = engine.evaluate(ordered(rest + list(replacement)))
            # the selection's own test (the paired mean's z or the signed ranks', whichever is larger):
            # with few poses the mean's z alone let a stand-in 8 times worse in RMS pass as "not worse"
            return (swapped, entry_z(swapped["heldout_squares"], final["heldout_squares"]),
                    entry_z(without["heldout_squares"], swapped["heldout_squares"]))

        rows = [_row([chosen], final, z_worse=0.0, z_explains=entry_z(without["heldout_squares"],
                                                                         final["heldout_squares"]), engine=engine)]
        for alternative in unchosen:
            swapped, z_worse, z_explains = judged([alternative])
            if z_explains > selection_z and z_worse >= selection_z:  # explains, but not all: a companion?
                completions = [(judged([alternative, w]), w) for w in unchosen if w != alternative]
                if completions:
                    (swapped, z_worse, z_explains), w = min(completions, key=lambda c: c[0][1])
                    alternative = [alternative, w]
            if z_worse < selection_z and z_explains > selection_z:
                rows.append(_row(alternative if isinstance(alternative, list) else [alternative], swapped,
                                 z_worse, z_explains, engine=engine))
        groups[chosen] = rows
    return groups


def _row(effects: list, result: dict, z_worse: float, z_explains: float, engine: FitEngine) -> dict:
    held = ErrorStats.heldout(result)
    beyond = max((implausibility(result, engine.bases, e) for e in effects), default=0.0)
    return {"effect": "+".join(effects), "effects": list(effects), "heldout_rms_mm": held.rms * 1e3,
            "heldout_mean_mm": held.mean * 1e3, "heldout_max_mm": held.max * 1e3,
            "n_parameters": result["n_parameters"], "z_worse_than_chosen": z_worse, "z_over_neither": z_explains,
            "size_over_physics": beyond, "_squares": row_squares(result["heldout_squares"])}


def one_standard_error_choice(rows: list) -> dict:
    """The row to keep: of those within one standard error of the best held-out mean squared
    error (paired differences), those whose fitted sizes their own physics explains (RMS of value
    over physical bound at most 1) first, then the fewest parameters; ties go to the lower error."""
    best = min(rows, key=lambda r: r["_squares"].mean())
    within = []
    for r in rows:
        d = r["_squares"] - best["_squares"]
        se = d.std(ddof=1) / math.sqrt(d.size) if d.size > 1 else 0.0
        if d.mean() <= se:
            within.append(r)
    return min(within, key=lambda r: (r["size_over_physics"] > 1.0, r["n_parameters"], r["_squares"].mean()))


#: how much higher than the best model seen a model's held-out RMS may be, for the swaps and
#: eliminations that make it (a relative figure: per-row squared errors are heavy-tailed, and a
#: paired z alone lets a model 50 % worse pass when a few rows scatter)
REACH = 0.02


def within_reach(squares: np.ndarray, reference: np.ndarray, z: float) -> bool:
    """Whether a model's per-row held-out squared errors are no significantly worse than the
    reference's (paired z below ``z``) and its held-out RMS within :data:`REACH` of it."""
    return paired_z(squares, reference) < z and \
        math.sqrt(float(np.mean(squares))) <= (1.0 + REACH) * math.sqrt(float(np.mean(reference)))


def settle_swaps(engine: FitEngine, current: list, pool, selection_z: float, say,
                 reference: np.ndarray | None = None) -> tuple[list, list]:
    """Apply the one-standard-error rule to every ambiguity group until no swap is asked for
    (each set is visited once, so it ends). With ``reference`` (the per-row held-out squared
    errors of the best model seen), a swap must also stay within one standard error and
    :data:`REACH` of it (:func:`within_reach`), so that a chain of swaps, each as good as the last,
    cannot drift to a worse model. Returns the new set and the swaps made."""
    current = list(current)
    swaps, seen = [], {frozenset(current)}
    while True:
        say("checking what the data cannot tell apart")
        groups = swap_alternatives(engine, current, pool, selection_z)
        move = None
        for chosen, rows in groups.items():
            if len(rows) > 1:
                if reference is not None:
                    rows = [rows[0]] + [r for r in rows[1:] if within_reach(r["_squares"], reference, 1.0)]
                keep = one_standard_error_choice(rows)
                at = current.index(chosen)
                candidate = current[:at] + keep["effects"] + current[at + 1:]
                if keep["effects"] != [chosen] and frozenset(candidate) not in seen:
                    move = (rows[0], keep, candidate)
                    break
        if move is None:
            return current, swaps
        out, keep, current = move
        seen.add(frozenset(current))
        swaps.append({"out": out["effect"], "in": keep["effect"],
                      "heldout_rms_mm": {out["effect"]: out["heldout_rms_mm"], keep["effect"]: keep["heldout_rms_mm"]},
                      "n_parameters": {out["effect"]: out["n_parameters"], keep["effect"]: keep["n_parameters"]}})


def ambiguity_report(groups: dict) -> list:
    """The groups with more than one member, as JSON-ready dicts (largest group first)."""
    out = []
    for chosen, rows in groups.items():
        if len(rows) > 1:
            out.append({"chosen": chosen, "effects": [r["effect"] for r in rows],
                        "members": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]})
    out.sort(key=lambda g: -len(g["effects"]))
    return out


def stand_in_shapes(engine: FitEngine, current: list, pool, rng: np.random.Generator) -> dict:
    """(N, 3) TCP motion patterns of each unchosen effect of ``pool`` at a random draw of
    its typical size, minus what the chosen model's own columns absorb (least squares on
    the first measured frame): the kind of leftover an effect the model lacks would leave.
    For the structure test's power probe; effects driven by the approach direction or the
    temperature are left out (their leftover is not a function of the joint values)."""
    final_cols = engine.columns(ordered(current))
    _, g, idx = final_cols.per_part[0]
    # the structure test looks for what the joint values predict: an effect driven by the
    # approach direction or the temperature leaves a pattern it is not built to see (the
    # "where" breakdown by direction and temperature is), so it is no yardstick of its power
    joint_driven = [e for e in pool if not set(effect_class(e).context_columns) & {"<joint>_dir", "temperature_c"}]
    motions = {}
    for u in [e for e in joint_driven if e not in current and e in engine.bases]:
        b = engine.bases[u]
        g_u = b.per_part[0].g  # (N, r, k) per unit of the union parameters' local columns
        draw = rng.standard_normal(g_u.shape[2]) * b.scales[b.index[0]]
        motions[u] = sensitivity_times(g_u, draw[:, None])[:, :3, 0]  # its factors' product: no (N, r, k) rows
    if g.shape[2] and motions:
        model = ChainedJacobian(g, np.arange(g.shape[2]), final_cols.scale[idx])
        left = _least_squares_residual(model, np.stack(list(motions.values()), axis=2))
        motions = {u: left[:, :, i] for i, u in enumerate(motions)}
    return {u: motion for u, motion in motions.items() if np.any(motion)}


def _least_squares_residual(model: ChainedJacobian, vectors: np.ndarray) -> np.ndarray:
    """vectors (N, 3, m) less their least-squares fit by the model's columns on the position rows
    (each vector its own fit): the model (3N x k) is never held whole (it was, and LAPACK's copy of
    it, 2 x 108 MB at 10^4 poses with the cyclic effect). One tall-skinny QR of [model | vectors],
    a chunk of poses at a time, gives R = [[R11, R12], [0, R22]]; the coefficients solve R11 x = R12."""
    k, m = model.shape[2], vectors.shape[2]
    r = np.zeros((0, k + m))
    for start in range(0, vectors.shape[0], QR_CHUNK):
        rows = slice(start, start + QR_CHUNK)
        block = model.block(rows)[:, :3, :]
        chunk = np.concatenate([block.reshape(-1, k), vectors[rows].reshape(-1, m)], axis=1)
        stacked = np.concatenate([r, chunk], axis=0)
        r = linalg.qr(stacked, mode="r", overwrite_a=True, check_finite=False)[0][:min(stacked.shape)]
    coefficients = np.linalg.lstsq(r[:k, :k], r[:k, k:], rcond=None)[0]
    out = vectors.copy()
    for start in range(0, vectors.shape[0], QR_CHUNK):
        rows = slice(start, start + QR_CHUNK)
        out[rows] -= model.block(rows)[:, :3, :] @ coefficients
    return out


def rival_models(estimator) -> list:
    """For every ambiguity group of a fitted diagnosis (a fitted ``GapDiagnosis``), the chosen model against each model
    with a stand-in in the chosen effect's place, both fitted: a list of pairs of
    (effect instances, parameter vectors) for
    :func:`~tcr_accuracy.diagnosis.design.plan_discriminating_poses`."""
    result = estimator.result_
    chosen_model = estimator.fitted_model(result.selected_effects)
    pairs = []
    for group in result.ambiguous:
        rest = [e for e in result.selected_effects if e != group["chosen"]]
        for member in group["members"][1:]:
            pairs.append((chosen_model, estimator.fitted_model(rest + member["effects"])))
    return pairs
