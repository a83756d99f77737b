"""What changed between two diagnoses of the same robot, and whether the fits can tell.

Two calibration campaigns (before and after a crash, a gearbox change, a few months) each
give a fitted model (:meth:`tcr_accuracy.diagnosis.result.Diagnosis.to_dict`). Per parameter
of the robot the change between them is set against its standard error
``sqrt(std_old^2 + std_new^2)``: beyond ``z`` of it (default 3) the change exceeds both fits'
uncertainty. The tracker's frame (``frames.base.*``) belongs to each campaign's setup and is
not compared; the TCP offset (``frames.tool.*``) is the setup's too and listed apart.
Parameters present in one fit only (an effect selected in one campaign, a parameter
identifiable in one) are named, not compared.

What a change does to the TCP: both fitted robots (tracker frame left out) are evaluated on
the same joint values and their TCP positions compared after removing the rigid motion a
change of the tracker frame would absorb (Kabsch); the same for the significant changes
alone (the old robot with only those parameters moved). SI throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..effects import make_effect, predict_positions, prediction_jacobian
from ..exceptions import InputError
from ..io.json_values import JsonForm, plain
from ..model.context import MeasurementContext
from ..model.robot import RobotModel
from ..frames.rigid import rigid_fit

#: Keys a diagnosis' JSON carries that a comparison reads.
REQUIRED_KEYS = ("robot", "parameters", "parameter_std", "parameter_units", "selected_effects")
#: Parameters of the tracker's frame: the setup of one campaign, never compared.
TRACKER_PREFIX = "frames.base."
#: Parameters of the TCP offset (where the reflector sits on the tool): setup, listed apart.
TOOL_PREFIX = "frames.tool."


@dataclass(frozen=True)
class FittedModel:
    """One diagnosis as a comparison reads it (SI).

    parameters : effect -> {parameter name: value}
    std : effect -> {parameter name: standard error, or inf where the fit gave none}
    units : effect -> {parameter name: SI unit}
    options : effect -> keyword options the effect was fitted with
    """

    robot: str
    parameters: dict
    std: dict
    units: dict
    options: dict
    source: str = ""

    @classmethod
    def from_dict(cls, doc, source: str = "") -> "FittedModel":
        """Read the JSON of ``diagnose --json``; InputError when it is not one."""
        missing = [k for k in REQUIRED_KEYS if not isinstance(doc, dict) or k not in doc]
        if missing:
            raise InputError(f"{source}: not a diagnosis (no {', '.join(missing)}); write one with "
                             "tcr-accuracy diagnose")
        parameters, std, units = {}, {}, {}
        try:
            for effect, values in doc["parameters"].items():
                parameters[effect] = {str(k): float(v) for k, v in values.items()}
                given = doc["parameter_std"].get(effect, {})
                std[effect] = {k: (math.inf if given.get(k) is None else float(given[k])) for k in values}
                units[effect] = {k: str(doc["parameter_units"][effect][k]) for k in values}
        except (AttributeError, KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{source}: not a diagnosis (its parameters, standard errors and units do not "
                             f"match: {type(exc).__name__} {exc})") from None
        bad = [n for p in parameters.values() for n, v in p.items() if not math.isfinite(v)]
        if bad:
            raise InputError(f"{source}: parameter {bad[0]} is not a finite number")
        options = doc.get("effect_options") or {}
        return cls(str(doc["robot"]), parameters, std, units,
                   {e: dict(options.get(e) or {}) for e in parameters}, source)

    def flat(self) -> dict:
        """{parameter name: (effect, value, std, unit)} over every effect."""
        return {n: (e, v, self.std[e][n], self.units[e][n]) for e, p in self.parameters.items() for n, v in p.items()}


@dataclass(frozen=True)
class ParameterChange:
    """One parameter fitted in both campaigns: new - old against sqrt(std_old^2 + std_new^2)."""

    name: str
    effect: str
    unit: str
    old: float
    new: float
    std_error: float  # of the change; inf when either fit gave no standard error
    z: float  # |change| / std_error (0 when the standard error is unknown)
    significant: bool
    setup: bool  # the TCP offset: the setup's, not the robot's
    #: (old, new) as the fits gave them, where ``old``/``new`` are on a common basis (see
    #: :func:`on_common_basis`); None when they are the fits' own values
    as_fitted: tuple | None = None

    @property
    def change(self) -> float:
        return self.new - self.old

    def to_dict(self) -> dict:
        finite = lambda v: float(v) if math.isfinite(v) else None  # noqa: E731
        return {"parameter": self.name, "effect": self.effect, "unit": self.unit, "old": self.old, "new": self.new,
                "change": self.change, "std_error": finite(self.std_error), "z": finite(self.z),
                "significant": self.significant,
                **({"as_fitted": {"old": self.as_fitted[0], "new": self.as_fitted[1]}} if self.as_fitted else {})}


@dataclass(frozen=True)
class OneSided:
    """Parameters of one effect present in one fit only."""

    effect: str
    present_in: str  # "old" (vanished) or "new" (appeared)
    parameters: dict  # name -> (value, std, unit)
    whole_effect: bool  # the effect itself is in one fit only (selected in one campaign)

    @property
    def what(self) -> str:
        word = "vanished" if self.present_in == "old" else "appeared"
        return (f"effect {word}" if self.whole_effect else
                f"{'fewer' if self.present_in == 'old' else 'more'} parameters identifiable ({word})")

    def to_dict(self) -> dict:
        return {"effect": self.effect, "present_in": self.present_in, "what": self.what,
                "parameters": {n: {"value": v, "std": s if math.isfinite(s) else None, "unit": u}
                               for n, (v, s, u) in self.parameters.items()}}


@dataclass(frozen=True)
class TcpEffect:
    """TCP position difference norms [m] over the evaluation poses, rigid frame change removed."""

    mean: float
    rms: float
    max: float

    @staticmethod
    def of(norms: np.ndarray) -> "TcpEffect":
        return TcpEffect(float(norms.mean()), float(np.sqrt(np.mean(norms**2))), float(norms.max()))

    def to_dict(self) -> dict:
        return {"mean_mm": self.mean * 1e3, "rms_mm": self.rms * 1e3, "max_mm": self.max * 1e3}


@dataclass
class Comparison(JsonForm):
    """What :func:`compare_models` found (SI); :meth:`to_json` is the JSON form ``compare --json``
    writes, :meth:`from_json` (or :func:`tcr_accuracy.read_result` for a file) reads it back.

    Attributes
    ----------
    robot : str
        The robot's name.
    z_threshold : float
        A change is significant beyond this many standard errors of it.
    changes : list of ParameterChange
        The robot's parameters fitted in both campaigns.
    setup : list of ParameterChange
        The TCP offset's (the setup's, listed apart).
    one_sided : list of OneSided
        Parameters present in one fit only.
    tcp_all, tcp_significant : TcpEffect
        What all changes, and the significant ones alone, do to the TCP [m].
    n_poses : int
        Poses the TCP effect was evaluated on.
    sources : tuple of str
        The two campaigns (old, new).
    notes : list of str
    poses : str
        Which poses, in words.
    robot_source : str or None
        How to load the robot again.
    tool_frame : str
        Its TCP frame.
    document : dict or None
        The JSON form it was read from (None when computed); :meth:`to_dict` gives it back as it was.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> same = tcr.compare_models(robot, d, d, measured.q)
    >>> tcr.Comparison.from_json(same.to_json()).significant  # one campaign against itself: nothing changed
    []
    """

    robot: str
    z_threshold: float
    changes: list  # ParameterChange of the robot's parameters
    setup: list  # ParameterChange of the TCP offset
    one_sided: list  # OneSided
    tcp_all: TcpEffect
    tcp_significant: TcpEffect
    n_poses: int
    sources: tuple = ("", "")
    notes: list = field(default_factory=list)
    poses: str = ""
    robot_source: str | None = None
    tool_frame: str = ""
    document: dict | None = field(default=None, repr=False, compare=False)

    @property
    def significant(self) -> list:
        return [c for c in self.changes if c.significant]

    def to_dict(self) -> dict:
        """The JSON form (plain values; lengths in mm, parameters in their SI unit)."""
        if self.document is not None:
            return dict(self.document)
        out = {
            "robot": self.robot,
            "old": self.sources[0], "new": self.sources[1],
            "z_threshold": self.z_threshold,
            "significant": [c.name for c in self.significant],
            "changes": [c.to_dict() for c in self.changes],
            "setup_changes": [c.to_dict() for c in self.setup],
            "one_fit_only": [o.to_dict() for o in self.one_sided],
            "tcp_effect": {"n_poses": self.n_poses, "all_changes": self.tcp_all.to_dict(),
                           "significant_changes": self.tcp_significant.to_dict(),
                           "rigid_frame_change_removed": True},
            "notes": list(self.notes),
            "poses": self.poses, "robot_source": self.robot_source, "tool_frame": self.tool_frame,
        }
        if self.robot_source is None:
            del out["robot_source"]
        return plain(out)

    @classmethod
    def from_dict(cls, doc: dict, source: str = "") -> "Comparison":
        """Of its JSON form (a document :func:`tcr_accuracy.read_result` checked).

        Parameters
        ----------
        doc : dict
        source : str
            The file it came from, for messages.

        Returns
        -------
        Comparison
        """
        def change(c, setup):
            as_fitted = c.get("as_fitted")
            return ParameterChange(c["parameter"], c.get("effect", ""), c["unit"], c["old"], c["new"],
                                   math.inf if c["std_error"] is None else c["std_error"],
                                   _z(c), bool(c["significant"]), setup,
                                   None if as_fitted is None else (as_fitted["old"], as_fitted["new"]))

        def one(o):
            return OneSided(o["effect"], o["present_in"], {n: (p["value"], math.inf if p["std"] is None else p["std"],
                                                               p["unit"]) for n, p in o["parameters"].items()},
                            o.get("what", "").startswith("effect"))

        tcp = doc["tcp_effect"]
        effect = {k: TcpEffect(v["mean_mm"] * 1e-3, v["rms_mm"] * 1e-3, v["max_mm"] * 1e-3)
                  for k, v in tcp.items() if isinstance(v, dict)}
        return cls(str(doc["robot"]), float(doc["z_threshold"]), [change(c, False) for c in doc["changes"]],
                   [change(c, True) for c in doc.get("setup_changes", [])],
                   [one(o) for o in doc.get("one_fit_only", [])], effect["all_changes"], effect["significant_changes"],
                   int(tcp["n_poses"]), (str(doc["old"]), str(doc["new"])), list(doc.get("notes", [])),
                   str(doc.get("poses", "")), doc.get("robot_source"), str(doc.get("tool_frame", "")), doc)

    @classmethod
    def from_json(cls, text: str, source: str = "") -> "Comparison":
        """:meth:`from_dict` of JSON text a script holds (a file: :func:`tcr_accuracy.read_result`).

        Parameters
        ----------
        text : str
        source : str

        Returns
        -------
        Comparison
        """
        from ..input_files import parse_json

        doc = parse_json(text, source or "comparison JSON", "give what Comparison.to_json wrote")
        if not isinstance(doc, dict) or not {"changes", "tcp_effect", "robot"} <= set(doc):
            raise InputError(f"{source or 'comparison JSON'}: not a comparison as Comparison.to_json writes it")
        return cls.from_dict(doc, source)


def _fitted(fit, label: str) -> FittedModel:
    """A comparison's view of a diagnosis (a :class:`~tcr_accuracy.diagnosis.result.Diagnosis`, or
    already a :class:`FittedModel`)."""
    if isinstance(fit, FittedModel):
        return fit
    return FittedModel.from_dict(fit.to_dict(), getattr(fit, "file", "") or fit.source or label)


def _z(change: dict) -> float:
    """A change's z of its JSON form: null is infinite where the standard error is 0 and the value
    moved (the fits gave none), else 0 (no standard error: not judged)."""
    if change["z"] is not None:
        return float(change["z"])
    return math.inf if change["std_error"] == 0 and change["change"] else 0.0


# ---------------------------------------------------------------------------------------
def check_same_robot(robot: RobotModel, old: FittedModel, new: FittedModel) -> None:
    """InputError unless both fits are of ``robot`` and share each common parameter's unit."""
    if old.robot != new.robot:
        raise InputError(f"{old.source} is a diagnosis of {old.robot}, {new.source} of {new.robot}: "
                         "compare two diagnoses of the same robot")
    if old.robot != robot.name:
        raise InputError(f"{old.source} and {new.source} are diagnoses of {old.robot}, not of {robot.name}: "
                         "give robot= as in the diagnosis", parameter="robot", value=robot.name)
    a, b = old.flat(), new.flat()
    for name in a.keys() & b.keys():
        if a[name][3] != b[name][3]:
            raise InputError(f"parameter {name} is in {a[name][3]} in {old.source} but in {b[name][3]} in "
                             f"{new.source}: not the same parameter")
        if a[name][0] != b[name][0]:
            raise InputError(f"parameter {name} belongs to {a[name][0]} in {old.source} but to {b[name][0]} in "
                             f"{new.source}")


