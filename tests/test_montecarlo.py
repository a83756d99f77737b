"""Monte Carlo engine: chunk merging, seeding contract, exactness of the fast chain
engine against the Pinocchio loop, first-order agreement, Dask == single process."""

import json

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from tcr_accuracy.cli import main
from tcr_accuracy.model.clearance import ClearanceModel
from tcr_accuracy.model.errors import ErrorModel, seed_budget
from tcr_accuracy.model.kinematics import tcp_chain_soa, tcp_poses_pinocchio
from tcr_accuracy.analysis.montecarlo import STAT_COLUMNS, chunk_plan, run_monte_carlo, sample_rows
from tcr_accuracy.analysis.reliability import first_order
from tcr_accuracy.random_state import fill_standard_normal


class ToolShiftSampler:
    """Hidden truth for the test: only tool.dx moves, by N(mu, sigma) [m].

    A translation on the TCP frame moves the TCP by R_tcp @ (v, 0, 0) exactly, so
    the position errors are the values times the TCP's x axis, and the attitude
    does not change.
    """

    name = "tool shift"

    def __init__(self, error_model, mu, sigma):
        self.error_model, self.mu, self.sigma = error_model, mu, sigma

    def sample(self, n, rng):
        x = np.zeros((n, self.error_model.size))
        x[:, self.error_model.index("tool.dx")] = self.mu + self.sigma * rng.standard_normal(n)
        return x


