"""Each effect's keyword options as a file may give them, as JSON Schema.

A diagnosis JSON (``effect_options``) and an as-built YAML (``options``) carry the options each
effect was built with (:attr:`tcr_accuracy.effects.base.Effect.options`). Read back, an option
sizes the model: ``cyclic``'s ``max_order`` sets how many parameters there are, so a forged
``max_order: 1e9`` would build a model of billions of parameters. Each option is held here to
its type and to a range a real model has; an option an effect does not take is refused.
``tests/test_result_files.py`` checks that every keyword option of every effect is listed.
"""

from __future__ import annotations

_LINK_MASS_FACTORS = {"anyOf": [{"type": "null"}, {"type": "array", "maxItems": 10_000,
                                                   "items": {"type": "number", "minimum": 0, "maximum": 1e3}}]}
_NAMES = {"type": "array", "maxItems": 100_000, "items": {"type": "string", "minLength": 1, "maxLength": 1000}}

_ANGLES = {"anyOf": [{"type": "null"}, {"type": "array", "maxItems": 10_000,
                                        "items": {"type": "number", "minimum": -1e3, "maximum": 1e3}}]}

#: effect -> option -> JSON Schema of its value (options not listed are refused).
OPTIONS = {
    # knot intervals per joint (intervals - 3 parameters per revolute joint: the diagnosis sets up to 256 from
    # the data's density), each joint's travel [rad] and its inner knots [rad] (None: equal intervals)
    "angle_table": {"intervals": {"type": "integer", "minimum": 4, "maximum": 1000},
                    "lower": _ANGLES, "upper": _ANGLES,
                    "knots": {"anyOf": [{"type": "null"}, {"type": "array", "maxItems": 10_000, "items": {
                        "anyOf": [{"type": "null"}, {"type": "array", "maxItems": 999, "items": {
                            "type": "number", "minimum": -1e3, "maximum": 1e3}}]}}]}},
    "backlash": {"link_mass_factors": _LINK_MASS_FACTORS},
    "clearance": {"joints": {"anyOf": [{"type": "null"}, _NAMES]}},
    "compliance": {"link_mass_factors": _LINK_MASS_FACTORS},
    # the highest order of the Fourier series: 2 (max_order - 2) parameters per revolute joint
    "cyclic": {"max_order": {"type": "integer", "minimum": 3, "maximum": 200}},
    # the campaign's time axis, its start and span in that axis' unit (s or rows: up to ~30 years of
    # seconds since 1970), the warm-up's time constant as a share of the span
    "drift": {"time_axis": {"enum": ["order", "time_s"]},
              "start": {"type": "number", "minimum": -1e12, "maximum": 1e12},
              "span": {"type": "number", "exclusiveMinimum": 0, "maximum": 1e12},
              "time_constant": {"type": "number", "exclusiveMinimum": 0, "maximum": 100}},
    "frames": {"tool_rotation": {"type": "boolean"}, "session_frames": {"type": "boolean"},
               "session_tools": {"type": "boolean"},
               "sessions": {"anyOf": [{"type": "null"}, {"type": "array", "maxItems": 10_000,
                                                         "items": {"type": ["string", "integer"]}}]}},
    "geometry": {"components": {"anyOf": [{"type": "null"}, _NAMES]}},
    "lateral_compliance": {"link_mass_factors": _LINK_MASS_FACTORS},
    "thermal": {"per_link": {"type": "boolean"},
                "reference_temperature_c": {"type": "number", "minimum": -273.15, "maximum": 1000}},
    "transmission": {"harmonics": {"type": "array", "minItems": 1, "maxItems": 100, "uniqueItems": True,
                                   "items": {"type": "integer", "minimum": 1, "maximum": 100}}},
}


def options_schema(effect: str) -> dict:
    """The JSON Schema of the options object of ``effect`` (no option for an effect not listed)."""
    return {"type": "object", "properties": OPTIONS.get(effect, {}), "additionalProperties": False}


def check_options(effect: str, options, where: str) -> dict:
    """``options`` of ``effect`` checked against :func:`options_schema`; returns them.

    Raises
    ------
    InputError
        One line naming ``where`` (the file and key) and the option at fault.
    """
    import jsonschema

    from ..exceptions import InputError

    error = jsonschema.exceptions.best_match(
        jsonschema.Draft202012Validator(options_schema(effect)).iter_errors(options))
    if error is not None:
        path = "".join(f".{p}" if isinstance(p, str) else f"[{p}]" for p in error.absolute_path)
        raise InputError(f"{where}{path}: {' '.join(str(error.message).split())[:300]}")
    return options