def parameter_changes(old: FittedModel, new: FittedModel, z: float = 3.0) -> tuple[list, list, list]:
    """(robot changes, TCP offset changes, one-sided effects) between two fits.

    Robot and TCP offset parameters present in both are compared (``z``: how many standard
    errors of the change make it significant); the tracker frame is left out.
    """
    a, b = old.flat(), new.flat()
    changes, setup = [], []
    for name in [n for n in a if n in b and not n.startswith(TRACKER_PREFIX)]:
        effect, v_old, s_old, unit = a[name]
        v_new, s_new = b[name][1], b[name][2]
        se = math.hypot(s_old, s_new)
        zval = abs(v_new - v_old) / se if 0 < se < math.inf else (math.inf if se == 0 and v_new != v_old else 0.0)
        change = ParameterChange(name, effect, unit, v_old, v_new, se, zval, bool(zval > z),
                                 name.startswith(TOOL_PREFIX))
        (setup if change.setup else changes).append(change)
    one_sided = []
    for present, mine, other in (("old", old, new), ("new", new, old)):
        for effect, values in mine.parameters.items():
            names = [n for n in values if n not in other.flat() and not n.startswith(TRACKER_PREFIX)]
            if names:
                one_sided.append(OneSided(effect, present, {n: (values[n], mine.std[effect][n],
                                                                 mine.units[effect][n]) for n in names},
                                          effect not in other.parameters))
    return changes, setup, one_sided


