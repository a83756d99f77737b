"""The scratch pool: an array is handed out again only when nothing refers to it, and
results computed in a pool stay intact while later batches reuse it."""

import numpy as np

from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.model.kinematics import tcp_chain_soa, tcp_poses_pinocchio
from tcr_accuracy.model.scratch import ScratchArrays, scratch


def test_an_array_is_reused_only_once_nothing_holds_it():
    pool = ScratchArrays()
    a = pool.take((5,))
    b = pool.take((5,))
    assert not np.shares_memory(a, b)
    view = a[1:3]
    address = a.ctypes.data
    del a
    assert pool.take((5,)).ctypes.data != address  # the view keeps its base busy
    del view
    assert pool.take((5,)).ctypes.data == address
    assert pool.take((2, 5), np.float32).dtype == np.float32
    assert scratch((5,)) is None  # no pool active: numpy allocates


def test_results_kept_from_one_batch_survive_the_next_batches(tool_changer):
    budget = seed_budget(tool_changer, "table2")
    em, q = budget.error_model, tool_changer.working_pose
    rng = np.random.default_rng(3)
    batches = [budget.sample(400, rng) for _ in range(3)]
    with ScratchArrays().active():
        kept = [tcp_chain_soa(tool_changer, q, np.ascontiguousarray(x.T), em) for x in batches]
    for (rot, pos), x in zip(kept, batches):
        loop = tcp_poses_pinocchio(tool_changer, q, x, em)
        assert np.abs(pos.T - loop.position).max() < 1e-12
        assert np.abs(rot.T.reshape(-1, 3, 3) - loop.rotation).max() < 1e-12