def test_chunked_statistics_equal_those_of_the_regenerated_samples(tool_changer):
    em = ErrorModel(tool_changer)
    q = tool_changer.working_pose
    sampler = ToolShiftSampler(em, 2e-4, 1e-4)
    n, chunk = 25_000, 4_000
    result = run_monte_carlo(sampler, q, n, 11, chunk=chunk, position_tolerances=(2e-4, 3e-4))
    # regenerate the values from the documented seeding contract, independently of the engine
    children = np.random.SeedSequence(11).spawn(len(chunk_plan(n, chunk)))
    values = np.concatenate([2e-4 + 1e-4 * np.random.default_rng(c).standard_normal(size)
                             for c, size in zip(children, chunk_plan(n, chunk))])
    axis = tcp_poses_pinocchio(tool_changer, q).rotation[0][:, 0]
    expected = values[:, None] * axis[None, :]
    stats = result.stats
    np.testing.assert_allclose(stats.mean[:3], expected.mean(axis=0), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(stats.std[:3], expected.std(axis=0, ddof=1), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(stats.maximum[:3], expected.max(axis=0), atol=1e-14)
    np.testing.assert_allclose(stats.minimum[:3], expected.min(axis=0), atol=1e-14)
    norm = np.abs(values)
    assert stats.mean[STAT_COLUMNS.index("norm")] == pytest.approx(norm.mean(), rel=1e-9)
    np.testing.assert_array_equal(result.inside_position, [(norm < 2e-4).sum(), (norm < 3e-4).sum()])
    np.testing.assert_allclose(stats.std[4:7], 0.0, atol=1e-12)  # attitude untouched
    assert result.n_samples == n and result.cloud.shape == (20_000, 3)
    np.testing.assert_allclose(result.cloud, expected[:20_000], atol=1e-15)


def test_same_seed_same_result_other_seed_other_result(tool_changer):
    budget = seed_budget(tool_changer, "table2")
    q = tool_changer.working_pose
    a = run_monte_carlo(budget, q, 12_000, 5, chunk=5_000)
    b = run_monte_carlo(budget, q, 12_000, 5, chunk=5_000)
    c = run_monte_carlo(budget, q, 12_000, 6, chunk=5_000)
    np.testing.assert_array_equal(a.stats.mean, b.stats.mean)
    np.testing.assert_array_equal(a.stats.std, b.stats.std)
    assert not np.allclose(a.stats.mean, c.stats.mean, rtol=0, atol=0)


@pytest.mark.parametrize("preset", ["table1", "table2", "clearance"])
def test_fast_engine_matches_the_pinocchio_loop_on_the_same_samples(tool_changer, preset):
    sampler = ClearanceModel.from_robot(tool_changer) if preset == "clearance" else seed_budget(tool_changer, preset)
    em = sampler.error_model
    rows = sample_rows(sampler, 300, np.random.default_rng(2))
    x = np.stack([np.broadcast_to(r, (300,)) for r in rows], axis=1)
    rot, pos = tcp_chain_soa(tool_changer, tool_changer.working_pose, rows, em)
    loop = tcp_poses_pinocchio(tool_changer, tool_changer.working_pose, x, em)
    np.testing.assert_allclose(pos.T, loop.position, atol=1e-12)
    np.testing.assert_allclose(rot.T.reshape(-1, 3, 3), loop.rotation, atol=1e-12)


def test_sample_rows_follow_the_budget_distributions(tool_changer):
    """Row variances against the budget's own covariance (an independent formula)."""
    budget = seed_budget(tool_changer, "table1")
    rows = sample_rows(budget, 200_000, np.random.default_rng(0))
    x = np.stack([np.broadcast_to(r, (200_000,)) for r in rows], axis=1)
    cov = budget.parameter_covariance()
    active = np.diag(cov) > 0
    np.testing.assert_allclose(x[:, active].var(axis=0), np.diag(cov)[active], rtol=0.02)
    np.testing.assert_array_equal(x[:, ~active], 0.0)


def test_monte_carlo_std_matches_first_order_for_small_errors(tool_changer):
    budget = seed_budget(tool_changer, "table1").scaled(0.01)
    q = tool_changer.working_pose
    result = run_monte_carlo(budget, q, 100_000, 3)
    fo = first_order(budget, q)
    # 100k samples: the std of a std estimate is ~0.22 %
    np.testing.assert_allclose(result.stats.std[:3], fo.position_std, rtol=0.015)
    np.testing.assert_allclose(result.stats.std[4:7], fo.euler_std, rtol=0.015)


def _cli_json(tmp_path, name, extra):
    out = tmp_path / name
    code = main(["montecarlo", "--samples", "24000", "--chunk", "5000", "--seed", "3", "--quiet",
                 "--tail-samples", "0", "--json", str(out)] + extra)
    assert code == 0
    return json.loads(out.read_text())


def test_dask_local_cluster_gives_identical_statistics(tmp_path):
    single = _cli_json(tmp_path, "single.json", [])
    cluster = _cli_json(tmp_path, "cluster.json", ["--workers", "2"])
    assert cluster["stats_mm"] == single["stats_mm"]
    assert cluster["stats_rad"] == single["stats_rad"]
    assert cluster["reliability_position"] == single["reliability_position"]
    assert cluster["reliability_angle"] == single["reliability_angle"]


def _loop_error_columns(robot, q, x, em):
    """dx, dy, dz, |dP|, the ZYX angle errors and |P| - |P0| by the plain per-sample Pinocchio
    loop, with the Euler angles from scipy (not the package's own conversion)."""
    nominal = tcp_poses_pinocchio(robot, q)
    actual = tcp_poses_pinocchio(robot, q, x, em)
    dpos = actual.position - nominal.position[0]
    euler = Rotation.from_matrix(actual.rotation).as_euler("ZYX")
    d_euler = euler - Rotation.from_matrix(nominal.rotation).as_euler("ZYX")[0]
    d_euler = (d_euler + np.pi) % (2 * np.pi) - np.pi
    radial = np.linalg.norm(actual.position, axis=1) - np.linalg.norm(nominal.position[0])
    return np.column_stack([dpos, np.linalg.norm(dpos, axis=1), d_euler, radial])


@pytest.mark.parametrize("robot_name,preset,pose", [("tool_changer", "table2", None),
                                                    ("ur5", "table1", [0.3, -1.2, 1.4, -0.6, 1.1, 0.4])])
def test_whole_pipeline_agrees_with_the_per_sample_pinocchio_loop_to_1e9_m(robot_name, preset, pose, request):
    """run_monte_carlo (float32 angles in the normal draws, pooled scratch arrays over three
    chunks of two sizes) against one perturbed Pinocchio model per sample: the kept cloud
    sample by sample, every statistic, and the counts inside the tolerances."""
    robot = request.getfixturevalue(robot_name)
    budget = seed_budget(robot, preset)
    em = budget.error_model
    q = robot.working_pose if pose is None else np.array(pose)
    n, chunk, seed = 2_500, 1_000, 7
    # the samples, regenerated from the documented seeding contract
    children = np.random.SeedSequence(seed).spawn(len(chunk_plan(n, chunk)))
    x = np.concatenate([np.stack([np.broadcast_to(r, (size,)) for r in
                                  sample_rows(budget, size, np.random.default_rng(child))], axis=1)
                        for child, size in zip(children, chunk_plan(n, chunk))])
    loop = _loop_error_columns(robot, q, x, em)
    tolerances = np.quantile(loop[:, 3], [0.3, 0.7])  # informative counts, away from 0 and n
    angle_tolerance = float(np.median(np.abs(loop[:, 4:7])))
    result = run_monte_carlo(budget, q, n, seed, chunk=chunk, keep_cloud=n, position_tolerances=tolerances,
                             angle_tolerance=angle_tolerance)
    assert np.abs(result.cloud - loop[:, :3]).max() < 1e-9  # [m], every sample
    s = result.stats
    for got, expected in ((s.mean, loop.mean(axis=0)), (s.std, loop.std(axis=0, ddof=1)),
                          (s.minimum, loop.min(axis=0)), (s.maximum, loop.max(axis=0))):
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)  # [m] and [rad]
    near = [int(np.sum(np.abs(loop[:, 3] - t) < 1e-9)) for t in tolerances]  # ties the 1e-9 may flip
    expected_inside = [int(np.sum(loop[:, 3] < t)) for t in tolerances]
    assert all(abs(int(got) - e) <= k for got, e, k in zip(result.inside_position, expected_inside, near))
    np.testing.assert_array_equal(result.inside_angle, (np.abs(loop[:, 4:7]) < angle_tolerance).sum(axis=0))


def test_box_muller_normals_are_standard_normal_and_reproducible():
    """fill_standard_normal against scipy's normal law: Kolmogorov-Smirnov, tail counts
    within binomial bounds, the cos/sin partners of a pair uncorrelated."""
    n = 400_001  # odd: the last cosine has no sine partner
    z = fill_standard_normal(np.random.default_rng(5), np.empty(n))
    assert stats.kstest(z, "norm").pvalue > 1e-3
    for k in (1.0, 2.0, 3.0):
        p = 2 * stats.norm.sf(k)
        assert abs(np.mean(np.abs(z) > k) - p) < 5 * np.sqrt(p * (1 - p) / n)
    half = (n + 1) // 2
    assert abs(np.corrcoef(z[:n - half], z[half:])[0, 1]) < 5 / np.sqrt(n - half)
    np.testing.assert_array_equal(z, fill_standard_normal(np.random.default_rng(5), np.empty(n)))
