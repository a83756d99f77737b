"""What follows the measurement order: variables the data cannot tell from a drift in time.

A campaign that sweeps a joint from one end to the other in measurement order, or measures cold
in the morning and warm in the afternoon, makes that joint's angle (or the temperature, or the
payload) a clock: an error that grows with it cannot be told from one that grows with time (an
encoder scale from a warm-up drift, the links' expansion from the tracker's drift). Here each
such variable is found by its correlation with the measurement order and with ``time_s``, and
named with the effects it confounds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

#: |correlation| above which a variable is said to follow the measurement order
FOLLOWS = 0.9

#: Share of an effect's signature (its fitted TCP errors on these poses, beyond what a frame change
#: makes) the drift model must reproduce for the effect to be called confounded with it. At 0.9 the
#: part no drift can make is under a third of the signature's RMS (sqrt 0.1): an effect the selection
#: took (its gain well above the noise) keeps that third as the evidence that tells it from a drift;
#: a signature linear in a variable following the order at r = 0.95 is reproduced r^2 = 90 %, at
#: r = 0.99 98 % (a joint swept in measurement order: an encoder scale is then a drift's equal).
CONFOUNDED_SHARE = 0.9


@dataclass(frozen=True)
class Confounding:
    """A variable that follows the measurement order (or ``time_s``).

    Attributes
    ----------
    variable : str
        ``joint <name>``, ``temperature_c`` or ``payload_kg``.
    clock : str
        ``measurement order`` or ``time_s``.
    r : float
        Their correlation.
    effects : tuple of str
        The effects whose signature grows with the variable (they cannot be told from ``drift``).
    """

    variable: str
    clock: str
    r: float
    effects: tuple
    #: chosen effect -> the share of its signature the drift model reproduces on these poses
    #: (:func:`reproduced_share`), for the chosen effects the variable may confound
    reproduced: dict = dataclasses.field(default_factory=dict)

    def confounds(self, effect: str) -> bool:
        """Whether ``effect`` cannot be told from a drift: the variable may confound it and the drift
        reproduces at least :data:`CONFOUNDED_SHARE` of its signature (where not measured: it may)."""
        share = self.reproduced.get(effect)
        return effect in self.effects and (share is None or share >= CONFOUNDED_SHARE)

    def judged(self, effect: str) -> str:
        """In words: how much of ``effect``'s signature the drift reproduces, and the verdict."""
        share = self.reproduced.get(effect)
        if share is None:
            return f"an error growing with it ({effect}) cannot be told from a drift in time"
        verdict = "cannot be told from it" if share >= CONFOUNDED_SHARE else "told apart, named"
        return (f"drift reproduces {100 * share:.0f} % of {effect}'s signature on these poses "
                f"(confounded from {100 * CONFOUNDED_SHARE:.0f} %): {verdict}")

    def to_dict(self) -> dict:
        out = {"variable": self.variable, "follows": self.clock, "r": self.r, "effects": list(self.effects),
               "drift_alike": ["drift"],
               "confounded_effects": [e for e in (self.reproduced or self.effects) if self.confounds(e)],
               "why": f"{self.variable} follows the {self.clock} (r = {self.r:+.2f}): "
                      + ("; ".join(self.judged(e) for e in self.reproduced) if self.reproduced else
                         f"an error growing with it ({', '.join(self.effects)}) cannot be told from a drift in time")}
        if self.reproduced:
            out["drift_reproduces"] = {e: float(v) for e, v in self.reproduced.items()}
            out["confounded_from"] = CONFOUNDED_SHARE
        return out


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    if np.std(a) == 0 or np.std(b) == 0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def confounded_variables(joint_names, q: np.ndarray, context, measured, threshold: float = FOLLOWS) -> list:
    """Every joint angle, and the temperature and payload where measured, whose correlation with
    the measurement order or with ``time_s`` exceeds ``threshold`` in size.

    Parameters
    ----------
    joint_names : list of str
    q : ndarray of shape (N, n_joints)
        Joint values [rad, m].
    context : MeasurementContext
        With ``order`` and, where recorded, ``time_s``.
    measured : collection of str
        The context fields the rows carry (``temperature_c``, ``payload_kg``).
    """
    clocks = []
    if context.order is not None:
        clocks.append(("measurement order", np.asarray(context.order, dtype=float)))
    if context.time_s is not None and np.all(np.isfinite(context.time_s)) and np.ptp(context.time_s) > 0:
        clocks.append(("time_s", np.asarray(context.time_s, dtype=float)))
    variables = [(f"joint {name}", q[:, j], ("encoder_scale",)) for j, name in enumerate(joint_names)]
    if "temperature_c" in measured:
        variables.append(("temperature_c", np.asarray(context.temperature_c, dtype=float), ("thermal",)))
    if "payload_kg" in measured:
        variables.append(("payload_kg", np.asarray(context.payload_kg, dtype=float),
                          ("compliance", "lateral_compliance")))
    out = []
    for label, values, effects in variables:
        best = max(((clock, _correlation(values, axis)) for clock, axis in clocks), key=lambda c: abs(c[1]),
                   default=None)
        if best is not None and abs(best[1]) > threshold:
            out.append(Confounding(label, best[0], best[1], effects))
    return out


def reproduced_share(signature: np.ndarray, drift: np.ndarray, frames: np.ndarray) -> float:
    """The share of an effect's signature a drift reproduces, beyond what a frame change makes.

    Parameters
    ----------
    signature : ndarray of shape (N, 3)
        The effect's fitted TCP position errors on the measured poses [m].
    drift, frames : ndarray of shape (N, 3, k)
        The drift model's and the tracker frame's TCP columns on the same poses.

    Returns
    -------
    float
        ``1 - |s - P_{frames, drift} s|^2 / |s - P_{frames} s|^2`` (least squares over the poses): 0
        where no drift makes any of it, 1 where a drift makes all of it; 0 for a signature a frame
        change makes whole.
    """
    s = np.asarray(signature, dtype=float).reshape(-1)
    def left(columns):
        a = np.asarray(columns, dtype=float).reshape(s.size, -1)
        norms = np.linalg.norm(a, axis=0)
        a = a[:, norms > 0] / norms[norms > 0]
        return s - a @ np.linalg.lstsq(a, s, rcond=1e-10)[0]
    beyond_frames = left(frames)
    total = float(beyond_frames @ beyond_frames)
    if total <= 1e-12 * max(float(s @ s), 1e-300):
        return 0.0
    rest = left(np.concatenate([frames, drift], axis=2))
    return max(float(1.0 - rest @ rest / total), 0.0)  # at most 1 as it stands; below 0 by round-off only
