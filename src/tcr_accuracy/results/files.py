"""The JSON results the commands write, validated once on read.

``diagnose --json``, ``iso9283 evaluate --json`` and ``compare --json`` write results that
``report``, ``compare``, ``iso9283 evaluate --model`` and ``export`` read back. Each is read here
by :func:`read_result`, through the one opener (:func:`tcr_accuracy.input_files.read_json_file`:
regular file, size, depth, no NaN) and then against a schema of its kind (JSON Schema, checked
by the ``jsonschema`` library): the keys the readers use, their types, shapes (a 4 x 4 transform,
[low, high] intervals), and ranges (counts >= 1, folds >= 2, lengths and standard errors >= 0 and
below 1 km, effect names from the vocabulary, each effect's options as the effect takes them:
:mod:`tcr_accuracy.effects.option_schema`, which bounds the options that size a model).
Where the robot is loaded, :func:`check_physics` then holds every parameter to its effect's
:meth:`~tcr_accuracy.effects.base.Effect.physical_range` (the diagnosis fits inside it, so a value
outside is a forged or foreign file) and to the effect's parameter names for that robot.

A file that fails is one :class:`~tcr_accuracy.exceptions.InputError` line naming the file, the
key (``$.parameter_std.joint_offsets['joint_offsets.j2']``) and what is wrong; never a
``KeyError`` later, never ``nan`` or ``None`` printed on the customer's page.
"""

from __future__ import annotations

import math

from ..exceptions import InputError
from ..input_files import control_character, read_json_file

#: The longest length a result may hold [mm]: 1 km (as the CLI's options).
MAX_MM = 1e6
#: The most measurements, readings or poses a result may count.
MAX_COUNT = 10**9
#: The most parameters of one effect a diagnosis may hold (a cyclic error of order 200 on 50 joints
#: has 20,000).
MAX_PARAMETERS = 100_000

_TEXT = {"type": "string", "maxLength": 100_000}
_NAME = {"type": "string", "minLength": 1, "maxLength": 1000}
_NUMBER = {"type": "number"}
_MM = {"type": "number", "minimum": 0, "maximum": MAX_MM}
_SIGNED_MM = {"type": "number", "minimum": -MAX_MM, "maximum": MAX_MM}
_MM_OR_NULL = {"anyOf": [_MM, {"type": "null"}]}
_NOISE = {"type": "number", "minimum": 1e-6, "maximum": 1e3}
_NUMBER_OR_NULL = {"anyOf": [_NUMBER, {"type": "null"}]}
_COUNT = {"type": "integer", "minimum": 1, "maximum": MAX_COUNT}
_TEXTS = {"type": "array", "items": _TEXT, "maxItems": 100_000}
_INTERVAL = {"type": "array", "items": _NUMBER_OR_NULL, "minItems": 2, "maxItems": 2}
_MM_INTERVAL = {"type": "array", "items": _SIGNED_MM, "minItems": 2, "maxItems": 2}
_TRANSFORM = {"type": "array", "minItems": 4, "maxItems": 4,
              "items": {"type": "array", "minItems": 4, "maxItems": 4, "items": _NUMBER}}
#: Mean, RMS and max of error norms over ``count`` points.
_STATS = {"type": "object", "properties": {"mean_mm": _MM, "rms_mm": _MM, "max_mm": _MM, "count": _COUNT}}


_VECTOR_MM = {"type": "array", "items": _SIGNED_MM, "minItems": 3, "maxItems": 3}
#: Measured points summarised (:class:`tcr_accuracy.frames.uncertainty_budget.PointSet`, mm).
_POINT_SET = {"type": "object", "required": ["n", "mean_mm", "covariance_mm2", "lower_mm", "upper_mm"],
              "properties": {"n": _COUNT, "mean_mm": _VECTOR_MM, "lower_mm": _VECTOR_MM, "upper_mm": _VECTOR_MM,
                             "covariance_mm2": {"type": "array", "minItems": 3, "maxItems": 3, "items": {
                                 "type": "array", "minItems": 3, "maxItems": 3,
                                 "items": {"type": "number", "minimum": -1e12, "maximum": 1e12}}}}}


def _by_effect(value: dict, names) -> dict:
    """An object keyed by effect names (``names``: the vocabulary) with values of schema ``value``."""
    return {"type": "object", "propertyNames": {"enum": list(names)}, "additionalProperties": value}


def _by_parameter(value: dict) -> dict:
    return {"type": "object", "propertyNames": {"maxLength": 200}, "additionalProperties": value,
            "maxProperties": MAX_PARAMETERS}


