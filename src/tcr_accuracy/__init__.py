"""tcr-accuracy: motion accuracy of serial robots, built on Pinocchio.

One folder per layer, each importing only from the layers before it (the README's
"Architecture" section draws them): ``model`` (robot, URDF, error model, kinematics, gravity)
-> ``io`` (measurement CSV) -> ``effects`` (the effect library) -> ``analysis`` (Monte Carlo,
sensitivity, simulation, sampling) -> ``diagnosis`` -> ``prediction`` (predictors,
compensation) -> ``asbuilt`` (the calibrated robot and its forms) -> ``iso9283`` (the standard's
pose and path tests) -> ``view`` (reports, plots,
meshcat) -> ``cli``.

The names most scripts need are importable from here; they load on first use, so
``import tcr_accuracy`` stays light::

    import numpy as np
    import tcr_accuracy as tcr

    robot = tcr.load_robot("ur5")
    poses = tcr.tcp_poses(robot, np.zeros(robot.n_joints))
"""

__version__ = "0.1.0"

#: public name -> module that defines it (loaded on first access, PEP 562)
_EXPORTS = {
    "load_robot": "model.robot", "RobotModel": "model.robot",
    "ErrorModel": "model.errors", "ErrorBudget": "model.errors", "seed_budget": "model.errors",
    "tcp_poses": "model.kinematics", "pose_error": "model.kinematics",
    "error_jacobian": "model.jacobians", "error_jacobians": "model.jacobians",
    "gravity_torque": "model.gravity", "as_built_urdf": "asbuilt.urdf",
    "MeasurementSet": "io.measurements", "read_measurements": "io.measurements",
    "write_measurements": "cli.writers",
    "make_effect": "effects", "vocabulary": "effects", "Effect": "effects",
    "run_monte_carlo": "analysis.montecarlo", "simulate_measurements": "analysis.simulate",
    "random_scenario": "analysis.simulate", "load_scenario": "analysis.scenario",
    "diagnose": "diagnosis.diagnose", "GapDiagnosis": "diagnosis.diagnose", "Diagnosis": "diagnosis.result",
    "Comparison": "diagnosis.compare", "compare_models": "diagnosis.compare", "IsoTestResult": "iso9283.result_file",
    "IsoCondition": "iso9283.result_file", "ExportResult": "asbuilt.export_result", "read_result": "results.types",
    "NotStoredError": "exceptions",
    "make_predictor": "prediction.methods", "MeasuredErrorModel": "prediction.composed",
    "compensate_joints": "prediction.compensation", "predict_errors": "prediction.error_prediction",
    "ErrorPrediction": "prediction.error_prediction", "held_out_error": "prediction.held_out",
    "HeldOutError": "prediction.held_out", "compensate_targets": "prediction.target_compensation",
    "TargetCompensation": "prediction.target_compensation", "register_tracker": "frames.registration",
    "load_as_built": "asbuilt.model_file", "AsBuiltModel": "asbuilt.model",
    "build_export": "asbuilt.export", "refit_geometry": "asbuilt.refit", "dh_table": "asbuilt.dh",
    "mdh_table": "asbuilt.dh", "filter_joint_targets": "asbuilt.compensation_filter",
    "filter_pose_targets": "asbuilt.compensation_filter", "filter_program": "asbuilt.programs",
    "with_factory_kinematics": "asbuilt.factory_kinematics",
    "plan_iso_cube": "iso9283.plan", "evaluate_pose_test": "iso9283.evaluate",
    "plan_path_test": "iso9283.path_plan", "evaluate_path_test": "iso9283.path_evaluate",
    "IsoPlan": "iso9283.plan", "cycle_order": "iso9283.plan", "evaluate_conditions": "iso9283.evaluate",
    "IsoEvaluation": "iso9283.evaluate",
    "read_tracker_stream": "io.tracker_stream",
    "Scene": "view.viewer", "diagnosis_summary": "view.diagnosis_summary",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'tcr_accuracy' has no attribute {name!r}")
    from importlib import import_module

    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
