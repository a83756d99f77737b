"""Scratch arrays reused from one batch to the next, for loops over chunks of samples.

A chunk of Monte Carlo samples builds a few hundred temporary (N,) arrays. Taken fresh
from ``malloc`` each time, their memory goes back to the operating system between chunks
and every page is faulted in again: on the reference machine that cost twice the
arithmetic. A :class:`ScratchArrays` keeps the arrays and hands one out again as soon as
nothing refers to it any more (its reference count says so; views count, since they hold
their base), so a loop over chunks touches the same warm memory. The batched kinematics
(:mod:`tcr_accuracy.model.kinematics`) takes its temporaries from the pool made active by
:meth:`ScratchArrays.active`, and allocates as usual when none is.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

_ACTIVE: ContextVar["ScratchArrays | None"] = ContextVar("tcr_accuracy_scratch", default=None)


def _references(arrays: list, i: int) -> int:
    """sys.getrefcount of arrays[i], counted the same way for the pool's scan and its calibration."""
    array = arrays[i]
    return sys.getrefcount(array)


#: What _references reports for an array only the pool's list holds (3 on CPython 3.11: the
#: list, the local name and getrefcount's argument; measured, since interpreters differ)
_FREE_REFERENCES = _references([np.empty(0)], 0)


class ScratchArrays:
    """A pool of arrays by shape and dtype, each handed out again once nothing holds it.

    Examples
    --------
    >>> pool = ScratchArrays()
    >>> a = pool.take((4,))
    >>> a is pool.take((4,))  # a is still held
    False
    >>> address = a.ctypes.data
    >>> del a
    >>> pool.take((4,)).ctypes.data == address
    True
    """

    def __init__(self):
        self._arrays: dict[tuple, list[np.ndarray]] = {}
        self._next: dict[tuple, int] = {}

    def take(self, shape: tuple, dtype=np.float64) -> np.ndarray:
        """An array of ``shape`` and ``dtype`` that nothing else refers to (contents undefined)."""
        key = (shape, dtype)
        arrays = self._arrays.setdefault(key, [])
        count = len(arrays)
        start = self._next.get(key, 0)
        for k in range(count):
            i = start + k - count if start + k >= count else start + k
            if _references(arrays, i) == _FREE_REFERENCES:
                self._next[key] = i + 1
                return arrays[i]
        array = np.empty(shape, dtype)
        arrays.append(array)
        self._next[key] = 0
        return array

    @property
    def nbytes(self) -> int:
        """Memory held by the pool [bytes]."""
        return sum(a.nbytes for arrays in self._arrays.values() for a in arrays)

    @contextmanager
    def active(self):
        """Within the block, :func:`scratch` takes its arrays from this pool."""
        token = _ACTIVE.set(self)
        try:
            yield self
        finally:
            _ACTIVE.reset(token)


def scratch(shape: tuple, dtype=np.float64) -> np.ndarray | None:
    """An array of ``shape`` from the active pool, or None (numpy then allocates) without one."""
    pool = _ACTIVE.get()
    return None if pool is None else pool.take(shape, dtype)


def scratch_like(first, second=0.0) -> np.ndarray | None:
    """An output array for a float64 ufunc on one or two operands (floats or same-shape
    float64 arrays) from the active pool, or None."""
    pool = _ACTIVE.get()
    if pool is None:
        return None
    array, other = (first, second) if isinstance(first, np.ndarray) else (second, first)
    if not isinstance(array, np.ndarray) or array.dtype != np.float64:
        return None
    if isinstance(other, np.ndarray) and (other.shape != array.shape or other.dtype != np.float64):
        return None
    return pool.take(array.shape)
