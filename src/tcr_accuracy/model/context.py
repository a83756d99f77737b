"""The conditions a measurement was taken under, as the effects see them.

Model layer: imports only :mod:`tcr_accuracy.model.robot`. The measurement reader
(:mod:`tcr_accuracy.io.measurements`) fills a :class:`MeasurementContext` from CSV columns,
``simulate`` draws one, and the effects read it; none of them needs the others for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Reference temperature of the nominal model [degC]: the temperature the URDF's
#: dimensions hold at, used when a file has no ``temperature_c`` column.
REFERENCE_TEMPERATURE_C = 20.0

#: Context column an effect may declare -> the :class:`MeasurementContext` field it fills
#: (``<joint>_dir`` stands for all the per-joint direction columns).
CONTEXT_FIELDS = {"payload_kg": "payload_kg", "temperature_c": "temperature_c", "<joint>_dir": "direction",
                  "time_s": "time_s"}


@dataclass
class MeasurementContext:
    """Per-row conditions the effects may depend on (SI, degC).

    Attributes
    ----------
    payload_kg : ndarray of shape (N,)
        Payload at the TCP [kg]; 0 when unknown.
    temperature_c : ndarray of shape (N,)
        Arm temperature [degC]; the reference temperature when unknown.
    direction : ndarray of shape (N, n_joints)
        Approach direction of each joint, +1 or -1, and 0 where not given (effects
        then derive it, e.g. backlash from the sign of the gravity torque).
    rng : numpy.random.Generator or None
        Random source for stochastic effects (clearance) when simulating.
    outside_q : ndarray of shape (N, n_outside) or None
        Values [rad, m] of the robot's joints that do not move the TCP
        (:attr:`RobotModel.outside_joint_names`), e.g. a second arm whose masses load
        the torso; None: every such joint at its neutral value (or its mimic rule).
        Only the gravity torques read them.
    session : ndarray of shape (N,) of int or None
        The measurement session of each row (its own tracker frame); None: one session.
    time_s : ndarray of shape (N,) or None
        When each row was measured [s]; None when not recorded.
    order : ndarray of shape (N,) of int or None
        Each row's place in the order the campaign being diagnosed was measured in (0 first); None
        for rows that are not such a campaign's (poses to predict or compensate: a file's own row
        order says nothing about the campaign's time).
    """

    payload_kg: np.ndarray
    temperature_c: np.ndarray
    direction: np.ndarray
    rng: np.random.Generator | None = None
    outside_q: np.ndarray | None = None
    #: (N,) int: the measurement session of each row (its own tracker frame), or None: one session
    session: np.ndarray | None = None
    time_s: np.ndarray | None = None
    order: np.ndarray | None = None

    @classmethod
    def defaults(cls, n_rows: int, n_joints: int, *, payload_kg: float = 0.0,
                 temperature_c: float = REFERENCE_TEMPERATURE_C) -> "MeasurementContext":
        """Context of N rows with a constant payload and temperature and no directions."""
        return cls(np.full(n_rows, float(payload_kg)), np.full(n_rows, float(temperature_c)),
                   np.zeros((n_rows, n_joints)))

    def __len__(self) -> int:
        return self.payload_kg.shape[0]

    def subset(self, rows) -> "MeasurementContext":
        """The context of some rows (index array or boolean mask)."""
        def pick(values):
            return None if values is None else values[rows]

        return MeasurementContext(self.payload_kg[rows], self.temperature_c[rows], self.direction[rows],
                                  self.rng, pick(self.outside_q), pick(self.session), pick(self.time_s),
                                  pick(self.order))


def context_column(context: MeasurementContext | None, attr: str, n: int, default: float) -> np.ndarray:
    """(n,) values of one per-row context field, ``default`` when there is no context."""
    if context is None:
        return np.full(n, default)
    value = np.asarray(getattr(context, attr), dtype=float)
    return np.broadcast_to(value, (n,)) if value.ndim == 0 else value