def _options_schema(names) -> dict:
    from ..effects.option_schema import options_schema

    return {"type": "object", "propertyNames": {"enum": list(names)},
            "properties": {e: options_schema(e) for e in names}}


def _diagnosis_schema(names) -> dict:
    step = {"type": "object",
            "required": ["effect", "n_parameters", "train_rms_mm", "heldout_mean_mm", "heldout_rms_mm", "heldout_max_mm"],
            "properties": {"effect": {"enum": list(names)}, "effects": {"type": "array", "items": {"enum": list(names)}},
                           "n_parameters": {"type": "integer", "minimum": 0, "maximum": MAX_COUNT},
                           "train_rms_mm": _MM, "heldout_rms_mm": _MM, "heldout_mean_mm": _MM, "heldout_max_mm": _MM,
                           "gain_heldout_rms_mm": {"anyOf": [_SIGNED_MM, {"type": "null"}]},
                           "gain_interval_mm": {"anyOf": [{"type": "null"}, _MM_INTERVAL]},
                           "heldout_count": _COUNT,
                           "z_vs_previous": _NUMBER_OR_NULL}}
    # an effect tried alone with frames: its figures; one not tried: why
    candidate = {"type": "object", "required": ["tried"],
                 "properties": {"tried": {"type": "boolean"}, "why": _TEXT, "heldout_rms_mm_with_frames": _MM,
                                "gain_mm": _SIGNED_MM, "z": {"type": "number", "minimum": -1e6, "maximum": 1e6},
                                "n_parameters": {"type": "integer", "minimum": 0, "maximum": MAX_COUNT}},
                 "if": {"properties": {"tried": {"const": True}}},
                 "then": {"required": ["heldout_rms_mm_with_frames", "gain_mm", "z", "n_parameters"]}}
    return {
        "type": "object",
        "required": ["robot", "parameters"],  # each reader adds the keys it uses (FIT_KEYS, PAGE_KEYS, MODEL_KEYS)
        "properties": {
            "robot": _NAME, "robot_source": _NAME, "tool_frame": _NAME, "measurements": _TEXT,
            "n_measurements": {"type": "integer", "minimum": 3, "maximum": MAX_COUNT},
            "folds": {"type": "integer", "minimum": 2, "maximum": 1000},
            # a noise floor of 0 is no instrument (the page divides by it): at least 1 nm, as --noise-mm
            "noise_floor_mm": _NOISE, "tracker_noise_mm": {"anyOf": [_NOISE, {"type": "null"}]},
            "final_heldout_rms_mm": _MM,
            "final_over_noise": _NUMBER_OR_NULL,
            "gap": _STATS,
            "noise": {"type": "object", "properties": {"per_axis_mm": _MM_OR_NULL, "source": _TEXT,
                                                       "independent": {"type": "boolean"}, "detail": _TEXT}},
            "steps": {"type": "array", "minItems": 1, "maxItems": 10_000, "items": step},
            "selected_effects": {"type": "array", "uniqueItems": True, "items": {"enum": list(names)}},
            "primary_effect": {"anyOf": [{"type": "null"}, {"enum": list(names)}]},
            "parameters": _by_effect(_by_parameter(_NUMBER), names),
            "parameter_std": _by_effect(_by_parameter({"anyOf": [{"type": "number", "minimum": 0},
                                                                 {"type": "null"}]}), names),
            "parameter_interval_95": _by_effect(_by_parameter(_INTERVAL), names),
            "parameter_units": _by_effect(_by_parameter({"type": "string", "maxLength": 50}), names),
            "physical": _by_effect({"type": "object", "properties": {
                "plausible": {"type": "boolean"}, "range": _by_parameter(_INTERVAL),
                "fit_range": _by_parameter(_INTERVAL),
                "pinned": {"type": "array", "maxItems": MAX_PARAMETERS, "items": {
                    "type": "object", "required": ["parameter", "bound"],
                    "properties": {"parameter": _NAME, "bound": {"enum": ["lower", "upper"]}}}},
                "reason": _TEXT}}, names),
            "effect_parameters": _by_effect(_by_parameter(_NUMBER), names),
            "effect_options": _options_schema(names),
            "trackerMbase": _TRANSFORM,
            "joint_names": {"type": "array", "items": _NAME, "maxItems": 1000},
            "fold_assignments": {"type": "integer", "minimum": 1, "maximum": 1000},
            "heldout_by_frame": {"type": "object", "maxProperties": 1000, "additionalProperties": _STATS},
            "sessions": {"type": "array", "maxItems": 100_000},
            "session_setup": {"type": ["object", "null"], "properties": {"chosen": _TEXT}},
            "notes": _TEXTS, "ambiguous": {"type": "array", "items": {"type": "object"}},
            "outside_physics": {"type": "array", "items": {"type": "object"}},
            "structure_remains": {"type": "boolean"}, "structure_verdict": _TEXT,
            "structure": {"type": "object", "properties": {"reason": _TEXT}},
            "extra_scatter": {"type": "object", "properties": {"tested": {"type": "boolean"},
                                                               "detected": {"type": "boolean"}}},
            "selection_frequency": _by_effect({"type": "number", "minimum": 0, "maximum": 1}, names),
            "selection": {"type": "object", "properties": {"n_replays": {"type": "integer", "minimum": 0,
                                                                         "maximum": MAX_COUNT}}},
            "candidates": _by_effect(candidate, names),
            "as_built_urdf": _TEXT, "as_built_effects": _TEXT,
            "frames_measured": {"type": "array", "items": _NAME, "maxItems": 1000},
            "measured_points": _POINT_SET,
            **_findings_schema(names),
        },
    }


