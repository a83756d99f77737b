"""Monte Carlo engine: chunk merging, seeding contract, exactness of the fast chain
engine against the Pinocchio loop, first-order agreement, Dask == single process."""

import json

import numpy as np
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.model.clearance import ClearanceModel
from tcr_accuracy.model.errors import ErrorModel, seed_budget
from tcr_accuracy.model.kinematics import tcp_chain_soa, tcp_poses_pinocchio
from tcr_accuracy.analysis.montecarlo import STAT_COLUMNS, chunk_plan, run_monte_carlo, sample_rows
from tcr_accuracy.analysis.reliability import first_order


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
