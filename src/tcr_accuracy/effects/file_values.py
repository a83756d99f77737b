"""Effect parameters and options read back from a result file (a diagnosis JSON, an as-built YAML).

A file may have been edited, truncated or forged, and what it holds goes into a URDF, a
controller or a compensation: every value is checked before it is used, and the first one at
fault is one :class:`~tcr_accuracy.exceptions.InputError` line naming the file and the key.

* A number is a JSON/YAML number: ``true``/``yes`` (a boolean), text (``"0x10"``, ``"1:30"``),
  null, a list are refused, and so is anything not finite.
* A parameter lies within what a diagnosis can fit: the effect's :meth:`~Effect.fit_range`, the
  union of the mechanisms it can stand for, which holds its :meth:`~Effect.physical_range`
  (fits keep any sign within it, so a negative compliance is a result, not a forgery). The
  setup's ``frames`` are unbounded by physics; a file's are held to :data:`SETUP_LIMITS` (a TCP
  offset of 10 m or a tracker 1 km away is no measurement setup).
* An option has the type of the effect's default (a number for a number, a flag for a flag,
  text only where the default is text), integers within 0..:data:`MAX_INTEGER_OPTION`.
"""

from __future__ import annotations

import inspect
import math

import numpy as np

from ..exceptions import InputError
from .base import Effect, effect_class, make_effect
from .option_schema import check_options

#: Bounds of the setup's parameters read from a file [m, rad]: ``frames.tool.*`` (the measured
#: point on the TCP frame) and ``frames.base.*`` (the tracker's frame).
SETUP_LIMITS = {"tool_m": 10.0, "base_m": 1000.0, "rad": 2.0 * math.pi}
#: Largest integer option a file may set (a cyclic error's highest order, a harmonic).
MAX_INTEGER_OPTION = 1000
#: Largest magnitude of a real-valued option (a reference temperature, a campaign's span).
MAX_REAL_OPTION = 1e9


def file_number(value, where: str) -> float:
    """``value`` as a finite float, or InputError naming ``where`` (file and key)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        shown = repr(value) if not isinstance(value, (dict, list)) else type(value).__name__
        raise InputError(f"{where}: {shown} is not a number")
    number = float(value)
    if not math.isfinite(number):
        raise InputError(f"{where}: {value!r} is not a finite number")
    return number


def parameter_vector(effect: Effect, values, where: str) -> np.ndarray:
    """(k,) the effect's parameters from ``{name: value}`` [SI]; a missing name is 0.

    Parameters
    ----------
    effect : Effect
    values : dict
        Parameter name -> number, as read from the file.
    where : str
        The file and the key of the mapping (``d.json: effect_parameters.geometry``).

    Returns
    -------
    ndarray of shape (k,)

    Raises
    ------
    InputError
        A value that is not a finite number, a name the effect does not have on this robot, or
        a value beyond what a diagnosis can fit.
    """
    if not isinstance(values, dict):
        raise InputError(f"{where}: must map parameter names to numbers, got {type(values).__name__}")
    names = effect.parameter_names()
    index = {n: i for i, n in enumerate(names)}
    lower, upper = _file_range(effect, names)
    vector = np.zeros(len(names))
    for name, value in values.items():
        key = f"{where}.{name}"
        if name not in index:
            raise InputError(f"{key}: {effect.name} has no parameter {name!r} on {effect.robot.name}")
        number = file_number(value, key)
        i = index[name]
        if not lower[i] <= number <= upper[i]:
            unit = effect.parameter_units()[i]
            low, high = effect.physical_range()
            raise InputError(f"{key}: {number:.6g} {unit} is beyond what a diagnosis can fit "
                             f"({lower[i]:.3g} to {upper[i]:.3g} {unit}; physical range {low[i]:.3g} to "
                             f"{high[i]:.3g} {unit})")
        vector[i] = number
    return vector


def _file_range(effect: Effect, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    lower, upper = (np.array(v, dtype=float) for v in effect.fit_range())
    for i, name in enumerate(names):
        if not name.startswith("frames."):
            continue
        component = name.rsplit(".", 1)[-1]
        bound = SETUP_LIMITS["rad"] if component.startswith("r") else \
            SETUP_LIMITS["tool_m" if name.startswith("frames.tool.") else "base_m"]
        lower[i], upper[i] = max(lower[i], -bound), min(upper[i], bound)
    return lower, upper


def effect_options(name: str, options, where: str) -> dict:
    """An effect's options from a file, each of the type of the effect's default.

    Parameters
    ----------
    name : str
        The effect.
    options : dict or None
        Option name -> value, as read from the file.
    where : str
        The file and the key of the mapping (``d.json: effect_options.cyclic``).

    Returns
    -------
    dict
        The options, ready for :func:`~tcr_accuracy.effects.make_effect`.
    """
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise InputError(f"{where}: must map option names to values, got {type(options).__name__}")
    defaults = {p: spec.default for p, spec in inspect.signature(effect_class(name, source=where).__init__)
                .parameters.items() if spec.kind is inspect.Parameter.KEYWORD_ONLY}
    out = {}
    for option, value in options.items():
        key = f"{where}.{option}"
        if option not in defaults:
            raise InputError(f"{key}: {name} has no option {option!r} (options: {', '.join(defaults) or 'none'})")
        out[option] = _option_value(defaults[option], value, key)
    check_options(name, options, where)  # each option's bounds, as a diagnosis JSON's and a scenario's
    return out


def _option_value(default, value, key: str):
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise InputError(f"{key}: {value!r} is not true or false")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_INTEGER_OPTION:
            raise InputError(f"{key}: {value!r} is not a whole number from 0 to {MAX_INTEGER_OPTION}")
        return value
    if isinstance(default, float):
        number = file_number(value, key)
        if abs(number) > MAX_REAL_OPTION:
            raise InputError(f"{key}: {number:.6g} is beyond {MAX_REAL_OPTION:g}")
        return number
    if isinstance(default, str):
        if not isinstance(value, str) or len(value) > 200:
            raise InputError(f"{key}: {value!r} is not a short text")
        return value
    # None or a sequence by default: a list of numbers or names, or null
    if value is None:
        return None
    if not isinstance(value, list):
        raise InputError(f"{key}: {type(value).__name__} is not a list (or null)")
    if len(value) > MAX_INTEGER_OPTION:
        raise InputError(f"{key}: {len(value)} items; at most {MAX_INTEGER_OPTION}")
    items = []
    for k, item in enumerate(value):
        if isinstance(item, str) and len(item) <= 200:
            items.append(item)
        elif isinstance(item, int) and not isinstance(item, bool) and abs(item) <= MAX_INTEGER_OPTION:
            items.append(item)
        elif item is None or (isinstance(item, list) and len(item) <= MAX_INTEGER_OPTION):  # per joint: numbers
            items.append(None if item is None else [file_number(v, f"{key}[{k}][{i}]") for i, v in enumerate(item)])
        else:
            items.append(file_number(item, f"{key}[{k}]"))
    return tuple(items) if isinstance(default, tuple) else items


def checked_effect(name, robot, options, where: str) -> Effect:
    """The effect ``name`` on ``robot`` with the file's options (checked), or one InputError line."""
    if not isinstance(name, str):
        raise InputError(f"{where}: effect names are text, got {name!r}")
    checked = effect_options(name, options, f"{where}.{name}")  # its InputError names the file and key
    try:
        return make_effect(name, robot, **checked)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}.{name}: options not usable ({exc})") from None
