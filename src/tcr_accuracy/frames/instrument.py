"""The measuring instrument's own accuracy: a maximum permissible error that grows with distance,
along the line of sight (the distance meter) and across it (the angle encoders).

Laser trackers and total stations are specified as a maximum permissible error (MPE) ``a + b d``
at distance ``d`` from the instrument (ISO 10360-10 for trackers), separately for the distance
measured along the beam (radial) and for the position across it (transverse: the angles times
the distance). A point far from the tracker is measured less well across the beam than one near
it; weighing every point alike lets the far ones pull the fit. Here each measured point gets
its covariance from the specification, ``Sigma = s_r^2 u u^T + s_t^2 (I - u u^T)`` with ``u`` the
line of sight and ``s = MPE / 2`` (the makers state that typical results are half the MPE: the
MPE read as two standard deviations), and the fit weighs its rows by ``Sigma^-1/2``.

Lengths in m (MPE terms: a in m, b in m per m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError


@dataclass(frozen=True)
class Instrument:
    """A measuring instrument's specification.

    Attributes
    ----------
    name : str
    radial : (float, float)
        MPE along the line of sight: a [m] + b [m/m] x distance.
    transverse : (float, float)
        MPE across the line of sight: a [m] + b [m/m] x distance.
    source : str
        Where the figures come from.
    """

    name: str
    radial: tuple
    transverse: tuple
    source: str = ""

    def sigmas(self, distance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) standard deviations along and across the line of sight [m] at distances [m]."""
        distance = np.asarray(distance, dtype=float)
        return ((self.radial[0] + self.radial[1] * distance) / 2.0,
                (self.transverse[0] + self.transverse[1] * distance) / 2.0)

    def covariances(self, points: np.ndarray) -> np.ndarray:
        """(N, 3, 3) each point's covariance [m^2] in the instrument's frame; points (N, 3) [m]
        in that frame (the instrument at its origin)."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        distance = np.linalg.norm(points, axis=1)
        u = points / np.maximum(distance, 1e-9)[:, None]
        radial, transverse = self.sigmas(distance)
        along = np.einsum("ni,nj->nij", u, u)
        return radial[:, None, None] ** 2 * along + transverse[:, None, None] ** 2 * (np.eye(3) - along)

    def per_axis_noise(self, points: np.ndarray) -> float:
        """RMS per-axis standard deviation [m] over the points: the noise floor the spec gives."""
        trace = np.trace(self.covariances(points), axis1=1, axis2=2)
        return float(np.sqrt(np.mean(trace) / 3.0))

    def whitening(self, points: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """(N, 3, 3) weights of the position rows in the robot's base frame: ``Sigma^-1/2`` rotated
        into the base frame (``rotation``: trackerRbase, (3, 3) or one per row (N, 3, 3)) and
        scaled by the per-axis noise, so a weighted residual stays in metres where every point is
        average."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        distance = np.linalg.norm(points, axis=1)
        sight = points / np.maximum(distance, 1e-9)[:, None]
        rotation = np.broadcast_to(np.asarray(rotation, dtype=float), (len(points), 3, 3))
        u = np.einsum("nji,nj->ni", rotation, sight)  # R^T u: the line of sight in base axes
        radial, transverse = self.sigmas(distance)
        along = np.einsum("ni,nj->nij", u, u)
        reference = self.per_axis_noise(points)
        return reference * (along / radial[:, None, None] + (np.eye(3) - along) / transverse[:, None, None])

    def describe(self) -> str:
        (ra, rb), (ta, tb) = self.radial, self.transverse
        return (f"{self.name}: MPE {ra * 1e6:g} um + {rb * 1e6:g} um/m along the beam, {ta * 1e6:g} um + "
                f"{tb * 1e6:g} um/m across it" + (f" ({self.source})" if self.source else ""))

    def to_dict(self) -> dict:
        return {"name": self.name, "radial_mpe_um": [self.radial[0] * 1e6, self.radial[1] * 1e6],
                "transverse_mpe_um": [self.transverse[0] * 1e6, self.transverse[1] * 1e6],
                "mpe_units": "um + um/m x distance", "source": self.source}


#: Common instruments by the MPE their makers publish (a [m], b [m/m]).
INSTRUMENTS = {
    "leica-at9xx": Instrument("leica-at9xx", (10e-6, 0.3e-6), (15e-6, 6e-6),
                              "Leica absolute trackers AT930/AT960, as their manuals state to ISO 10360-10"),
    "leica-at500": Instrument("leica-at500", (10e-6, 0.3e-6), (15e-6, 6e-6),
                              "Leica AT500 user manual, ISO 10360-10 subsystem MPE"),
    "api-radian": Instrument("api-radian", (15e-6, 6e-6), (15e-6, 6e-6),
                             "API Radian-class tracker, one figure for both directions"),
    "leica-ts60": Instrument("leica-ts60", (0.6e-3, 1e-6), (0.0, 4.8e-6),
                             "Leica TS60 total station on a prism: 0.6 mm + 1 ppm, 0.5 arc-second (two sigma)"),
}


#: The largest MPE an instrument may be given: a [m], b [m/m] (a total station's is about 1e-3 m + 1.5e-6 m/m).
MPE_MAX = (1e-2, 1e-3)
#: The smallest a + b [m, m/m together]: 1e-9, as the least instrument noise a run takes (--noise-mm 1e-6).
MPE_MIN_M = 1e-9


def instrument_from(name: str | None = None, mpe=None, radial_mpe=None) -> Instrument | None:
    """An instrument by name (:data:`INSTRUMENTS`), or from its MPE.

    Parameters
    ----------
    name : str, optional
    mpe : (a, b), optional
        MPE a [m] + b [m/m] x distance, across the beam (and along it too unless ``radial_mpe``).
    radial_mpe : (a, b), optional
        MPE along the beam, where it differs.
    """
    if name is not None:
        key = name.strip().lower()
        if key not in INSTRUMENTS:
            raise InputError(f"instrument={name!r}: unknown (known: {', '.join(INSTRUMENTS)}; or give its MPE)",
                             parameter="instrument", value=name)
        return INSTRUMENTS[key]
    if mpe is None:
        return None
    for label, pair in (("instrument_mpe", mpe), ("instrument_radial_mpe", radial_mpe)):
        if pair is None:
            continue
        values = np.asarray(pair, dtype=float)
        if values.shape != (2,) or not np.all(np.isfinite(values)) or np.any(values < 0) or values.sum() <= 0:
            raise InputError(f"{label} {list(pair)}: need two numbers a >= 0 [m] and b >= 0 [m/m], not both 0",
                             parameter=label, value=pair)
        # 1e300 m made the weighted fit's eigenvalues fail to converge, 1e-300 m its matrix singular
        if values[0] > MPE_MAX[0] or values[1] > MPE_MAX[1] or values.sum() < MPE_MIN_M:
            raise InputError(f"{label} {list(pair)}: want a <= {MPE_MAX[0]:g} m and b <= {MPE_MAX[1]:g} m/m, "
                             f"a + b >= {MPE_MIN_M:g} (no measuring instrument lies outside)",
                             parameter=label, value=pair)
    transverse = tuple(float(v) for v in mpe)
    radial = transverse if radial_mpe is None else tuple(float(v) for v in radial_mpe)
    return Instrument("given MPE", radial, transverse, "as given")
