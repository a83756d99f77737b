"""The measurements of one robot in SI units (:class:`MeasurementSet`), the column names of the
measurement CSV that are not joints, and several sets joined as sessions (:func:`join_sessions`).

The CSV is read by :mod:`tcr_accuracy.io.measurements` and written by
:mod:`tcr_accuracy.io.measurement_text`; both speak of the set defined here.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..model.context import REFERENCE_TEMPERATURE_C, MeasurementContext
from ..random_state import renamed_keyword

QUATERNION_COLUMNS = ("qw", "qx", "qy", "qz")
CONTEXT_COLUMNS = ("payload_kg", "temperature_c", "time_s")
#: columns whose cells are labels, not numbers
LABEL_COLUMNS = ("session",)
#: Labels a pose or path test adds to a row (ISO 9283, ``iso9283 plan``): accepted, carried, not used by a fit.
ANNOTATION_COLUMNS = ("pose_id", "cycle", "approach", "load_pct", "speed_pct", "target_x_mm", "target_y_mm",
                      "target_z_mm", "path", "speed_mm_s", "s_mm")
#: The annotations that are names, not numbers (``P1``, ``S01.P1``, ``+x``, ``line``): kept as text.
TEXT_ANNOTATIONS = ("pose_id", "cycle", "approach", "path")


@dataclass
class MeasurementSet:
    """Measurements of one robot, SI units.

    Attributes
    ----------
    joint_names : list of str
        Joint order of ``q`` (the robot's).
    q : ndarray of shape (N, n_joints)
        Commanded joint values [rad, m].
    position : ndarray of shape (N, 3)
        Measured TCP position in the measurement (tracker) frame [m].
    quaternion : ndarray of shape (N, 4) or None
        Measured TCP orientation (w, x, y, z), unit norm; None when not measured.
    payload_kg : ndarray of shape (N,) or None
        Payload [kg]; None when the file has no ``payload_kg`` column.
    temperature_c : ndarray of shape (N,) or None
        Temperature [degC]; None when the file has no ``temperature_c`` column.
    direction : ndarray of shape (N, n_joints) or None
        Approach directions +1/-1, 0 for joints without a ``<joint>_dir`` column;
        None when the file has no direction column at all.
    outside_q : ndarray of shape (N, n_outside) or None
        Values [rad, m] of the robot's joints that do not move the TCP
        (``robot.outside_joint_names``: another arm, a head), for the gravity torques;
        None when the file has none of their columns and no mimic rule sets them.
    annotations : dict of str to ndarray of shape (N,), or None
        The file's :data:`ANNOTATION_COLUMNS` by column name: the :data:`TEXT_ANNOTATIONS`
        as names (object arrays of str, a whole number as its digits: see
        :func:`canonical_label`), the others as numbers (the name carries the unit:
        ``target_x_mm``); None when it has none.
    source : str
        Where the rows came from (file path or a label).
    rows : ndarray of shape (N,)
        Row (line) number of each measurement in the source file.
    session : ndarray of shape (N,) of str, or None
        Session label of each row (one tracker frame each); None: one session.
    time_s : ndarray of shape (N,) or None
        Time of each measurement [s]; None when the file has no ``time_s`` column.

    Examples
    --------
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> q = np.random.default_rng(0).uniform(-1, 1, (20, 6))
    >>> measured = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=q,
    ...                               position=tcr.tcp_poses(robot, q).position, source="simulated")
    >>> measured
    MeasurementSet(20 rows x 6 joints, source='simulated', context columns: none)
    """

    joint_names: list[str]
    q: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray | None = None
    payload_kg: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    direction: np.ndarray | None = None
    source: str = "<memory>"
    rows: np.ndarray | None = None
    outside_q: np.ndarray | None = None
    session: np.ndarray | None = None
    time_s: np.ndarray | None = None
    annotations: dict | None = None

    def __post_init__(self) -> None:
        self.q = np.atleast_2d(np.asarray(self.q, dtype=float))
        self.position = np.atleast_2d(np.asarray(self.position, dtype=float))
        if self.rows is None:
            self.rows = np.arange(2, 2 + self.q.shape[0])

    def __len__(self) -> int:
        return self.q.shape[0]

    def __repr__(self) -> str:
        measured = [k for k in ("quaternion", "payload_kg", "temperature_c", "direction", "outside_q", "time_s")
                    if getattr(self, k) is not None]
        sessions = f", {len(self.session_labels)} sessions" if self.session is not None else ""
        source = self.source if len(self.source) <= 60 else self.source[:57] + "..."
        return (f"MeasurementSet({len(self)} rows x {self.q.shape[1]} joints, source={source!r}"
                f"{sessions}, context columns: {', '.join(measured) or 'none'})")

    @property
    def context(self) -> MeasurementContext:
        """The per-row context (payload, temperature, approach directions, other joints, session),
        with defaults where a column is absent: no payload, the reference temperature, no direction."""
        return self.make_context()

    @renamed_keyword("rng", "random_state")
    def make_context(self, reference_temperature_c: float = REFERENCE_TEMPERATURE_C,
                     random_state=None) -> MeasurementContext:
        """The per-row context with another reference temperature [degC] where the file has none,
        and the random numbers the effects that draw them (clearance) take (``random_state``: an
        int, a Generator or None for none; formerly ``rng``)."""
        rng = None if random_state is None else np.random.default_rng(random_state)
        n, nj = self.q.shape
        return MeasurementContext(
            payload_kg=self.payload_kg.copy() if self.payload_kg is not None else np.zeros(n),
            temperature_c=(self.temperature_c.copy() if self.temperature_c is not None
                           else np.full(n, float(reference_temperature_c))),
            direction=self.direction.copy() if self.direction is not None else np.zeros((n, nj)),
            rng=rng,
            outside_q=None if self.outside_q is None else self.outside_q.copy(),
            session=self.session_index(),
            time_s=None if self.time_s is None else np.asarray(self.time_s, dtype=float).copy(),
        )

    @property
    def session_labels(self) -> list[str]:
        """The sessions' labels in order of first appearance ([] without a session column)."""
        return [] if self.session is None else list(dict.fromkeys(self.session.tolist()))

    def session_index(self) -> np.ndarray | None:
        """(N,) int: each row's session, numbered in order of first appearance (None: one session)."""
        if self.session is None:
            return None
        number = {label: k for k, label in enumerate(self.session_labels)}
        return np.array([number[label] for label in self.session.tolist()], dtype=int)

    def subset(self, rows) -> "MeasurementSet":
        """The measurements of some rows (index array or boolean mask), e.g. a fold."""
        def pick(a):
            return None if a is None else a[rows]

        return replace(self, q=self.q[rows], position=self.position[rows],
                       quaternion=pick(self.quaternion), payload_kg=pick(self.payload_kg),
                       temperature_c=pick(self.temperature_c), direction=pick(self.direction),
                       rows=self.rows[rows], outside_q=pick(self.outside_q), session=pick(self.session),
                       time_s=pick(self.time_s),
                       annotations=None if self.annotations is None else
                       {k: v[rows] for k, v in self.annotations.items()})


