"""One root for every error this package raises on purpose.

The CLI turns :class:`InputError` into one line on stderr and exit code 2, and
:class:`AnalysisError` into one line and exit code 1. Everything else is a bug.
"""


class TcrError(Exception):
    """Root of the errors raised by tcr_accuracy."""


class InputError(TcrError, ValueError):
    """Bad input from the user: a file, a row, a column or an argument at fault.

    The message names what is wrong and, where it can, how to fix it. ``parameter`` and
    ``value``, where given, are the library parameter at fault and the value it had. A library
    names no command-line flag: a message names a parameter in keyword form (``folds=1: need at
    least 2``, a hint ``give tool=FRAME``, ``tracker_map["x_mm"]="HEADER"``) or, opening the
    message, by name (``effects: unknown ...``), and the command line words it as the flag that
    sets it (:mod:`tcr_accuracy.cli.flag_names`).
    """

    def __init__(self, message: str = "", *, parameter: str | None = None, value=None):
        super().__init__(message)
        self.parameter = parameter
        self.value = value


class FixedFrameError(InputError):
    """A frame no joint moves was asked for as a TCP (a reflector on the robot's base).

    ``frame``: its name; ``position``: (3,) its place in the robot's base frame [m]. Where a
    measured frame may be a base reference, the caller catches this and uses the position.
    """

    def __init__(self, message: str, frame: str, position):
        super().__init__(message, parameter="tool", value=frame)
        self.frame = frame
        self.position = position


class AnalysisError(TcrError, RuntimeError):
    """The input was valid but the analysis could not reach a result."""


class NotStoredError(TcrError, LookupError):
    """A result read back from its file was asked for what the file does not hold (the per-row
    residual arrays of a diagnosis, its stages).

    Parameters
    ----------
    message : str
        What is missing and how to get it.
    name : str
        The attribute asked for.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> saved = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3).to_json()
    >>> try:
    ...     tcr.Diagnosis.from_json(saved).final_residual
    ... except tcr.NotStoredError as error:
    ...     print(error.name)
    final_residual
    """

    def __init__(self, message: str, name: str = ""):
        super().__init__(message)
        self.name = name
