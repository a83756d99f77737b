"""A joint-columns effect (cyclic errors, angle tables) turns its joints a chunk of poses at a time:
every chunk, the last one short, gets its own turn.

The turns are written out here from the effect's Fourier series (dq_j = sum_n a_n sin(n q_j) +
b_n cos(n q_j)), independent of the chunking."""

import numpy as np

from tcr_accuracy.effects.cyclic import CyclicError
from tcr_accuracy.model.context import MeasurementContext

from conftest import random_joint_values


def test_cyclic_turns_over_several_chunks_are_the_series_written_out(ur5):
    """11 poses in chunks of 4 (4 + 4 + 3). Seen failing on the chunk loop's ``range(0, q.shape[0],
    CHUNK)`` turned to ``q.shape[-1]`` (the 6 joints: the poses past the first chunk keep no turn) and on
    the chunk's slice ``start + CHUNK`` turned to ``start - CHUNK``."""
    rng = np.random.default_rng(11)
    q = random_joint_values(ur5, 11, rng)
    effect = CyclicError(ur5, max_order=4)
    effect.CHUNK = 4
    params = rng.normal(size=effect.n_params) * 1e-4
    coefficients = params.reshape(6, 2, 2)  # joint, order 3 / 4, sin / cos
    expected = np.zeros_like(q)
    for j in range(6):
        for i, n in enumerate((3, 4)):
            expected[:, j] += coefficients[j, i, 0] * np.sin(n * q[:, j]) + coefficients[j, i, 1] * np.cos(n * q[:, j])
    turned = effect.perturb(params, q, MeasurementContext.defaults(11, 6)).dq
    np.testing.assert_allclose(turned, expected, rtol=0, atol=1e-15)
