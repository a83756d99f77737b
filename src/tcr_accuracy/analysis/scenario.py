"""Scenarios: which effects a simulated robot hides, and how its context and noise are drawn.

A *scenario* (a YAML file, a mapping, or a truth file written by
:func:`tcr_accuracy.analysis.simulate.write_truth`) is read here into a :class:`Scenario`, and
each of its effects is resolved into an effect instance with parameter values in SI
(:func:`resolve_effect`). Drawing poses and context, and measuring the perturbed TCP, is
:mod:`tcr_accuracy.analysis.simulate`'s job; this module knows only the format.

Scenario format (every key optional)::

    effects:
      frames:                       # the tracker frame and TCP offset
        base_mm: {dx: 25, dy: -40, dz: 10}
        base_mrad: {rz: 8}
      geometry:
        spread_mm: 0.2              # random: normal, this std, for every length parameter
        spread_mrad: 0.2            # ... and every angle parameter
      joint_offsets:
        offsets_deg: {j2: 0.05, j3: -0.03}
      compliance:
        tcp_rms_mm: 1.5             # scale the drawn compliances to this RMS TCP displacement
        options: {link_mass_spread: 0.05}
      thermal:
        alpha_per_k: 1.2e-5
    context:
      payload_kg: 150               # payload of the rows that carry it (default: a disc cutter)
      payload_fraction: 0.5
      temperature_c: 20             # mean; rows spread uniformly by +-temperature_spread_c
      temperature_spread_c: 10
      directions: random            # random +-1 approach directions per joint, or none
    noise_mm: 0.02

Inside an effect, a key ``<label>_<unit>`` gives values: a number for every parameter
of that dimension, or a mapping ``{selector: value}`` where the selector is the
parameter name without the effect prefix (``j3.dy``), or a leading or trailing part of
it (``j3``, ``dy``); a label that is itself a selector restricts the key to those
parameters (``base_mm: {dx: 25}`` sets ``frames.base.dx``). ``spread_<unit>`` draws normal values with that standard deviation
instead. ``parameters`` takes full names in SI (``compliance.j2: 2.0e-8``): a truth file
is a scenario. An effect with no values is drawn around its typical scales.
``tcp_rms_mm`` rescales the effect to that RMS TCP displacement over the simulated rows.
Units: m, mm, um, rad, mrad, urad, deg, arcsec, per_k, ppm_per_k, ppm, rad_per_nm,
urad_per_nm, deg_per_knm, m_per_n, um_per_n, mm_per_kn; no suffix = dimensionless.

Effects outside the vocabulary (``unmodelled``, ``link_bending``) are named the same way.
What this module needs to know about an effect (its parameters, units, scales and sign
constraint) it reads from the effect's class.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model.context import REFERENCE_TEMPERATURE_C
from ..effects import Effect, effect_class
from ..effects.option_schema import check_options
from ..exceptions import InputError
from ..io.budget_file import parse_table, setting_number
from ..input_files import SIZE_LIMITS, read_input_text
from ..model.robot import RobotModel
from ..units import SUFFIXES, split_suffix


@dataclass
class ContextSpec:
    """How the simulated context columns are drawn."""

    payload_kg: float | None = None  # None: typical_payload_kg(robot)
    payload_fraction: float = 0.5
    temperature_c: float = REFERENCE_TEMPERATURE_C
    temperature_spread_c: float = 10.0
    directions: str = "random"  # "random" or "none"


@dataclass
class Scenario:
    """Hidden effects (name -> spec as in the YAML) and how to draw context and noise."""

    effects: dict[str, dict] = field(default_factory=dict)
    context: ContextSpec = field(default_factory=ContextSpec)
    noise_m: float | None = None
    source: str = "<scenario>"


_CONTEXT_KEYS = {"payload_kg", "payload_fraction", "temperature_c", "temperature_spread_c", "directions"}


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario YAML file (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The YAML file (``effects``, ``context``, ``noise_mm``).

    Returns
    -------
    Scenario
        The hidden effects, their parameters [SI] and the context to draw.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> scenario = tcr.load_scenario("examples/scenario_compliance.yaml")
    >>> "compliance" in scenario.effects
    True
    """
    path = Path(path)
    text = read_input_text(path, "scenario file", limit=SIZE_LIMITS["settings"])
    data = parse_table(text, str(path), "toml" if path.suffix.lower() == ".toml" else "yaml")
    if _is_truth(data):  # a --truth file: the same robot again (more poses, a test set)
        data = truth_as_scenario(data)
    return scenario_from_dict(data, source=str(path))