def _findings_schema(names) -> dict:
    """What the report's first page reads of a diagnosis' findings: the mechanism each chosen effect
    stands for, its check and what its fit assumed, the families and their shares (each compared
    with the largest), the primary family and group, the order-of-measurement confounds, the
    fitted geometry's plausibility checks, the instrument's specification, the temperatures measured."""
    effect = {"enum": list(names)}
    mechanism = {"type": "object", "required": ["effect", "family", "mechanism", "physical"],
                 "properties": {"effect": effect, "family": _NAME, "mechanism": _TEXT, "physical": {"type": "boolean"},
                                "check": _TEXT, "assumed": _TEXTS}}
    # two shares compared (paired): the larger's lead, its interval and the selection's paired test
    comparison = {"type": "object", "required": ["larger", "smaller", "difference_mm", "interval_mm", "ranked"],
                  "properties": {"larger": _NAME, "smaller": _NAME, "difference_mm": _SIGNED_MM,
                                 "interval_mm": _MM_INTERVAL, "z": _NUMBER_OR_NULL, "z_threshold": _NUMBER,
                                 "ranked": {"type": "boolean"}}}
    family = {"type": "object", "required": ["family", "effects", "share_mm", "interval_mm"],
              "properties": {"family": _NAME, "effects": {"type": "array", "items": effect, "maxItems": 1000},
                             "share_mm": _SIGNED_MM, "interval_mm": _MM_INTERVAL, "what": _TEXT,
                             "stand_ins": {"type": "array", "items": effect, "maxItems": 1000},
                             "below_largest": comparison}}
    check = {"type": "object", "required": ["what", "subject", "flagged", "text"],
             "properties": {"what": _NAME, "subject": _NAME, "flagged": {"type": "boolean"}, "text": _TEXT}}
    mpe = {"type": "array", "items": {"type": "number", "minimum": 0, "maximum": 1e9}, "minItems": 2, "maxItems": 2}
    temperature = {"type": "number", "minimum": -1e4, "maximum": 1e4}
    return {
        "mechanisms": {"type": "array", "items": mechanism, "maxItems": 1000},
        "families": {"type": "array", "items": family, "maxItems": 1000},
        "primary_family": {"anyOf": [{"type": "null"}, _NAME]},
        "primary_group": {"type": "array", "items": effect, "maxItems": 1000},
        "own_share_ranking": {"type": "array", "items": comparison, "maxItems": 1000},
        "plausibility": {"type": "object", "properties": {
            "tolerance": {"anyOf": [{"type": "null"}, {"type": "object", "properties": {"robot_class": _NAME}}]},
            "checks": {"type": "array", "items": check, "maxItems": 10_000}}},
        "confounding": {"type": "array", "items": {"type": "object", "required": ["why"],
                                                   "properties": {"why": _TEXT}}},
        "instrument": {"anyOf": [{"type": "null"}, {"type": "object", "required": ["transverse_mpe_um", "radial_mpe_um"],
                                                    "properties": {"name": _TEXT, "transverse_mpe_um": mpe,
                                                                   "radial_mpe_um": mpe}}]},
        "where": {"type": "object", "properties": {
            "joints": {"type": "object", "additionalProperties": {
                "type": "object", "properties": {"unit": {"enum": ["m", "rad"]}}}},
            "temperature_c": {"type": "object", "properties": {"bins": {"type": "array", "maxItems": 10_000, "items": {
                "type": "object", "required": ["low", "high"], "properties": {"low": temperature,
                                                                               "high": temperature}}}}}}},
    }


