"""The interface every effect shares, and the registry that is nothing but the classes.

An effect is one class, in one module of this package, deriving from :class:`Effect`
(or :class:`LinearEffect`), registered by name with :func:`register` (the package lists the built-in
ones in :mod:`tcr_accuracy.effects`): ``diagnose``, ``simulate``, the CLI and the reports read
everything they need from the class itself. The class holds the effect's physics, what the
effect is, and beside it two attributes of their own:

* ``fit_policy``, a :class:`~tcr_accuracy.effects.fit_policy.FitPolicy`: how the diagnosis
  treats it (its place in the vocabulary, last resort, the options it builds it with for the
  data, a smoothness penalty);
* ``simulation``, a :class:`~tcr_accuracy.effects.simulation_rules.SimulationRules`: how
  ``simulate`` and the blind benchmark draw it as a hidden truth.

:func:`register` refuses a class that declares a policy value or a drawing hook on the class
itself: each concern has one home.

==========================  ===========================================================
physics (class attribute)   meaning
==========================  ===========================================================
``name``                    the vocabulary word (``compliance``); parameters are ``<name>.*``
``summary``                 one line for reports and ``--help``
``in_words``                a few plain words naming it in a sentence ("joints giving way under gravity")
``physics``                 one line: why the parameters lie where :meth:`Effect.physical_range`
                            says (the diagnosis fits inside that range and reports it)
``family``                  the family of mechanisms (:data:`~tcr_accuracy.effects.mechanisms.FAMILIES`):
                            the level a diagnosis names when the members cannot be told apart
``geometric``               its fitted parameters are pure geometry (go into an as-built URDF)
``context_columns``         CSV context it reads (``payload_kg``, ``temperature_c``,
                            ``<joint>_dir``)
``non_negative``            its parameters are magnitudes (a width, a compliance): the
                            default physical range starts at zero, simulate draws |value|
``stochastic``              random scatter, not a bias: predictions of the mean pose leave it
                            out, a diagnosis tests it and never fits it
==========================  ===========================================================

Three ranges per parameter: :meth:`Effect.parameter_scales` (its typical size),
:meth:`Effect.physical_range` (what the effect's own physics allows) and :meth:`Effect.fit_range`
(the union of the ranges of every mechanism with the effect's signature: the diagnosis keeps
any signature the data want inside it). What a fitted value means is read from
:meth:`Effect.mechanisms`: the effect's own physics and the other causes with the same
signature, each with the values it explains.

Options are explicit keyword-only arguments of the class's ``__init__`` (a misspelt
option fails); :attr:`Effect.options` lists those that differ from their defaults.

What an effect does: ``perturb(params, q, context)`` gives joint-side offsets ``dq``
(N, n_joints) and/or error vectors ``x`` (N, n_error_params) of
:class:`~tcr_accuracy.model.errors.ErrorModel`, i.e. it acts on the Pinocchio model's joint
values and joint placements, never on output positions; ``parameter_jacobian`` gives
their derivatives in the parameters (exact for linear effects; :attr:`Effect.analytic_jacobian`
says whether the class writes its own).
"""

from __future__ import annotations

import abc
import inspect
from contextlib import contextmanager
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..model.context import MeasurementContext
from ..model.errors import ErrorModel
from ..exceptions import InputError
from ..model.robot import RobotModel
from ..units import REVOLUTE
from .fit_policy import FitPolicy
from .simulation_rules import SimulationRules


@dataclass(frozen=True)
class EffectOutput:
    """What an effect does to the model for N joint vectors.

    dq : ndarray of shape (N, n_joints) or None
        Offsets added to the commanded joint values [rad, m].
    x : ndarray of shape (N, n_error_params) or None
        Geometric error vectors (layout of :class:`~tcr_accuracy.model.errors.ErrorModel`).
    """

    dq: np.ndarray | None = None
    x: np.ndarray | None = None


@dataclass(frozen=True)
class EffectJacobian:
    """Derivatives of an effect's output with respect to its k parameters.

    dq : ndarray of shape (N, n_joints, k) or None
    x : ndarray of shape (N, n_error_params, k), or (n_error_params, k) when the same
        for every row, or None
    """

    dq: np.ndarray | None = None
    x: np.ndarray | None = None


#: name -> class, filled by :func:`register` (the registered classes are the vocabulary).
_REGISTRY: dict[str, type["Effect"]] = {}