def _is_truth(data) -> bool:
    """Whether a mapping is a hidden truth as ``simulate --truth`` writes it (each effect with
    its exact parameters and their units)."""
    effects = data.get("effects") if isinstance(data, dict) else None
    return (isinstance(effects, dict) and bool(effects) and isinstance(data.get("context"), dict)
            and all(isinstance(s, dict) and isinstance(s.get("parameters"), dict) and "units" in s
                    for s in effects.values()))


def scenario_from_dict(data: dict, source: str = "<scenario>") -> Scenario:
    """Check the structure of a scenario mapping and wrap it."""
    if not isinstance(data, dict):
        raise InputError(f"{source}: a scenario is a mapping with keys effects, context, noise_mm")
    unknown = set(data) - {"effects", "context", "noise_mm", "robot", "dominant", "outside_vocabulary", "beyond_physics",
                           "seed", "n", "orientation_noise_rad", "noise_m", "notes"}
    if unknown:
        raise InputError(f"{source}: unknown key(s) {', '.join(sorted(unknown))} (keys: effects, context, noise_mm)")
    effects = data.get("effects") or {}
    if not isinstance(effects, dict):
        raise InputError(f"{source}: effects: a mapping effect name -> settings")
    for name, spec in effects.items():
        effect_class(name, source=source)  # raises for unknown names
        if spec is not None and not isinstance(spec, dict):
            raise InputError(f"{source}: effects.{name}: settings must be a mapping (or empty)")
    context = _context(data.get("context") or {}, source)
    noise = None
    if "noise_mm" in data:
        noise = _number(data["noise_mm"], f"{source}: noise_mm") * 1e-3
    elif "noise_m" in data:
        noise = _number(data["noise_m"], f"{source}: noise_m")
    if noise is not None and noise < 0:
        raise InputError(f"{source}: noise must be >= 0")
    if "tcp_rms_mm" in data:
        raise InputError(f"{source}: tcp_rms_mm: belongs to an effect (effects.<name>.tcp_rms_mm)")
    return Scenario(effects={k: dict(v or {}) for k, v in effects.items()}, context=context,
                    noise_m=noise, source=source)


#: Bounds of the context settings: key -> (low, high) [kg, 1, degC, K].
_CONTEXT_RANGES = {"payload_kg": (0.0, 1e6), "payload_fraction": (0.0, 1.0),
                   "temperature_c": (-273.15, 1000.0), "temperature_spread_c": (0.0, 1000.0)}


def _context(ctx, source: str) -> ContextSpec:
    """The ``context:`` mapping of a scenario, every value checked (a number in its range)."""
    if not isinstance(ctx, dict):
        raise InputError(f"{source}: context: a mapping with keys {', '.join(sorted(_CONTEXT_KEYS))}")
    unknown = sorted(set(ctx) - _CONTEXT_KEYS)
    if unknown:
        raise InputError(f"{source}: context: unknown key(s) {', '.join(unknown)} "
                         f"(keys: {', '.join(sorted(_CONTEXT_KEYS))})")
    values = {}
    for key, value in ctx.items():
        if key == "directions":
            if value not in ("random", "none"):
                raise InputError(f"{source}: context.directions: 'random' or 'none', got {value!r:.60}")
            values[key] = value
        elif key == "payload_kg" and value is None:
            values[key] = None  # the robot's typical payload
        else:
            low, high = _CONTEXT_RANGES[key]
            values[key] = setting_number(value, f"{source}: context.{key}", low=low, high=high)
    return ContextSpec(**values)


def _number(value, where: str, *, low: float | None = None) -> float:
    """A number of a scenario (finite, of sane size; ``low``: the least it may be)."""
    return setting_number(value, where) if low is None else setting_number(value, where, low=low)


def _selected(sub: str, selector: str) -> bool:
    parts, sel = sub.split("."), str(selector).split(".")
    return parts[: len(sel)] == sel or parts[-len(sel):] == sel