def _iso_figures(required: bool) -> dict:
    pose = {"type": "object", "required": ["pose_id", "n", "ap_mm", "ap_x_mm", "ap_y_mm", "ap_z_mm", "rp_mm"],
            "properties": {"pose_id": {"anyOf": [{"type": "integer", "minimum": -(2**31), "maximum": 2**31 - 1},
                                                 _NAME]}, "n": _COUNT,
                           "ap_mm": _MM, "rp_mm": _MM_OR_NULL, "ap_x_mm": _SIGNED_MM, "ap_y_mm": _SIGNED_MM,
                           "ap_z_mm": _SIGNED_MM, "l_mean_mm": _MM_OR_NULL, "s_l_mm": _MM_OR_NULL, "pose": _NAME,
                           "instrument_distance_mm": _MM}}
    return {
        "type": "object",
        "required": ["poses", "summary", "n_readings", "frame"] if required else ["poses", "summary"],
        "properties": {
            "n_readings": _COUNT, "frame": _NAME, "frame_fit": _TEXT, "measurements": _TEXT,
            "frame_source": _TEXT, "ap_absolute": {"type": "boolean"}, "frame_residual_rms_mm": _MM_OR_NULL,
            "frame_n_points": {"anyOf": [{"type": "null"}, _COUNT]}, "standard_cycles": _COUNT,
            "robot": _NAME, "robot_source": _NAME, "tool_frame": _NAME, "model": _TEXT, "kind": _TEXT,
            "poses": {"type": "array", "minItems": 1, "maxItems": 100_000, "items": pose},
            "summary": {"type": "object", "required": ["ap_max_mm", "rp_max_mm"],
                        "properties": {"ap_max_mm": _MM, "rp_max_mm": _MM_OR_NULL}},
            "distances": {"type": "array", "items": {"type": "object", "properties": {
                "n": _COUNT, "ad_mm": _SIGNED_MM, "rd_mm": _MM, "commanded_mm": _MM, "mean_mm": _MM}}},
            "directional": {"type": "array", "items": {"type": "object", "properties": {"vap_mm": _MM}}},
            "notes": _TEXTS,
            "condition": {"type": "object", "properties": {"load_pct": _PERCENT, "speed_pct": _PERCENT}},
        },
    }


#: A test condition's share of the rated load or speed [%].
_PERCENT = {"anyOf": [{"type": "null"}, {"type": "number", "minimum": 0, "maximum": 1000}]}


def _iso_schema() -> dict:
    schema = _iso_figures(True)
    schema["properties"]["compensated"] = _iso_figures(False)
    block = _iso_figures(True)  # each test condition's figures, as measured and compensated
    block["properties"]["compensated"] = _iso_figures(False)
    schema["properties"]["conditions"] = {"type": "array", "minItems": 1, "maxItems": 1000, "items": block}
    return schema


def _comparison_schema(names) -> dict:
    # a parameter's value and change in SI (m, rad, ...): within what any effect's physical range allows
    value = {"type": "number", "minimum": -1e6, "maximum": 1e6}
    change = {"type": "object", "required": ["parameter", "unit", "old", "new", "change", "std_error", "z",
                                             "significant"],
              "properties": {"parameter": _NAME, "effect": {"enum": list(names)}, "unit": {"type": "string",
                                                                                          "maxLength": 50},
                             "old": value, "new": value, "change": value,
                             "std_error": {"anyOf": [{"type": "number", "minimum": 0, "maximum": 1e6},
                                                     {"type": "null"}]},
                             "z": {"anyOf": [{"type": "number", "minimum": 0, "maximum": 1e9}, {"type": "null"}]},
                             "significant": {"type": "boolean"}}}
    tcp = {"type": "object", "required": ["mean_mm", "rms_mm", "max_mm"],
           "properties": {"mean_mm": _MM, "rms_mm": _MM, "max_mm": _MM}}
    return {
        "type": "object",
        "required": ["changes", "tcp_effect", "z_threshold", "old", "new", "robot"],
        "properties": {
            "robot": _NAME, "robot_source": _NAME, "tool_frame": _NAME, "old": _TEXT, "new": _TEXT,
            "z_threshold": {"type": "number", "exclusiveMinimum": 0, "maximum": 1000},
            "significant": {"type": "array", "items": _NAME},
            "changes": {"type": "array", "items": change}, "setup_changes": {"type": "array", "items": change},
            "one_fit_only": {"type": "array", "items": {"type": "object"}},
            "tcp_effect": {"type": "object", "required": ["n_poses", "all_changes", "significant_changes"],
                           "properties": {"n_poses": _COUNT, "all_changes": tcp, "significant_changes": tcp}},
            "notes": _TEXTS, "poses": _TEXT,
        },
    }