def _effects(robot: RobotModel, parameters: dict, options: dict) -> tuple[list, list, list]:
    """The fit's effects, their full parameter vectors [SI] (names the fit did not keep at
    zero, the tracker frame ``frames.base.*`` left out) and their parameter names."""
    effects, vectors, all_names = [], [], []
    for name, values in parameters.items():
        try:
            effect = make_effect(name, robot, **options.get(name, {}))
        except TypeError as exc:
            raise InputError(f"effect {name}: options {options.get(name)} do not fit it ({exc})") from None
        names = effect.parameter_names()
        unknown = [n for n in values if n not in names]
        if unknown:
            raise InputError(f"parameter {unknown[0]} is not one of {robot.name}'s {name} parameters (tool frame "
                             f"{robot.tool_frame!r}): give the robot= and tool= the diagnosis used", parameter="robot",
                             value=robot.name)
        vectors.append(np.array([0.0 if n.startswith(TRACKER_PREFIX) else values.get(n, 0.0) for n in names]))
        effects.append(effect)
        all_names += names
    return effects, vectors, all_names


def robot_positions(robot: RobotModel, parameters: dict, options: dict, q: np.ndarray,
                    context: MeasurementContext | None = None) -> np.ndarray:
    """(N, 3) [m] TCP positions in the robot's base frame of the robot a fit describes.

    parameters : effect -> {name: value SI}; names the fit did not keep (not identifiable)
    are zero, the tracker frame (``frames.base.*``) is left out.
    """
    effects, vectors, _ = _effects(robot, parameters, options)
    return predict_positions(robot, effects, vectors, q, context)


