"""Options by name only (``iso9283/``, ``effects/``, ``frames/``): every effect's constructor takes its
options as keyword-only parameters (the scikit-learn convention the project's style asks of
estimators), and the ISO 9283, registration and prediction functions take their settings so, after
the data they work on, which may be named. A mutation run reads the ``*`` of a signature as an
operator: turned to ``/`` it makes the data positional-only and the settings positional, which no
figure shows; this test does (issue 36). Each entry was seen failing on its ``*`` turned to ``/``.
"""

import importlib
import inspect

import pytest

#: (module under tcr_accuracy, callable, parameters that may be given by position or by name,
#: keyword-only parameters)
SIGNATURES = [
    ("effects.angle_table", "AngleTable.__init__", ("self", "robot"), ("intervals", "lower", "upper", "knots")),
    ("effects.backlash", "Backlash.__init__", ("self", "robot"), ("link_mass_factors",)),
    ("effects.base", "effect_classes", (), ("vocabulary_only",)),
    ("effects.base", "effect_class", ("name",), ("vocabulary_only", "source")),
    ("effects.clearance", "Clearance.__init__", ("self", "robot"), ("joints", "rng")),
    ("effects.compliance", "Compliance.__init__", ("self", "robot"), ("link_mass_factors",)),
    ("effects.compose", "prediction_jacobian", ("robot", "effects", "params_list", "q", "context"), ("orientation",)),
    ("effects.cyclic", "CyclicError.__init__", ("self", "robot"), ("max_order",)),
    ("effects.drift", "Drift.__init__", ("self", "robot"), ("time_axis", "start", "span", "time_constant")),
    ("effects.frames", "Frames.__init__", ("self", "robot"),
     ("tool_rotation", "sessions", "session_frames", "session_tools")),
    ("effects.geometry", "Geometry.__init__", ("self", "robot"), ("components",)),
    ("effects.lateral_compliance", "LateralCompliance.__init__", ("self", "robot"), ("link_mass_factors",)),
    ("effects.thermal", "Thermal.__init__", ("self", "robot"), ("per_link", "reference_temperature_c")),
    ("effects.transmission", "Transmission.__init__", ("self", "robot"), ("harmonics",)),
    ("frames.registration", "register_tracker", ("robot", "q", "measured"),
     ("context", "fit_base", "fit_tool", "max_nfev")),
    ("iso9283.evaluate", "evaluate_pose_test", ("robot", "mset"), ("frame", "registration", "registration_source", "band")),
    ("iso9283.evaluate", "evaluate_conditions", ("robot", "mset"),
     ("frame", "registration", "registration_source", "band")),
    ("iso9283.formulas", "pose_figures", ("positions", "commanded", "deviations"), ("pose_id", "approach")),
    ("iso9283.formulas", "distance_figures", ("a_positions", "b_positions", "a_commanded", "b_commanded"),
     ("pose_a", "pose_b", "approach")),
    ("iso9283.formulas", "iso_figures", ("pose_id", "positions", "commanded"), ("deviations", "cycle", "approach")),
    ("iso9283.path", "path_figures", ("points", "s", "cycles"), ("planes", "corners", "commanded_times", "speed")),
    ("iso9283.path_evaluate", "evaluate_path_test", ("robot", "commanded", "stream"),
     ("frame", "registration", "registration_source", "planes", "model", "registration_after")),
    ("iso9283.path_plan", "plan_path_test", ("robot", "random_state"),
     ("centre", "size", "home", "tool_rotation", "tracker", "workspace", "rated_speed")),
    ("iso9283.plan", "plan_iso_cube", ("robot", "random_state"),
     ("centre", "size", "home", "tool_rotation", "tracker", "workspace", "n_samples", "n_centres", "bisections")),
    ("iso9283.plan", "_plan", ("reach", "centre", "size", "solved"), ("searched", "n_centres")),
    ("iso9283.plan", "IsoPlan.series", ("self", "cycles", "conditions"), ("rated_load_kg",)),
]


@pytest.mark.parametrize("module, name, by_position, by_name_only", SIGNATURES,
                         ids=[f"{m}.{n}" for m, n, _, _ in SIGNATURES])
def test_settings_are_keyword_only_and_the_data_before_them_may_be_named(module, name, by_position, by_name_only):
    """The parameters before the ``*`` are positional-or-keyword, those after it keyword-only, in order."""
    target = importlib.import_module(f"tcr_accuracy.{module}")
    for part in name.split("."):
        target = getattr(target, part)
    kinds = {p.name: p.kind for p in inspect.signature(target).parameters.values()
             if p.kind is not inspect.Parameter.VAR_KEYWORD}
    assert list(kinds) == list(by_position) + list(by_name_only)
    assert all(kinds[p] is inspect.Parameter.POSITIONAL_OR_KEYWORD for p in by_position)
    assert all(kinds[p] is inspect.Parameter.KEYWORD_ONLY for p in by_name_only)
