"""One way to pass randomness: a ``random_state`` argument (scikit-learn's name, SPEC 7's values).

Every public function and estimator that draws random numbers takes ``random_state``: an int
(reproducible), a :class:`numpy.random.Generator` (drawn from, so a caller can thread one
stream through several calls) or None (fresh entropy from the operating system).
:func:`numpy.random.default_rng` turns any of them into a Generator; :func:`int_seed` gives
the integer the code seeds child streams and scikit-learn's ``random_state`` with.

Until release 0.2 the keywords these arguments had before (``seed``, ``rng``) still work and
raise a :class:`DeprecationWarning` (:func:`renamed_keyword`).

:func:`fill_standard_normal` draws normal values from a Generator's uniforms faster than its
own ``standard_normal`` (the Monte Carlo sampler's stream).
"""

from __future__ import annotations

import functools
import warnings

import numpy as np

#: the release after which the old keywords are gone
REMOVED_IN = "0.2"


def int_seed(random_state) -> int:
    """An int seed from an int (itself), a Generator (one draw from it) or None (fresh entropy).

    Parameters
    ----------
    random_state : int, numpy.random.Generator or None
        The caller's ``random_state``.

    Returns
    -------
    int
        A non-negative integer below 2**63.
    """
    if isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool):
        return int(random_state)
    if random_state is None:
        return int(np.random.SeedSequence().generate_state(2, np.uint64)[0] >> np.uint64(1))
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(2**63 - 1))
    raise TypeError(f"random_state must be an int, a numpy.random.Generator or None, got {type(random_state).__name__}")


def renamed_keyword(old: str, new: str):
    """Decorator: the keyword ``old`` is still accepted for ``new``, with a DeprecationWarning.

    Parameters
    ----------
    old : str
        The keyword the function had before.
    new : str
        Its name now.

    Returns
    -------
    callable
        The decorator.
    """
    def decorate(function):
        name = function.__qualname__.removesuffix(".__init__")  # a class is called by its name

        @functools.wraps(function)
        def wrapper(*args, **kwargs):
            if old in kwargs:
                if new in kwargs:
                    raise TypeError(f"{name}() got both {old!r} (deprecated) and {new!r}")
                warnings.warn(f"{name}({old}=...) is deprecated and will be removed in {REMOVED_IN}; "
                              f"use {new}=...", DeprecationWarning, stacklevel=2)
                kwargs[new] = kwargs.pop(old)
            return function(*args, **kwargs)

        return wrapper

    return decorate


def fill_standard_normal(rng: np.random.Generator, out: np.ndarray, work: np.ndarray | None = None) -> np.ndarray:
    """Fill ``out`` with independent standard normal draws from ``rng`` (Box-Muller), in place.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the uniform draws: ``ceil(n / 2)`` float64, then as many float32.
    out : ndarray of float64, C-contiguous, any shape (n values)
        Filled and returned.
    work : ndarray of float32 and shape (2, ceil(n / 2)), optional
        Room for the angles and their sines (allocated when omitted).

    Returns
    -------
    ndarray
        ``out``.

    Notes
    -----
    Each pair of draws is ``r (cos t, sin t)`` with ``r = sqrt(-2 ln(1 - u))``, u a float64
    uniform on [0, 1) (53 bits: draws reach 8.57 standard deviations), and t = 2 pi v, v a
    float32 uniform on [0, 1) (24 bits). The first half of ``out`` gets the cosines, the
    second half the sines. Written out because numpy's ``Generator.standard_normal`` runs
    its ziggurat one value at a time (about 8 ns a draw on the reference machine, half of
    a Monte Carlo sample's budget), while this runs on numpy's vectorised log, sqrt and
    float32 sin and cos (about 3 ns). The angle alone is float32: it rounds each draw by
    about 6e-8 relative and takes 2^24 values, which moves the probability of an interval
    of draws by about 1e-7 at most, far below the sampling noise of any run that fits in
    memory (1e-5 for 1e10 draws).
    """
    if out.dtype != np.float64 or not out.flags.c_contiguous:
        raise TypeError("fill_standard_normal needs a C-contiguous float64 array")
    flat = out.reshape(-1)
    half = (flat.size + 1) // 2
    rest = flat.size - half
    radius = flat[:half]
    rng.random(out=radius)
    np.subtract(1.0, radius, out=radius)  # (0, 1]: the log stays finite
    np.log(radius, out=radius)
    radius *= -2.0
    np.sqrt(radius, out=radius)
    if work is None:
        work = np.empty((2, half), np.float32)
    angle, trig = work[0], work[1, :rest]
    rng.random(out=angle, dtype=np.float32)
    angle *= np.float32(2.0 * np.pi)
    np.sin(angle[:rest], out=trig)
    np.multiply(radius[:rest], trig, out=flat[half:])
    np.cos(angle, out=angle)
    radius *= angle
    return out