def _export_schema() -> dict:
    """export's accuracy.json (:class:`tcr_accuracy.asbuilt.export_result.ExportResult`)."""
    figure = {"type": "object", "required": ["form", "file", "on", "data", "n", "mean_mm", "rms_mm", "max_mm"],
              "properties": {"form": _NAME, "file": _TEXT, "on": {"enum": ["measured", "held-out", "k-fold held-out"]},
                             "data": _TEXT, "n": {"type": "integer", "minimum": 0, "maximum": MAX_COUNT},
                             "mean_mm": _MM, "rms_mm": _MM, "max_mm": _MM, "frame_rms_mm": _MM_OR_NULL}}
    return {"type": "object", "required": ["kind", "diagnosis", "robot", "accuracy", "point_sets"],
            "properties": {"kind": {"const": "export"}, "diagnosis": _TEXT, "robot": _NAME, "robot_source": _NAME,
                           "tool_frame": _NAME, "measured_frame": _NAME, "reach_mm": _MM_OR_NULL,
                           "accuracy": {"type": "array", "minItems": 1, "maxItems": 1000, "items": figure},
                           "point_sets": {"type": "object", "propertyNames": {"enum": ["measured", "held-out"]},
                                          "additionalProperties": _POINT_SET}}}


def schema_of(kind: str) -> dict:
    """The JSON Schema of a result of ``kind`` ('diagnosis', 'iso9283', 'comparison', 'export')."""
    from ..effects import vocabulary

    names = sorted(set(vocabulary()) | {"frames"})
    return {"diagnosis": _diagnosis_schema, "iso9283": lambda n: _iso_schema(),
            "comparison": _comparison_schema, "export": lambda n: _export_schema()}[kind](names)


#: What a diagnosis must hold to be compared: each parameter's standard error and unit.
FIT_KEYS = ("parameter_std", "parameter_units")
#: What a diagnosis must hold for the report's first page.
PAGE_KEYS = ("n_measurements", "folds", "steps", "selected_effects", "noise_floor_mm", "candidates", *FIT_KEYS)
#: What a diagnosis must hold to be exported (``diagnose --json`` and ``Diagnosis.to_json`` write them).
MODEL_KEYS = ("robot_source", "tool_frame", "effect_parameters", "trackerMbase")
#: The keys each kind must hold (a diagnosis: :data:`PAGE_KEYS` too where a report reads it).
REQUIRED = {"diagnosis": PAGE_KEYS, "iso9283": ("robot",), "comparison": (), "export": ()}  # robot: the one-robot check
#: Keys a result of 0.1 wrote under another name: old name -> the name read (compatibility until 0.2).
RENAMED_KEYS = {"tracker_transform": "trackerMbase"}
#: A container with more elements than this is not handed to the Python validator for its message.
_LARGE = 10_000


def validate_result(doc, kind: str, source, required=()) -> dict:
    """``doc`` checked whole: against the schema of ``kind`` (with the keys ``required`` besides
    those of every such result), for the cross-references a schema cannot say (every parameter
    with a standard error and a unit, named after its effect; a rigid tracker transform), and for
    its figures against each other and its copies of one number against each other
    (:mod:`tcr_accuracy.results.consistency`); returns it. InputError naming ``source`` and the
    key at fault.

    The schema is checked by ``jsonschema-rs`` (compiled: a 60 MB diagnosis in well under a
    second); where it fails, the ``jsonschema`` library words the error on the part at fault (its
    best match among the errors there, as it always did). ``jsonschema`` alone walks every element
    of a large array or mapping in Python at about 100 us each: a 60 MB file took minutes.
    """
    from .consistency import check_consistency

    schema = schema_of(kind)
    schema["required"] = list(dict.fromkeys([*schema["required"], *required]))
    error = _schema_error(schema, doc)
    if error is not None:
        article = "an" if kind[0] in "aeiou" else "a"
        raise InputError(f"{source}: {error}; not {article} {kind} result as tcr-accuracy writes it")
    _check_text(doc, source)
    if kind == "diagnosis":
        _check_diagnosis_references(doc, source)
    check_consistency(doc, kind, source)
    return doc


