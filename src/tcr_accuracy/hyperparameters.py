"""Hyper-parameters of the package's estimators, checked when ``fit`` starts.

Each estimator declares ``_parameter_constraints`` in scikit-learn's vocabulary (``Interval``,
``StrOptions``, types, ``None``; ``sklearn.utils._param_validation``), as scikit-learn's own
estimators do, and calls :func:`validate_hyperparameters` first thing in ``fit``: a power of NaN,
a negative noise, a rank tolerance of 0 is refused there, in one line naming the parameter and
the value, instead of a fit that returns NaN or zeros. The error is an
:class:`~tcr_accuracy.exceptions.InputError` (the command line: exit 2) and scikit-learn's
``InvalidParameterError`` at once, so that scikit-learn's estimator checks read it as theirs.

Base layer: scikit-learn is imported when a check runs.
"""

from __future__ import annotations

import functools
import re

from .exceptions import InputError


@functools.lru_cache(maxsize=None)
def _error_class():
    from sklearn.utils._param_validation import InvalidParameterError

    class HyperparameterError(InputError, InvalidParameterError):
        """A hyper-parameter outside what its estimator declares."""

    return HyperparameterError


def validate_hyperparameters(estimator) -> None:
    """Check ``estimator``'s hyper-parameters against its ``_parameter_constraints``.

    Raises
    ------
    InputError
        (also scikit-learn's ``InvalidParameterError``) naming the parameter, the estimator and the value;
        ``parameter`` and ``value`` carry them.
    """
    from sklearn.utils._param_validation import InvalidParameterError

    try:
        estimator._validate_params()
    except InvalidParameterError as exc:
        message = " ".join(str(exc).split())
        # scikit-learn words it "The 'folds' parameter of GapDiagnosis must be ...": the name is in the text only
        named = re.match(r"The '(\w+)' parameter of ", message)
        name = named[1] if named else None
        raise _error_class()(message, parameter=name, value=getattr(estimator, name, None) if name else None) from None