#: Names an effect class once declared on itself, and the attribute that holds each now:
#: :func:`register` refuses a class declaring one, so physics, fitting policy and simulation
#: rules stay apart.
MOVED_OFF_THE_CLASS = {
    **{n: "fit_policy" for n in ("order", "in_vocabulary", "last_resort", "requires_context",
                                 "options_for_data", "penalty_weights")},
    "dominant_candidate": "simulation (its dominant_place)",
    **{n: "simulation" for n in ("dominant_spec", "finish_dominant", "beyond_physics")},
}


class Effect(abc.ABC):
    """One effect: its parameters and how it perturbs the model.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot (never modified). Subclasses add their options as
        keyword-only arguments.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> effect = tcr.make_effect("compliance", tcr.load_robot("ur5"))
    >>> isinstance(effect, tcr.Effect), effect.family
    (True, 'gravity')
    """

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    #: the effect named in a few plain words, for a sentence a person acts on ("joints giving way under
    #: gravity"); empty: the summary stands in
    in_words: ClassVar[str] = ""
    #: why the parameters lie in :meth:`physical_range` (reports print it next to the range)
    physics: ClassVar[str] = ""
    #: the family of mechanisms it belongs to (``geometric``, ``gravity``, ``direction``, ``periodic`` (a
    #: joint's own angle: ``transmission``, ``cyclic``, ``angle_table``), ``scale``, ``thermal``, ``time``;
    #: ``setup`` for the tracker frame)
    family: ClassVar[str] = ""
    geometric: ClassVar[bool] = False
    context_columns: ClassVar[tuple[str, ...]] = ()
    non_negative: ClassVar[bool] = False
    stochastic: ClassVar[bool] = False
    #: how the diagnosis treats it (:mod:`~tcr_accuracy.effects.fit_policy`)
    fit_policy: ClassVar[FitPolicy] = FitPolicy()
    #: how simulate draws it as a hidden truth (:mod:`~tcr_accuracy.effects.simulation_rules`)
    simulation: ClassVar[SimulationRules] = SimulationRules()

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot

    @property
    def options(self) -> dict:
        """The keyword options this instance was built with, where they differ from the default."""
        out = {}
        for name, parameter in inspect.signature(type(self).__init__).parameters.items():
            if parameter.kind is not inspect.Parameter.KEYWORD_ONLY:
                continue
            value = getattr(self, name)
            default = parameter.default
            same = (value is None and default is None) if (value is None or default is None) else \
                np.array_equal(np.asarray(value, dtype=object), np.asarray(default, dtype=object))
            if not same:
                out[name] = value
        return out

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options.items() if k != "rng")
        return f"{type(self).__name__}({self.robot.name}{', ' + opts if opts else ''})"

    # -- parameters ----------------------------------------------------------------------
    @abc.abstractmethod
    def parameter_names(self) -> list[str]:
        """Names ``<effect>.<...>`` of the k parameters."""

    @abc.abstractmethod
    def parameter_units(self) -> list[str]:
        """SI unit of each parameter (``m``, ``rad``, ``rad/Nm``, ``m/N``, ``1/K``, ``1``)."""

    @abc.abstractmethod
    def parameter_scales(self) -> np.ndarray:
        """(k,) typical magnitude of each parameter [SI]: fit scaling, simulate defaults."""

    @property
    def n_params(self) -> int:
        return len(self.parameter_names())

    @property
    def analytic_jacobian(self) -> bool:
        """False when :meth:`parameter_jacobian` is the base class's finite differences of
        :meth:`perturb` (read from the class, never declared: it cannot go stale)."""
        return type(self).parameter_jacobian is not Effect.parameter_jacobian

    def physical_range(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of each parameter on a real robot [SI]: the diagnosis fits inside it.

        Default: a magnitude (``non_negative``) is at least zero, anything else is free.
        Effects with a physics of their own override this and say why in ``physics``.
        """
        k = self.n_params
        return (np.zeros(k) if self.non_negative else np.full(k, -np.inf)), np.full(k, np.inf)

    def fit_range(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of each parameter that keeps a fit sane [SI]: the diagnosis fits inside
        it, whatever the sign, so that a signature the data show is kept even where it belongs
        to another mechanism than the effect's own (:meth:`mechanisms` says which). It is the
        union of the mechanisms' ranges: a value held on its bound is one the data push beyond
        every known mechanism. Physics, not fitting policy: it is where the known causes of the
        effect's signature lie (an effect's wider mechanisms take their bounds from it), whoever
        reads it.

        Default: ten times the largest finite bound of :meth:`physical_range`, either sign.
        """
        lower, upper = self.physical_range()
        bound = 10.0 * np.maximum(np.abs(lower), np.abs(upper))
        return -bound, bound

    def mechanisms(self):
        """The mechanisms this effect's signature can stand for, each with the parameter values it
        explains (:class:`~tcr_accuracy.effects.mechanisms.Mechanism`), the effect's own physics
        first. Default: its own physics over :meth:`physical_range`."""
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        return (Mechanism(self.name, self.summary, "", lower, upper),)

    def zeros(self) -> np.ndarray:
        return np.zeros(self.n_params)

    def check_params(self, params) -> np.ndarray:
        params = np.asarray(params, dtype=float).reshape(-1)
        if params.shape != (self.n_params,):
            raise InputError(f"effect {self.name}: {params.size} parameter values given, it has "
                             f"{self.n_params} ({', '.join(self.parameter_names()[:4])}, ...)")
        if not np.all(np.isfinite(params)):
            raise InputError(f"effect {self.name}: non-finite parameter value")
        return params

    @property
    def error_model(self) -> ErrorModel:
        em = self.__dict__.get("_error_model")
        if em is None:
            em = self.__dict__["_error_model"] = ErrorModel(self.robot)
        return em

    # -- what it does --------------------------------------------------------------------
    @abc.abstractmethod
    def perturb(self, params, q: np.ndarray, context: MeasurementContext) -> EffectOutput:
        """Joint offsets and/or error vectors for commanded joints q (N, n) [SI]."""

    def parameter_jacobian(self, params, q: np.ndarray, context: MeasurementContext) -> EffectJacobian:
        """d(dq)/d(params) (N, n, k) and d(x)/d(params) (N, p, k) at params.

        Fallback: central finite differences of :meth:`perturb` (step 1e-3 of each
        parameter's scale). Linear effects override this with their exact maps.
        """
        params = self.check_params(params)
        q = np.atleast_2d(q)
        steps = 1e-3 * self.parameter_scales()
        n, nj, p = q.shape[0], self.robot.n_joints, self.error_model.size
        ddq = np.zeros((n, nj, self.n_params))
        dx = np.zeros((n, p, self.n_params))
        for k, h in enumerate(steps):
            e = np.zeros(self.n_params)
            e[k] = h
            plus, minus = self.perturb(params + e, q, context), self.perturb(params - e, q, context)
            if plus.dq is not None:
                ddq[:, :, k] = (plus.dq - minus.dq) / (2 * h)
            if plus.x is not None:
                dx[:, :, k] = (plus.x - minus.x) / (2 * h)
        return EffectJacobian(ddq, dx)


class LinearEffect(Effect):
    """An effect linear in its parameters: perturb = parameter_jacobian @ params."""

    @abc.abstractmethod
    def parameter_jacobian(self, params, q, context) -> EffectJacobian:  # noqa: D102
        ...

    def perturb(self, params, q, context) -> EffectOutput:
        params = self.check_params(params)
        q = np.atleast_2d(np.asarray(q, dtype=float))
        jac = self.parameter_jacobian(params, q, context)
        dq = None if jac.dq is None else jac.dq @ params
        x = None
        if jac.x is not None:
            x = jac.x @ params
            if x.ndim == 1:
                x = np.broadcast_to(x, (q.shape[0], x.size))
        return EffectOutput(dq=dq, x=x)


class ErrorVectorEffect(LinearEffect):
    """An effect whose parameters are entries of the error vector itself: ``<name>.<entry>``
    sets the :class:`~tcr_accuracy.model.errors.ErrorModel` entry ``<entry>`` (``j3.dy``,
    ``base.rz``); translations in m, rotations in rad."""

    def parameter_units(self):
        return ["m" if n.split(".")[-1].startswith("d") else "rad" for n in self.parameter_names()]

    def parameter_jacobian(self, params, q, context):
        em = self.error_model
        cols = [em.index(n[len(self.name) + 1:]) for n in self.parameter_names()]
        dx = np.zeros((em.size, len(cols)))
        dx[cols, np.arange(len(cols))] = 1.0
        return EffectJacobian(x=dx)


class PerJointEffect(LinearEffect):
    """A joint-side effect with one parameter per joint: ``dq_j = p_j * signal_j(q, context)``.

    Subclasses give the per-joint signal (N, n_joints) and the unit of each parameter.
    """

    def parameter_names(self):
        return [f"{self.name}.{n}" for n in self.robot.joint_names]

    @abc.abstractmethod
    def signal(self, q: np.ndarray, context: MeasurementContext) -> np.ndarray:
        """(N, n_joints) d(dq_j)/d(p_j)."""

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(np.asarray(q, dtype=float))
        s = self.signal(q, context)
        n = self.robot.n_joints
        ddq = np.zeros((s.shape[0], n, n))
        ddq[:, np.arange(n), np.arange(n)] = s
        return EffectJacobian(dq=ddq)


def joint_unit(kind: str) -> str:
    """SI unit of a joint value of this kind."""
    return "rad" if kind == REVOLUTE else "m"


def per_joint_kind(robot: RobotModel, revolute: float, prismatic: float) -> np.ndarray:
    """(n_joints,) one value per joint by its kind (e.g. a bound in rad or in m)."""
    return np.array([revolute if k == REVOLUTE else prismatic for k in robot.joint_kinds], dtype=float)


# ---------------------------------------------------------------------------------------
# The registry: read-only views of the classes
# ---------------------------------------------------------------------------------------
def effect_classes(*, vocabulary_only: bool = True) -> dict[str, type[Effect]]:
    """Registered effect classes by name, in vocabulary order (``fit_policy.order``, then name)."""
    classes = sorted(_REGISTRY.values(), key=lambda c: (c.fit_policy.order, c.name))
    return {c.name: c for c in classes if c.fit_policy.in_vocabulary or not vocabulary_only}


def vocabulary() -> tuple[str, ...]:
    """The effect vocabulary: names of the registered in-vocabulary effects, in order.

    Returns
    -------
    tuple of str
        ``frames`` first, then the order the diagnosis tries them in.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> "geometry" in tcr.vocabulary() and "compliance" in tcr.vocabulary()
    True
    """
    return tuple(effect_classes())


def effect_class(name: str, *, vocabulary_only: bool = False, source: str = "effect") -> type[Effect]:
    """The class registered under ``name``, or one InputError line listing the names there are."""
    classes = effect_classes(vocabulary_only=vocabulary_only)
    if name in classes:
        return classes[name]
    inside = [n for n, c in classes.items() if c.fit_policy.in_vocabulary]
    outside = [n for n, c in classes.items() if not c.fit_policy.in_vocabulary]
    hint = f"; outside the vocabulary (simulate only): {', '.join(outside)}" if outside else ""
    raise InputError(f"{source}: unknown effect {name!r}; effects: {', '.join(inside)}{hint}")


def make_effect(name: str, robot: RobotModel, **options) -> Effect:
    """An effect by name, with its options checked against its keyword arguments.

    Parameters
    ----------
    name : str
        One of :func:`vocabulary` (or an effect outside it that only ``simulate`` uses).
    robot : RobotModel
        The nominal robot the effect acts on.
    **options
        The effect class's keyword-only arguments (a misspelt one is an InputError).

    Returns
    -------
    Effect
        The effect, with ``parameter_names()`` and its error model.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> effect = tcr.make_effect("joint_offsets", tcr.load_robot("ur5"))
    >>> effect.parameter_names()[:2]
    ['joint_offsets.shoulder_pan_joint', 'joint_offsets.shoulder_lift_joint']
    """
    cls = effect_class(name, source="effect")
    accepted = [p for p, spec in inspect.signature(cls.__init__).parameters.items()
                if spec.kind is inspect.Parameter.KEYWORD_ONLY]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise InputError(f"effect {name}: unknown option(s) {', '.join(unknown)} "
                         f"(options: {', '.join(accepted) or 'none'})")
    return cls(robot, **options)


def register(cls: type[Effect]) -> type[Effect]:
    """Add an effect class to the vocabulary under its ``name`` (usable as a class decorator).

    Parameters
    ----------
    cls : type
        A concrete :class:`Effect` subclass with its own ``name``.

    Returns
    -------
    type
        ``cls``, registered.

    Raises
    ------
    TypeError
        Where ``cls`` is abstract or names no effect of its own, or its name is taken by another class;
        where its ``fit_policy`` is no :class:`~tcr_accuracy.effects.fit_policy.FitPolicy` or its
        ``simulation`` no :class:`~tcr_accuracy.effects.simulation_rules.SimulationRules`; where it
        (or a class it derives from) declares a policy value or a drawing hook on the class itself
        (:data:`MOVED_OFF_THE_CLASS`), or ``analytic_jacobian``, which is read from its code.
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)) or "name" not in cls.__dict__ \
            or inspect.isabstract(cls):
        raise TypeError(f"{cls!r} is not a concrete Effect class with a name of its own")
    _check_homes(cls)
    known = _REGISTRY.get(cls.name)
    if known is not None and known is not cls:
        raise TypeError(f"effect name {cls.name!r} is taken by {known.__module__}.{known.__qualname__}")
    _REGISTRY[cls.name] = cls
    return cls


def _check_homes(cls: type[Effect]) -> None:
    """TypeError unless the class keeps its fitting policy and simulation rules in their own attributes."""
    where = f"effect {cls.name!r} ({cls.__module__}.{cls.__qualname__})"
    for klass in (k for k in cls.__mro__ if k not in (Effect, abc.ABC, object)):
        for attribute in klass.__dict__:
            if attribute in MOVED_OFF_THE_CLASS:
                raise TypeError(f"{where}: {klass.__qualname__} declares {attribute!r} on the class; it belongs in "
                                f"its {MOVED_OFF_THE_CLASS[attribute]} attribute")
            if attribute == "analytic_jacobian":
                raise TypeError(f"{where}: {klass.__qualname__} declares 'analytic_jacobian'; it is read from "
                                "whether the class writes its own parameter_jacobian")
    if not isinstance(cls.fit_policy, FitPolicy):
        raise TypeError(f"{where}: fit_policy must be a FitPolicy instance, got {cls.fit_policy!r}")
    if not isinstance(cls.simulation, SimulationRules):
        raise TypeError(f"{where}: simulation must be a SimulationRules instance, got {cls.simulation!r}")


def unregister(name: str) -> None:
    """Remove an effect class from the registry (tests that plug in a toy effect)."""
    _REGISTRY.pop(name, None)


@contextmanager
def plugged_in(cls: type[Effect]):
    """Keep ``cls`` registered inside the block only (a test's own effect)."""
    register(cls)
    try:
        yield cls
    finally:
        unregister(cls.name)


def reference_poses(robot: RobotModel, n: int = 64) -> np.ndarray:
    """(n, n_joints) fixed, reproducible poses spread inside the limits (unbounded: +-pi).

    Effects size their typical parameters on these, so a scale never depends on the data.
    """
    lo, hi = robot.joint_bounds()
    u = np.random.default_rng(20240501).uniform(size=(n, robot.n_joints))
    return lo + (hi - lo) * u


def link_mass_factors_option(robot: RobotModel, factors):
    """``factors`` (the ``link_mass_factors`` option of the gravity effects), returned as given once
    it is None or one finite factor >= 0 per chain joint; else a ValueError that the reader of a
    file words with the file and the key (it said "link mass factors: need 6 values >= 0" only
    when the model was first evaluated, naming neither)."""
    if factors is None:
        return None
    values = np.asarray(factors, dtype=float)
    if values.shape != (robot.n_joints,):
        raise ValueError(f"link_mass_factors: {values.size} values for the {robot.n_joints} joints of "
                         f"{robot.name}; want one factor >= 0 per joint")
    bad = np.flatnonzero(~np.isfinite(values) | (values < 0))
    if bad.size:
        raise ValueError(f"link_mass_factors[{int(bad[0])}]: {values[bad[0]]:g} is not a factor >= 0")
    return factors


def loaded_joint_scales(robot: RobotModel, rms_load: np.ndarray, revolute_target: float,
                        prismatic_target: float) -> np.ndarray:
    """Per-joint compliance scales that turn a joint by a target under its RMS load.

    ``rms_load`` (n_joints, ...) is the RMS gravity load a joint (or each axis of it)
    carries over the reference poses; unloaded entries (below 1e-6 of the largest) get
    the median of the others' scales.
    """
    kinds = np.array([k == REVOLUTE for k in robot.joint_kinds])
    target = np.where(kinds, revolute_target, prismatic_target).reshape((-1,) + (1,) * (rms_load.ndim - 1))
    loaded = rms_load > 1e-6 * max(float(rms_load.max()), 1e-300)
    scales = np.where(loaded, target / np.where(loaded, rms_load, 1.0), np.nan)
    fill = np.nanmedian(scales) if loaded.any() else 1e-6
    return np.where(loaded, scales, fill)