def _schema_error(schema: dict, doc) -> str | None:
    """``where: what`` of the first part of ``doc`` the schema refuses, or None when it holds."""
    import jsonschema
    import jsonschema_rs

    fast = jsonschema_rs.Draft202012Validator(schema)
    if fast.is_valid(doc):
        return None
    first = next(iter(fast.iter_errors(doc)))
    path = list(first.instance_path)
    sub_schema, instance = _at(schema, doc, path)
    if sub_schema is not None and _size(instance) <= _LARGE:  # worded by jsonschema on the part at fault
        validator = jsonschema.Draft202012Validator(sub_schema)
        error = jsonschema.exceptions.best_match(validator.iter_errors(instance))
        if error is not None:
            error.path.extendleft(reversed(path))
            where = error.json_path if error.json_path != "$" else "the top level"
            return f"{where}: {_said(error)}"
    where = _json_path(path)
    return f"{where if where != '$' else 'the top level'}: {_rs_said(first, instance)}"


def _rs_said(error, instance) -> str:
    """What jsonschema-rs found wrong with a large container, in jsonschema's words where the kind of
    error has them (its own message quotes the whole container: megabytes)."""
    kind = type(error.kind).__name__
    limit = getattr(error.kind, "limit", None)
    size = len(instance) if isinstance(instance, (dict, list)) else None
    said = {"MaxProperties": f"{size} properties, more than the {limit} allowed",
            "MaxItems": f"{size} items, more than the {limit} allowed",
            "MinItems": f"{size} items, fewer than the {limit} needed",
            "MinProperties": f"{size} properties, fewer than the {limit} needed"}.get(kind)
    if said is None:
        message = " ".join(error.message.split())
        said = f"{kind}: {message[:200]}..." if len(message) > 200 else message
    return said


def _at(schema: dict, doc, path: list):
    """(the schema that applies at ``path`` of ``doc``, the value there); schema None where the path
    runs through a keyword this walk does not follow."""
    node = doc
    for key in path:
        schema = _branch(schema, node)
        if isinstance(node, dict) and isinstance(schema, dict):
            schema = schema.get("properties", {}).get(key, schema.get("additionalProperties"))
        elif isinstance(node, list) and isinstance(schema, dict):
            schema = schema.get("items")
        else:
            return None, node
        if not isinstance(schema, dict):
            return None, node
        node = node[key]
    return schema, node


def _branch(schema: dict, node) -> dict:
    """The ``anyOf`` branch of ``schema`` for a container ``node`` (its type's), else ``schema``."""
    for option in schema.get("anyOf", ()):
        if option.get("type") == ("object" if isinstance(node, dict) else "array"):
            return option
    return schema


def _size(value) -> int:
    """How many elements a value holds, counted until :data:`_LARGE` is passed."""
    count, todo = 0, [value]
    while todo and count <= _LARGE:
        item = todo.pop()
        count += 1
        if isinstance(item, dict):
            todo.extend(item.values())
        elif isinstance(item, list):
            todo.extend(item)
    return count


def _json_path(path: list) -> str:
    """``$.key[3]['dotted.key']`` as jsonschema writes a path."""
    out = "$"
    for key in path:
        if isinstance(key, int):
            out += f"[{key}]"
        elif key.isidentifier():
            out += f".{key}"
        else:
            out += f"[{key!r}]"
    return out


def _check_text(doc, source) -> None:
    """No control or bidirectional-override character in a key or text of a result (a NUL went
    into the report's HTML and Markdown as it was); line breaks and tabs pass. One scan of the
    document's JSON text finds whether there is any (:func:`_suspect_text`); only then is the
    document walked to name the key."""
    if _suspect_text(doc):
        _walk_text(doc, source, "$")


def _suspect_text(doc) -> bool:
    """True when the JSON text of ``doc`` holds a character :func:`_walk_text` may refuse: an escape
    of a C0 control other than a line break or tab (``\\u0000``-``\\u001f``, ``\\b``, ``\\f``; a
    literal backslash before b or f is a false alarm the walk clears), or a character beyond ASCII
    that :func:`~tcr_accuracy.input_files.control_character` refuses (each distinct character is
    looked at once: a 60 MB result holds a few hundred)."""
    import json
    import re

    text = json.dumps(doc, ensure_ascii=False)
    if re.search(r"\\(?:u00[01][0-9a-fA-F]|[bf])", text):
        return True
    return any(control_character(c) is not None for c in set(text) if ord(c) >= 0x7F)


