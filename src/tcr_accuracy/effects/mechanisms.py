"""Signatures and mechanisms: what an effect's fitted term is, and what physical cause it stands for.

An effect's fitted term is a *signature*: a joint deflection that follows the gravity torque, an
offset that follows the approach direction, a length scale that follows the temperature, an error
that follows a joint's angle. The diagnosis keeps whatever signature the held-out data want, bounded
only to keep the fit sane (:meth:`~tcr_accuracy.effects.base.Effect.fit_range`); the *mechanism*
is then read from the fitted values' sign and size: each effect lists the mechanisms its signature
can stand for, each with the range of parameter values it explains (:class:`Mechanism`), the
effect's own physics first (``textbook``) and then the other causes with the same signature (a
controller's compensation, the instrument, the model's masses).

:func:`read_mechanism` classifies each parameter the data resolve (beyond two standard errors) by
the first mechanism whose range holds it, and words the effect's reading. SI units throughout.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: the families of effects, the level the data may resolve when the members cannot be told apart
FAMILIES = {
    "geometric": "the arm's geometry: encoder zeros and link dimensions",
    "gravity": "deflections under the gravity load: joints and bearings that give, links that bend",
    "direction": "errors that follow the direction a joint approaches its pose from",
    "periodic": "errors that follow a joint's own angle, periodic in it or over its whole travel: gears, encoders, "
                "cables",
    "scale": "errors proportional to a joint's angle: gear ratios",
    "thermal": "lengths that change with temperature",
    "time": "errors that change with time or measurement order: warm-up, a moving base or tracker",
}


@dataclass(frozen=True)
class Mechanism:
    """A physical cause an effect's signature can stand for.

    Attributes
    ----------
    key : str
        Short name (``elastic_joint``, ``gravity_compensation``).
    words : str
        What it is, in a sentence an engineer reads.
    check : str
        What to do on the robot or the instrument to confirm it.
    lower, upper : ndarray of shape (k,)
        The parameter values it explains [SI, the effect's units].
    textbook : bool
        The effect's own physics (True) or another cause with the same signature (False).
    """

    key: str
    words: str
    check: str
    lower: np.ndarray = field(repr=False)
    upper: np.ndarray = field(repr=False)
    textbook: bool = True

    def explains(self, values: np.ndarray) -> np.ndarray:
        """(k,) whether each parameter value lies in this mechanism's range."""
        return (values >= self.lower) & (values <= self.upper)


@dataclass(frozen=True)
class MechanismReading:
    """What an effect's fitted parameters say about its cause.

    Attributes
    ----------
    effect : str
    family : str
    mechanism : str
        The words: the mechanism (or mechanisms, by parameter) whose sign and size fit.
    keys : tuple of str
        The mechanisms' short names, largest share first.
    physical : bool
        Every parameter the data resolve is explained by a known mechanism.
    textbook : bool
        They are all explained by the effect's own physics.
    check : str
        What to do to confirm it.
    parameters : tuple of dict
        The resolved parameters: name, value [SI], std [SI], unit, mechanism key (or None) and
        whether that is the effect's own physics.
    confounded : tuple of str
        Why the data cannot tell this effect from another (empty when they can).
    assumed : tuple of str
        What the fit assumed that the data did not say (drift on the measurement order for want
        of a time column, say); empty when nothing.
    """

    effect: str
    family: str
    mechanism: str
    keys: tuple
    physical: bool
    textbook: bool
    check: str
    parameters: tuple
    #: what the data cannot tell this effect from (a variable that follows the measurement order)
    confounded: tuple = ()
    #: what the fit assumed that the data did not say
    assumed: tuple = ()

    def to_dict(self) -> dict:
        return {"effect": self.effect, "family": self.family, "mechanism": self.mechanism,
                "mechanism_keys": list(self.keys), "physical": self.physical, "textbook": self.textbook,
                "check": self.check, "parameters": [dict(p) for p in self.parameters],
                "confounded_with": list(self.confounded), "assumed": list(self.assumed)}


def _joint_of(name: str) -> str:
    """The joint (or frame) a parameter name refers to: ``compliance.j2`` -> ``j2``."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else name


def read_mechanism(effect, values: np.ndarray, std: np.ndarray, names: list[str] | None = None,
                   motion: np.ndarray | None = None, pinned: np.ndarray | None = None, significance: float = 2.0,
                   unexplained_share: float = 0.5) -> MechanismReading:
    """The mechanism an effect's fitted values stand for.

    Each parameter the data resolve (|value| beyond ``significance`` standard errors) is read by
    the first mechanism whose range its interval (value +- ``significance`` standard errors)
    reaches: the effect's own physics unless the data place the value beyond it. Mechanisms are
    weighed by the TCP motion of the parameters they explain.

    Parameters
    ----------
    effect : Effect
        The effect (its :meth:`~tcr_accuracy.effects.base.Effect.mechanisms`).
    values, std : ndarray of shape (k,)
        Its fitted parameters and their standard errors [SI] (every parameter of the effect;
        zero value and infinite std where not identifiable).
    names : list of str, optional
        The parameters' names (default the effect's own).
    motion : ndarray of shape (k,), optional
        RMS TCP motion [m] each parameter causes per unit of its value (default: its typical
        scale's inverse, i.e. weights by size relative to typical).
    pinned : ndarray of shape (k,) of bool, optional
        Parameters held on their fit range's bound: the data push them beyond every mechanism,
        so none explains them.
    significance : float, default=2.0
        A parameter counts when |value| exceeds this many standard errors (all count when none
        does: the reading then says what the values would mean).
    unexplained_share : float, default=0.5
        The effect is ``physical`` when the parameters no mechanism explains cause less than
        this share of the resolved parameters' TCP motion (the rest is said, by joint).
    """
    names = list(effect.parameter_names() if names is None else names)
    units = list(effect.parameter_units())
    values, std = np.asarray(values, dtype=float), np.asarray(std, dtype=float)
    finite_std = np.where(np.isfinite(std), std, np.inf)
    mechanisms = effect.mechanisms()
    resolved = np.abs(values) > significance * finite_std
    if not resolved.any():
        resolved = values != 0
    reach = np.where(np.isfinite(finite_std), significance * finite_std, 0.0)
    which = np.full(values.size, -1)
    for m, mechanism in reversed(list(enumerate(mechanisms))):  # the first mechanism the interval reaches wins
        which = np.where((values + reach >= mechanism.lower) & (values - reach <= mechanism.upper), m, which)
    if pinned is not None:
        which = np.where(np.asarray(pinned, dtype=bool), -1, which)
    per_unit = (1.0 / np.maximum(np.asarray(effect.parameter_scales(), dtype=float), 1e-300)) if motion is None \
        else np.asarray(motion, dtype=float)
    weight = np.abs(values) * per_unit
    shares: dict = {}
    for i in np.flatnonzero(resolved):
        shares[int(which[i])] = shares.get(int(which[i]), 0.0) + float(weight[i])
    total = sum(shares.values()) or 1.0
    order = sorted(shares, key=lambda m: -shares[m])
    phrases, checks = [], []
    for m in order:
        members = [_joint_of(names[i]) for i in np.flatnonzero(resolved & (which == m))]
        joints = ", ".join(dict.fromkeys(members))
        share = f", {shares[m] / total:.0%} of its TCP motion" if len(order) > 1 else ""
        if m < 0:
            phrases.append(f"values the data push beyond every mechanism {effect.name} can stand for ({joints}{share}): "
                           "another cause with the same signature, or a model that does not describe this robot")
            continue
        mechanism = mechanisms[m]
        where = joints if len(order) > 1 or len(members) < len(names) else ""
        phrases.append(mechanism.words + (f" ({where}{share})" if where else ""))
        checks.append(mechanism.check)
    parameters = tuple({"parameter": names[i], "value": float(values[i]), "std": float(std[i]),
                        "unit": units[i] if i < len(units) else "",
                        "mechanism": mechanisms[which[i]].key if which[i] >= 0 else None,
                        "textbook": bool(which[i] >= 0 and mechanisms[which[i]].textbook)}
                       for i in np.flatnonzero(resolved))
    explained = [m for m in order if m >= 0]
    return MechanismReading(
        effect=effect.name, family=effect.family, mechanism="; ".join(phrases) or "nothing the data resolve",
        keys=tuple(mechanisms[m].key if m >= 0 else "unexplained" for m in order),
        physical=bool(order) and shares.get(-1, 0.0) < unexplained_share * total,
        textbook=bool(explained) and all(mechanisms[m].textbook for m in explained) and len(explained) == len(order),
        check="; ".join(dict.fromkeys(checks)), parameters=parameters)