def resolve_effect(robot: RobotModel, name: str, spec: dict, rng: np.random.Generator,
                   source: str = "<scenario>", lenient: bool = False) -> tuple[Effect, np.ndarray, float | None]:
    """Instantiate one hidden effect and draw/convert its parameters to SI.

    lenient: skip value keys whose unit no parameter has (a robot without prismatic
    joints has no length-valued joint offsets) instead of raising.
    Returns (effect, params, tcp_rms_m or None).
    """
    cls = effect_class(name, source=source)
    where = f"{source}: effects.{name}"
    options = spec.get("options") or {}
    if not isinstance(options, dict):
        raise InputError(f"{where}.options: a mapping option -> value, got {type(options).__name__}")
    options = dict(options)
    mass_spread = options.pop("link_mass_spread", None)
    # the bounds a diagnosis JSON and an as-built YAML hold the same options to: cyclic's max_order
    # 1000000 asked for 3.5 GB of parameters, angle_table's intervals 1000 for a table no data resolve
    check_options(name, options, f"{where}.options")
    if mass_spread is not None:
        spread = _number(mass_spread, f"{where}.options.link_mass_spread", low=0.0)
        options["link_mass_factors"] = np.clip(1.0 + spread * rng.standard_normal(robot.n_joints), 0.1, None)
    try:
        if "link_mass_factors" in options:
            options["link_mass_factors"] = np.asarray(options["link_mass_factors"], dtype=float)
        effect = cls(robot, **options)
    except (TypeError, ValueError) as exc:  # an option the effect does not have (misspelt?), or a bad value
        raise InputError(f"{where}.options: {' '.join(str(exc).split())[:200]}") from None
    names = effect.parameter_names()
    subs = [n[len(name) + 1:] for n in names]
    units = effect.parameter_units()
    values = np.full(len(names), np.nan)
    spreads = np.full(len(names), np.nan)
    tcp_rms = None
    for key, value in spec.items():
        if key == "options":
            continue
        if key == "tcp_rms_mm":
            tcp_rms = _number(value, f"{where}.tcp_rms_mm", low=0.0) * 1e-3
            continue
        if key == "units":  # a --truth file read back: its units must be this effect's own
            if not isinstance(value, dict):
                raise InputError(f"{where}.units: a mapping full parameter name -> unit")
            for pname, unit in value.items():
                if pname in names and str(unit) != units[names.index(pname)]:
                    raise InputError(f"{where}.units.{pname}: {unit!r}, but the parameter is in "
                                     f"{units[names.index(pname)]} (a truth file's values are SI)")
            continue
        if key == "parameters":
            if not isinstance(value, dict):
                raise InputError(f"{where}.parameters: a mapping full parameter name -> SI value")
            for pname, v in value.items():
                if pname not in names:
                    raise InputError(f"{where}.parameters: unknown parameter {pname!r} "
                                     f"(parameters: {', '.join(names)})")
                values[names.index(pname)] = _number(v, f"{where}.parameters.{pname}")
            continue
        label, unit = split_suffix(key)
        dim, factor = SUFFIXES[unit] if unit else ("1", 1.0)
        target = spreads if label == "spread" else values
        matching = [k for k, u in enumerate(units) if u == dim]
        if not matching and lenient:
            continue
        if not matching:
            raise InputError(f"{where}.{key}: no parameter of {name} is in {dim} "
                             f"(its units: {', '.join(sorted(set(units)))})")
        if label != "spread":  # a label that names parameters (base_mm, j2_deg) also selects
            named = [k for k in matching if _selected(subs[k], label)]
            matching = named or matching
        if isinstance(value, dict):
            for selector, v in value.items():
                hit = [k for k in matching if _selected(subs[k], selector)]
                if not hit:
                    raise InputError(f"{where}.{key}: {selector!r} selects no {dim} parameter "
                                     f"(parameters: {', '.join(subs)})")
                target[hit] = _number(v, f"{where}.{key}.{selector}") * factor
        else:
            target[matching] = _number(value, f"{where}.{key}") * factor
    if np.any(spreads < 0):
        raise InputError(f"{where}: spreads must be >= 0")
    lower, upper = effect.fit_range()  # every mechanism the effect's signature stands for
    outside = np.flatnonzero(~np.isnan(values) & ((values < lower) | (values > upper)))
    if outside.size:
        k = int(outside[0])
        raise InputError(f"{where}: {effect.parameter_names()[k]} = {values[k]:.4g} {units[k]} is outside what any "
                         f"mechanism of {name} explains ({lower[k]:.4g} to {upper[k]:.4g} {units[k]})")
    draw = np.isnan(values)
    if np.all(draw) and np.all(np.isnan(spreads)):
        spreads = effect.parameter_scales()  # no values at all: around the typical scales
    spreads = np.where(np.isnan(spreads), 0.0, spreads)
    drawn = spreads[draw] * rng.standard_normal(int(draw.sum()))
    values[draw] = np.abs(drawn) if cls.non_negative else drawn + 0.0  # no -0.0
    return effect, values, tcp_rms


def truth_as_scenario(truth: dict) -> dict:
    """A scenario dict that re-creates the truth's effects exactly (parameters in SI)."""
    effects = {}
    for name, spec in truth["effects"].items():
        entry = {"parameters": dict(spec["parameters"])}
        if isinstance(spec.get("units"), dict):
            entry["units"] = dict(spec["units"])
        if spec.get("options"):
            entry["options"] = dict(spec["options"])
        effects[name] = entry
    return {"effects": effects, "context": dict(truth["context"]), "noise_m": truth["noise_m"]}
