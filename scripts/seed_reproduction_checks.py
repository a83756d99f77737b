#!/usr/bin/env python3
"""Numbers behind docs/seed-reproduction.md: which inputs could give the seed's outputs.

Run from the repository root:

    PYTHONPATH=src python scripts/seed_reproduction_checks.py

Prints, for the built-in tool-changer at the seed's working pose:
1. the nominal TCP and whether any joint values of our model reach the seed's point;
2. the first-order split of the Table 2 output spreads between link lengths and
   drives, and the factors on the inputs that would give the seed's Table 3 spreads;
3. whether the seed's Table 3 spreads and its Eq. (26) reliabilities fit together;
4. the clearance preset (Table 4) with and without its 0.087 rad deflection.
Monte Carlo runs use the same engine and seeds as the CLI (``montecarlo --seed 0``).
"""

import math

import numpy as np
from scipy import optimize, stats

from tcr_accuracy.model.clearance import ClearanceModel
from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.model.jacobians import error_jacobian
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.analysis.montecarlo import run_monte_carlo
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.analysis.tolerance import allocate_tolerance

SEED_TCP = np.array([-0.0924, 0.1609, -1.5119])  # [m], seed text after Table 2
SEED_STD = np.array([0.1389, 0.0822, 0.1414]) * 1e-3  # Table 3 std of dx, dy, dz [m]
SEED_MEAN = np.array([-4.71e-5, 1.59e-4, 2.54e-4]) * 1e-3
SEED_RELIABILITY = {0.15e-3: 0.7639, 0.25e-3: 0.9503}  # Eq. (26)
SEED_TABLE5_STD = np.array([0.4835, 0.2985, 0.3853]) * 1e-3
SEED_TABLE5_ANGLE_STD = np.array([2.1801e-4, 1.5260e-4, 6.9772e-5])  # phi, theta, psi [rad]


def mm(v):
    return np.array2string(np.asarray(v) * 1e3, precision=4, suppress_small=True)


def sci(v):
    return "[" + " ".join(f"{x:.3e}" for x in v) + "]"