def _walk_text(value, source, where: str) -> None:
    if isinstance(value, dict):
        for key, item in value.items():
            _walk_text(key, source, f"{where} (a key)")
            _walk_text(item, source, f"{where}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _walk_text(item, source, f"{where}[{i}]")
    elif isinstance(value, str):
        bad = control_character(value, allowed="\n\t\r")
        if bad is not None:
            raise InputError(f"{source}: {where[:200]}: holds the control character U+{ord(bad):04X}; not a result as "
                             "tcr-accuracy writes it")


def _said(error) -> str:
    """jsonschema's message, one line, its quoted value cut short (and written as JSON writes it)."""
    import json

    if error.validator == "required" and isinstance(error.instance, dict):
        missing = [k for k in error.validator_value if k not in error.instance]
        return (f"key {missing[0]!r} is missing" if len(missing) == 1 else
                f"keys {', '.join(map(repr, missing))} are missing")
    if error.validator == "type":
        shown = json.dumps(error.instance)[:80]
        wanted = error.validator_value if isinstance(error.validator_value, list) else [error.validator_value]
        text = f"{shown} is not of type {' or '.join(map(repr, wanted))}"
    else:
        text = " ".join(str(error.message).split())
    return text if len(text) <= 300 else text[:297] + "..."


def _check_diagnosis_references(doc: dict, source) -> None:
    for effect, values in doc["parameters"].items():
        for name in values:
            if not name.startswith(f"{effect}."):
                raise InputError(f"{source}: $.parameters.{effect}: parameter {name!r} is not one of {effect}'s")
            for key in (k for k in FIT_KEYS if k in doc):
                if name not in (doc[key].get(effect) or {}):
                    raise InputError(f"{source}: $.{key}.{effect}: no entry for {name}; every fitted parameter has "
                                     "a standard error and a unit in a diagnosis")
    for key in ("effect_parameters", "parameter_interval_95"):
        for effect, values in (doc.get(key) or {}).items():
            bad = next((n for n in values if not n.startswith(f"{effect}.")), None)
            if bad is not None:
                raise InputError(f"{source}: $.{key}.{effect}: parameter {bad!r} is not one of {effect}'s")
    for effect, info in (doc.get("physical") or {}).items():
        fitted = doc["parameters"].get(effect, {})
        bad = next((p["parameter"] for p in info.get("pinned", []) if p["parameter"] not in fitted), None)
        if bad is not None:
            raise InputError(f"{source}: $.physical.{effect}.pinned: {bad!r} is not a fitted parameter of {effect}")
    if "trackerMbase" in doc:
        _check_rigid(doc["trackerMbase"], f"{source}: $.trackerMbase")


def _check_rigid(matrix, where: str) -> None:
    """A 4 x 4 homogeneous rigid transform: orthonormal rotation of determinant +1, last row 0 0 0 1,
    translation within 1 km."""
    import numpy as np

    m = np.asarray(matrix, dtype=float)
    r = m[:3, :3]
    if np.abs(r).max() > 1.0 + 1e-6 or np.abs(m[:3, 3]).max() > MAX_MM * 1e-3 or \
            not np.allclose(m[3], [0, 0, 0, 1], atol=1e-9) or not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or \
            np.linalg.det(r) <= 0:
        raise InputError(f"{where}: not a rigid transform (an orthonormal rotation, a translation within 1 km and "
                         "a last row 0 0 0 1)")


def renamed_keys(doc, source) -> None:
    """Keys a result of 0.1 wrote under another name (:data:`RENAMED_KEYS`) read under today's, in
    place; a file with both is refused unless they agree (one copy of each number)."""
    if not isinstance(doc, dict):
        return
    for old, new in RENAMED_KEYS.items():
        if old in doc:
            value = doc.pop(old)
            if new in doc and doc[new] != value:
                raise InputError(f"{source}: $.{old} and $.{new} differ: one base-to-tracker transform, written "
                                 f"once ({new}; {old} is its name before 0.2)")
            doc[new] = value


def read_result_document(path, kind: str | None = None, *, hint: str = "", required=()) -> tuple[str, dict]:
    """(kind, checked document) of the JSON result file ``path``: opened by the one opener
    (:func:`tcr_accuracy.input_files.read_json_file`: a regular file within its size bound, no NaN)
    and checked whole (:func:`validate_result`). ``kind``: the one expected (any of
    :data:`~tcr_accuracy.results.kinds.KINDS` when None); ``required``: keys the caller needs
    besides (:data:`MODEL_KEYS`). InputError naming the file and key at fault.

    Parameters
    ----------
    path : str or Path
    kind : str, optional
    hint : str
        What to give instead, said when the file is no JSON.
    required : tuple of str

    Returns
    -------
    tuple of (str, dict)
    """
    from .kinds import kind_of

    doc = read_json_file(path, f"{kind or 'JSON'} result", hint=hint)
    renamed_keys(doc, path)
    found = kind_of(doc, str(path)) if kind is None else kind
    if kind is not None and not isinstance(doc, dict):
        raise InputError(f"{path}: not a {kind} result (a JSON object was expected)")
    return found, validate_result(doc, found, path, (*REQUIRED[found], *required) if kind is None else required)


def _within(value: float, low: float, high: float, unit: str, where: str) -> None:
    """InputError when ``value`` lies outside [low, high] (with rounding's slack)."""
    slack = 1e-9 * max([1.0, *(abs(b) for b in (low, high) if math.isfinite(b))])  # both may be infinite
    if not low - slack <= value <= high + slack:
        raise InputError(f"{where}: {value:g} {unit} is outside the range [{low:g}, {high:g}] {unit} a diagnosis "
                         "fits within (the effect's physics and the mechanisms it can stand for)")


def _bound(value, infinite: float) -> float:
    """A range bound as the JSON writes it (null: unbounded), rounded to 9 significant digits."""
    return infinite if value is None or not math.isfinite(value) else float(f"{value:.9g}")


def check_physics(doc: dict, robot, source) -> None:
    """Every parameter of a diagnosis (``parameters`` and ``effect_parameters``) a parameter of its
    effect on ``robot``, within the effect's fit range (:meth:`~tcr_accuracy.effects.base.Effect.fit_range`:
    its physics and the mechanisms it can stand for; a fit never leaves it), the ranges the JSON
    states its own; every option one the effect takes. ``frames`` (the setup: the tracker's frame,
    each measured frame's offset) is left to the schema. InputError naming the key."""
    from ..effects import make_effect

    options = doc.get("effect_options") or {}
    several = len(doc.get("frames_measured") or []) > 1  # one chain per measured frame; ``robot`` is the first's
    for key in ("parameters", "effect_parameters"):
        for effect, values in (doc.get(key) or {}).items():
            if effect == "frames":  # the setup's (tracker frame, each measured frame's offset): named per campaign,
                continue            # unbounded; the schema holds them to finite numbers
            try:
                model = make_effect(effect, robot, **(options.get(effect) or {}))
            except (TypeError, ValueError) as exc:
                raise InputError(f"{source}: $.effect_options.{effect}: {exc}") from None
            names = model.parameter_names()
            physical = model.physical_range()
            low, high = model.fit_range()
            for name, value in values.items():
                if name not in names:
                    if several:  # a joint of another measured frame's chain: its range is that chain's
                        continue
                    raise InputError(f"{source}: $.{key}.{effect}: {name} is not a parameter of {effect} on "
                                     f"{robot.name} (a diagnosis of another robot, or with other options)")
                k = names.index(name)
                _within(value, low[k], high[k], model.parameter_units()[k], f"{source}: $.{key}.{effect}['{name}']")
                if key != "parameters":
                    continue
                interval = (doc.get("parameter_interval_95") or {}).get(effect, {}).get(name)
                for bound in (b for b in (interval or []) if b is not None):  # value +- 1.96 std, cut to the range
                    _within(bound, low[k], high[k], model.parameter_units()[k],
                            f"{source}: $.parameter_interval_95.{effect}['{name}']")
                stated = (doc.get("physical") or {}).get(effect) or {}
                for what, (lo, hi) in (("range", (physical[0][k], physical[1][k])), ("fit_range", (low[k], high[k]))):
                    said = (stated.get(what) or {}).get(name)
                    if said is not None and (_bound(said[0], -math.inf) != _bound(lo, -math.inf)
                                             or _bound(said[1], math.inf) != _bound(hi, math.inf)):
                        raise InputError(f"{source}: $.physical.{effect}.{what}['{name}']: {said} is not {effect}'s "
                                         f"{what.replace('_', ' ')} [{lo:g}, {hi:g}] on {robot.name}")
