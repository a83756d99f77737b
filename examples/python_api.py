#!/usr/bin/env python3
"""tcr-accuracy from Python, top to bottom: the robot, its accuracy by design, a diagnosis of
measurements, and the prediction and compensation of what is left.

    python examples/python_api.py          # about 30 s; tests/test_python_api.py runs it

Every name used comes from the package root (``import tcr_accuracy as tcr``); SI units
throughout (m, rad); the printed lines convert to mm and deg.
"""

from pathlib import Path

import numpy as np

import tcr_accuracy as tcr

# %% The robot: the built-in tool-changer ("ur5", "panda", ... or a URDF path work the same)
robot = tcr.load_robot()
q0 = robot.working_pose                                    # (n_joints,) [rad, m]
pose = tcr.tcp_poses(robot, q0)
print(f"{robot.name}: {robot.n_joints} joints {robot.joint_names}, TCP '{robot.tool_frame}'")
print("TCP at the working pose [mm]:", np.round(pose.position[0] * 1e3, 2))

# %% Accuracy by design: Monte Carlo of the seed's Table 2 tolerances at the working pose
budget = tcr.seed_budget(robot, "table2")
mc = tcr.run_monte_carlo(budget, q0, 5_000, random_state=0, position_tolerances=[0.25e-3])
print(f"P(|dP| < 0.25 mm) = {mc.inside_position[0] / mc.n_samples:.4f} over {mc.n_samples} samples")

# %% Measurements of the as-built robot: simulated here from an example scenario;
# a real robot's come from tcr.read_measurements("measured.csv", robot)
scenario = tcr.load_scenario(Path(__file__).with_name("scenario_compliance.yaml"))
measured, truth = tcr.simulate_measurements(robot, scenario, 200, random_state=1)
print(f"{len(measured.q)} measurements, hidden effects: {', '.join(truth['effects'])}")

# %% Diagnosis: which effects explain the gap, judged on held-out measurements. A scikit-learn
# estimator (get_params, clone); tcr.diagnose(robot, measured) is the same in one call, and
# print(tcr.diagnosis_summary(diagnosis)) prints what `tcr-accuracy diagnose` does
diagnosis = tcr.GapDiagnosis(robot=robot, folds=5, random_state=0).fit(measured).result_
final = diagnosis.steps[-1]
print(f"primary effect: {diagnosis.primary_effect}; selected: {', '.join(diagnosis.selected_effects)}")
print(f"held-out RMS {final.heldout.rms * 1e3:.4f} mm, noise floor {diagnosis.noise_floor * 1e3:.4f} mm")

# %% Prediction: the tracker frame is fitted first, then the diagnosis' effect model plus a
# Gaussian process on what it leaves; each row's payload, temperature and approach direction
# (its context) reach the effects that use them
train, test = measured.subset(np.arange(160)), measured.subset(np.arange(160, 200))
model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("diagnosis+gp", robot, random_state=0))
model.fit(train.q, train.position, context=train.context)
miss = np.linalg.norm(model.heldout_residual(test.q, test.position, context=test.context), axis=1)
print(f"predicted error vs measured at {len(test.q)} held-out poses: mean miss {miss.mean() * 1e3:.4f} mm")

# %% Compensation: joint commands whose predicted real measured point lands where the model (the
# nominal robot with the fitted TCP offset, frame_robot_) puts it at the target joints
result = tcr.compensate_joints(model.frame_robot_, model.estimator_, test.q, context=test.context)
print(f"compensated {int(result.converged.sum())}/{len(result.converged)} targets, "
      f"largest predicted miss {result.predicted_miss.max() * 1e3:.6f} mm")