def main() -> None:
    robot = load_robot()
    q = robot.working_pose
    p = tcp_poses(robot, q).position[0]
    shoulder = np.array([0.0, 0.0, 0.315 + 0.210])

    print("1. Nominal TCP at the working pose (15, 30, -10 deg, 0 mm, -20, 0 deg)")
    print(f"   ours [m]: {np.round(p, 4)}   seed [m]: {SEED_TCP}")
    print(f"   distance from the shoulder (j2 axis point (0, 0, l1 + l2)): ours {np.linalg.norm(p - shoulder):.4f} m, "
          f"seed {np.linalg.norm(SEED_TCP - shoulder):.4f} m; reach l3 + l4 + l5 + l6 = 1.761 m")
    print(f"   the pose with angles read as radians: {np.round(tcp_poses(robot, np.array([15, 30, -10, 0, -20, 0.0])).position[0], 4)}")

    def miss(a, free_j4):
        qq = np.array([a[0], a[1], a[2], a[4] if free_j4 else 0.0, a[3], 0.0])
        return tcp_poses(robot, qq).position[0] - SEED_TCP

    lo, hi = robot.lower_limits[[0, 1, 2, 4, 3]], robot.upper_limits[[0, 1, 2, 4, 3]]  # within the joint limits
    fit0 = optimize.least_squares(lambda a: miss(a, False), q[[0, 1, 2, 4]], bounds=(lo[:4], hi[:4]))
    fit1 = optimize.least_squares(lambda a: miss(a, True), np.r_[q[[0, 1, 2, 4]], 0.1], bounds=(lo, hi))
    print(f"   closest our arm gets to the seed's point with j4 = 0, within the joint limits: "
          f"{np.linalg.norm(fit0.fun) * 1e3:.1f} mm away")
    print(f"   with the telescope free: {np.linalg.norm(fit1.fun) * 1e3:.3g} mm away at j1..j3, j5 = "
          f"{np.round(np.degrees(fit1.x[:4]), 2)} deg, j4 = {fit1.x[4] * 1e3:.1f} mm")

    print("\n2. Table 2 inputs -> Table 3 outputs (first order, checked by Monte Carlo)")
    budget = seed_budget(robot, "table2")
    jac = error_jacobian(robot, q, budget.error_model)[:3]

    def var(pred):
        return sum((jac @ s.direction) ** 2 * s.variance for s in budget.sources if pred(s))

    v_link = var(lambda s: s.group == "link_length")
    v_rev = var(lambda s: s.group == "drive" and s.unit == "rad")
    v_pri = var(lambda s: s.group == "drive" and s.unit == "m")
    print(f"   std [mm] of dx, dy, dz from: link lengths {mm(np.sqrt(v_link))}, revolute drives {mm(np.sqrt(v_rev))}, "
          f"telescope drive {mm(np.sqrt(v_pri))}; seed Table 3 {mm(SEED_STD)}")
    need = (SEED_STD**2 - v_link - v_pri) / v_rev
    print(f"   factor on the revolute drive spreads to reach the seed's std, per axis: "
          f"{np.round(np.sqrt(np.maximum(need, 0)), 5)} (0 = the link lengths alone already exceed it)")
    ratio = SEED_STD / np.sqrt(v_link + v_rev + v_pri)
    f_all = float(np.exp(np.mean(np.log(ratio))))
    print(f"   one factor on every spread, per axis: {np.round(ratio, 5)}; best single factor {f_all:.5f}")
    for label, f in (("arc-minutes", 1 / 60), ("milliradians", 1e-3 / math.radians(1)), ("arc-seconds", 1 / 3600)):
        print(f"   drive spreads read as {label} (x {f:.4g}): std [mm] {mm(np.sqrt(v_link + v_pri + f**2 * v_rev))}")
    res = run_monte_carlo(budget.scaled(f_all), q, 200_000, 1)
    print(f"   Monte Carlo, every spread x {f_all:.5f}: std [mm] {mm(res.stats.std[:3])}, "
          f"P(|dP| < 0.15, 0.25 mm) = {np.round(res.position_reliability, 4)}")
    for tol, prob in SEED_RELIABILITY.items():
        a = allocate_tolerance(budget, q, tol, prob, n_samples=200_000, rng=np.random.default_rng(1))
        r = run_monte_carlo(budget.scaled(a.factor), q, 200_000, 1)
        print(f"   factor giving P(|dP| < {tol * 1e3:g} mm) = {prob}: {a.factor:.5f} -> std [mm] {mm(r.stats.std[:3])}, "
              f"P = {np.round(r.position_reliability, 4)}")

    print("\n3. Do the seed's Table 3 and Eq. (26) fit together?")
    rng = np.random.default_rng(0)
    cov = jac @ budget.parameter_covariance() @ jac.T
    corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    for label, c in (("independent axes", np.eye(3)), ("our correlations", corr)):
        z = rng.standard_normal((2_000_000, 3)) @ np.linalg.cholesky(c * np.outer(SEED_STD, SEED_STD)).T + SEED_MEAN
        n = np.linalg.norm(z, axis=1)
        print(f"   normal dx, dy, dz with Table 3's std ({label}): P(|dP| < 0.15 mm) = {(n < 0.15e-3).mean():.4f}, "
              f"P(|dP| < 0.25 mm) = {(n < 0.25e-3).mean():.4f}, mean |dP| = {n.mean() * 1e3:.4f} mm")
    for tol, prob in SEED_RELIABILITY.items():
        print(f"   P = {prob} at T = {tol * 1e3:g} mm means: one normal axis of std "
              f"{tol / stats.norm.ppf(0.5 + prob / 2) * 1e3:.4f} mm, or an isotropic 3D normal of std "
              f"{tol / math.sqrt(stats.chi2.ppf(prob, 3)) * 1e3:.4f} mm per axis")

    print("\n4. Clearance (Table 4 -> Table 5)")
    cm = ClearanceModel.from_robot(robot)
    for label, model in (("Table 4 as printed (w 0.087 rad)", cm),
                         ("deflection 0.087 mrad", cm.with_spreads(deflection_std=0.087e-3)),
                         ("no deflection", cm.with_spreads(deflection_std=0.0))):
        r = run_monte_carlo(model, q, 200_000, 0)
        print(f"   {label:34s} mean [mm] {mm(r.stats.mean[:3])} std [mm] {mm(r.stats.std[:3])} "
              f"angle std [rad] {sci(r.stats.std[4:7])}")
    print(f"   {'seed Table 5':34s} mean [mm] [1.0033 0.0005 -0.0009] std [mm] {mm(SEED_TABLE5_STD)} "
          f"angle std [rad] {sci(SEED_TABLE5_ANGLE_STD)}")


if __name__ == "__main__":
    main()
