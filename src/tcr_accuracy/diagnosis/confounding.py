"""What follows the measurement order: variables the data cannot tell from a drift in time.

A campaign that sweeps a joint from one end to the other in measurement order, or measures cold
in the morning and warm in the afternoon, makes that joint's angle (or the temperature, or the
payload) a clock: an error that grows with it cannot be told from one that grows with time (an
encoder scale from a warm-up drift, the links' expansion from the tracker's drift). Here each
such variable is found by its correlation with the measurement order and with ``time_s``, and
named with the effects it confounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: |correlation| above which a variable is said to follow the measurement order
FOLLOWS = 0.9


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

    def to_dict(self) -> dict:
        return {"variable": self.variable, "follows": self.clock, "r": self.r, "effects": list(self.effects),
                "drift_alike": ["drift"],
                "why": f"{self.variable} follows the {self.clock} (r = {self.r:+.2f}): an error growing with it "
                       f"({', '.join(self.effects)}) cannot be told from a drift in time"}


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