def on_common_basis(robot: RobotModel, fit: FittedModel, common: set, q: np.ndarray,
                    context: MeasurementContext | None = None) -> dict:
    """The fit's values of the ``common`` parameters once what its other parameters of the same
    effects do to the TCP is carried into them, as far as they can express it.

    Two fits of different poses may keep different members of a group of parameters that
    move the TCP alike (identifiability keeps one, e.g. ``geometry.j2.dx`` in one campaign and
    ``geometry.j4.dx`` in the other), and what the other fit's member carries then shifts the
    shared parameters. Here the fit's TCP positions over ``q`` are fitted (Gauss-Newton, one
    step from the fit's own values) with the common parameters and a rigid frame change only.
    Returns {name: value SI} for the common names the fit has.
    """
    restricted = {e: {n: v for n, v in p.items() if n in common} for e, p in fit.parameters.items()}
    target = robot_positions(robot, fit.parameters, fit.options, q, context)
    effects, vectors, names = _effects(robot, restricted, fit.options)
    start = predict_positions(robot, effects, vectors, q, context)
    columns = [i for i, n in enumerate(names) if n in common and not n.startswith(TRACKER_PREFIX)]
    jac = prediction_jacobian(robot, effects, vectors, q, context)[:, :, columns]  # (N, 3, k)
    # a rigid frame change: translation, and a small rotation w moving p by w x p = -[p]x w
    skew = np.zeros((q.shape[0], 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -start[:, 2], start[:, 1], -start[:, 0]
    skew = skew - skew.transpose(0, 2, 1)
    rigid = np.concatenate([np.broadcast_to(np.eye(3), skew.shape), -skew], axis=2)
    a = np.concatenate([jac, rigid], axis=2).reshape(-1, len(columns) + 6)
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    step = np.linalg.lstsq(a / scale, (target - start).ravel(), rcond=1e-10)[0] / scale
    flat = np.concatenate(vectors)
    return {names[i]: float(flat[i] + step[k]) for k, i in enumerate(columns)}


def rigidly_aligned_difference(reference: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """(N,) [m] |moved - reference| after the best rigid motion of ``moved`` onto ``reference``."""
    rot, trans = rigid_fit(moved, reference)
    return np.linalg.norm(moved @ rot.T + trans - reference, axis=1)


def _with_changes(old: FittedModel, changes) -> dict:
    """The old fit's parameters with the given changes added."""
    parameters = {e: dict(p) for e, p in old.parameters.items()}
    for c in changes:
        parameters[c.effect][c.name] += c.change
    return parameters


def _moved_to(fit: FittedModel, values: dict) -> FittedModel:
    """The fit with some of its parameters set to ``values`` ({name: value SI})."""
    parameters = {e: {n: values.get(n, v) for n, v in p.items()} for e, p in fit.parameters.items()}
    return replace(fit, parameters=parameters)


def compare_models(robot: RobotModel, old: FittedModel, new: FittedModel, q: np.ndarray, *, z: float = 3.0,
                   context: MeasurementContext | None = None) -> Comparison:
    """Compare two fits of ``robot`` (see the module docstring).

    Parameters
    ----------
    robot : RobotModel
        The robot both were fitted to.
    old, new : Diagnosis or FittedModel
        The earlier and the later campaign's diagnosis (fitted, or read with
        :func:`tcr_accuracy.read_result`).
    q : array-like of shape (N, n_joints)
        Joint values [rad, m] to evaluate the TCP effect on (N >= 3).
    z : float, default=3.0
        A change is significant beyond this many standard errors of it.
    context : MeasurementContext, optional
        The poses' payload, temperature, ... (None: the defaults).

    Returns
    -------
    Comparison

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> same = tcr.compare_models(robot, d, d, measured.q)
    >>> tcr.Comparison.from_json(same.to_json()).significant  # one campaign against itself: nothing changed
    []
    """
    old, new = (_fitted(fit, label) for fit, label in ((old, "old"), (new, "new")))
    check_same_robot(robot, old, new)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[0] < 3 or q.shape[1] != robot.n_joints:
        raise InputError(f"poses: need at least 3 rows of {robot.n_joints} joint values, got shape {q.shape}")
    changes, setup, one_sided = parameter_changes(old, new, z)
    notes = []
    partial = [o for o in one_sided if not o.whole_effect]
    if partial:  # the fits kept different members of the same effects: compare on the common ones
        shared = {c.name for c in changes + setup}
        common = [_moved_to(f, on_common_basis(robot, f, shared, q, context)) for f in (old, new)]
        raw = {c.name: (c.old, c.new) for c in changes + setup}
        changes, setup, _ = parameter_changes(*common, z)
        changes, setup = ([replace(c, as_fitted=raw[c.name]) for c in group] for group in (changes, setup))
        notes.append("the fits kept different parameters of " + ", ".join(sorted({o.effect for o in partial}))
                     + " (identifiability differs with the poses): what those kept in one fit only do to the TCP "
                     "is carried into the common ones (least squares over the poses) before comparing")
    # the TCP offset is held at the old fit's: the TCP effect is the robot's change with the same tool
    tool_held = {e: dict(p) for e, p in new.parameters.items()}
    for c in setup:
        tool_held[c.effect][c.name] = old.parameters[c.effect][c.name]
    p_old = robot_positions(robot, old.parameters, old.options, q, context)
    p_new = robot_positions(robot, tool_held, new.options, q, context)
    p_sig = robot_positions(robot, _with_changes(old, [c for c in changes if c.significant]), old.options, q,
                            context)
    if any(c.significant for c in setup):
        notes.append("the TCP offset moved beyond z standard errors (" + ", ".join(
            c.name for c in setup if c.significant) + "): another tool or reflector seat, or chance; held at the "
            "old fit's value for the TCP effect")
    tested = len(changes) + len(setup)
    notes.append(f"by chance alone, {tested} unchanged parameters would give {tested * math.erfc(z / math.sqrt(2)):.2g} "
                 f"flags at z = {z:g} on average (two-sided normal tail)")
    return Comparison(robot.name, z, changes, setup, one_sided,
                      TcpEffect.of(rigidly_aligned_difference(p_old, p_new)),
                      TcpEffect.of(rigidly_aligned_difference(p_old, p_sig)), q.shape[0],
                      (old.source, new.source), notes, robot_source=robot.robot_source, tool_frame=robot.tool_frame)
