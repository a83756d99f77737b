"""Values as JSON holds them: the one conversion every result's JSON form goes through.

A result's ``to_dict`` gives plain Python values (dict, list, str, int, float, bool, None) that
:func:`json.dumps` writes with ``allow_nan=False``: numpy scalars and arrays become Python
numbers and lists, tuples lists, keys text, and a non-finite number None (JSON has no
infinity; a range unbounded on one side is written ``[null, 0.1]``). The readers take a None
bound back as infinite.
"""

from __future__ import annotations

import json
import math

import numpy as np


def plain(value):
    """``value`` with numpy types, tuples and non-finite floats made plain JSON values.

    Parameters
    ----------
    value : object
        Nested dicts, lists, tuples, numpy arrays and scalars, numbers, strings, None.

    Returns
    -------
    object
        The same structure of dict, list, str, int, float (finite), bool and None.

    Examples
    --------
    >>> import numpy as np
    >>> plain({"range": (float("-inf"), np.float64(0.5)), 3: np.arange(2)})
    {'range': [None, 0.5], '3': [0, 1]}
    """
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def dumps(value, indent: int | None = 2) -> str:
    """JSON text of :func:`plain` ``(value)`` (indented by ``indent``; no NaN or infinity).

    Parameters
    ----------
    value : object
        See :func:`plain`.
    indent : int or None, default=2
        As :func:`json.dumps` takes it.

    Returns
    -------
    str
        The JSON text, ending in a newline.
    """
    return json.dumps(plain(value), indent=indent, allow_nan=False) + "\n"


def finite_or(value, infinite: float) -> float:
    """A number of a JSON form back in SI: None (an unbounded side) as ``infinite``.

    Parameters
    ----------
    value : float or None
    infinite : float
        What None stands for (``math.inf`` or ``-math.inf``).

    Returns
    -------
    float
    """
    return infinite if value is None else float(value)


class JsonForm:
    """A result with a JSON form (its ``to_dict``): :meth:`to_json` writes it as valid JSON, the
    same text for every kind of result (Diagnosis, IsoTestResult, Comparison, ExportResult)."""

    def to_json(self, indent: int | None = 2) -> str:
        """The JSON text of ``to_dict()`` (plain values, no NaN or infinity: valid JSON).

        Parameters
        ----------
        indent : int or None, default=2

        Returns
        -------
        str
            The JSON text, ending in a newline.
        """
        return dumps(self.to_dict(), indent)
