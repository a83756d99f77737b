"""One root for every error this package raises on purpose.

The CLI turns :class:`InputError` into one line on stderr and exit code 2, and
:class:`AnalysisError` into one line and exit code 1. Everything else is a bug.
"""


class TcrError(Exception):
    """Root of the errors raised by tcr_accuracy."""


class InputError(TcrError, ValueError):
    """Bad input from the user: a file, a row, a column or an argument at fault.

    The message names what is wrong and, where it can, how to fix it.
    """


class AnalysisError(TcrError, RuntimeError):
    """The input was valid but the analysis could not reach a result."""