def join_sessions(sets: list[MeasurementSet], labels: list[str]) -> MeasurementSet:
    """Several measurement sets of one robot as one, each its own session (its label, or
    ``<label>:<session>`` where a set has a session column already); columns one set has and
    another lacks take their defaults (no payload, the reference temperature, no direction). A set
    whose rows are all an earlier set's rows (to its files' rounding: the same campaign written
    twice) is refused (:func:`~tcr_accuracy.io.session_rows.check_distinct_sessions`)."""
    if len(sets) == 1:
        return sets[0]
    from .session_rows import check_distinct_sessions

    check_distinct_sessions(sets, labels)
    session = np.concatenate([np.array([f"{label}:{v}" for v in s.session], dtype=object) if s.session is not None
                              else np.full(len(s), label, dtype=object) for s, label in zip(sets, labels)])

    def joined(attr, fill):
        values = [getattr(s, attr) for s in sets]
        if all(v is None for v in values):
            return None
        return np.concatenate([v if v is not None else fill(s) for v, s in zip(values, sets)])

    nj = sets[0].q.shape[1]
    return MeasurementSet(
        joint_names=list(sets[0].joint_names), q=np.concatenate([s.q for s in sets]),
        position=np.concatenate([s.position for s in sets]),
        quaternion=joined("quaternion", lambda s: np.tile([1.0, 0.0, 0.0, 0.0], (len(s), 1))),
        payload_kg=joined("payload_kg", lambda s: np.zeros(len(s))),
        temperature_c=joined("temperature_c", lambda s: np.full(len(s), REFERENCE_TEMPERATURE_C)),
        direction=joined("direction", lambda s: np.zeros((len(s), nj))),
        source=", ".join(s.source for s in sets), rows=np.concatenate([s.rows for s in sets]),
        outside_q=joined("outside_q", lambda s: np.zeros((len(s), next(
            o.outside_q.shape[1] for o in sets if o.outside_q is not None)))),
        session=session, time_s=joined("time_s", lambda s: np.full(len(s), np.nan)),
    )


__all__ = ["ANNOTATION_COLUMNS", "CONTEXT_COLUMNS", "LABEL_COLUMNS", "MeasurementSet", "QUATERNION_COLUMNS",
           "TEXT_ANNOTATIONS", "join_sessions"]
