"""Command line: ``tcr-accuracy <command> ...`` (``main``), built from one module per topic.

Exit codes: 0 ok, 1 the analysis failed (or an unexpected error), 2 bad input,
130 interrupted (Ctrl-C or SIGTERM). Every failure is one line on stderr naming the
command and what went wrong; ``--debug`` (before or after the command) prints the full
traceback as well.

Every command runs inside :func:`tcr_accuracy.cli.staging.staged_outputs`: its files are
written together when it ends without an error, and not at all otherwise, each through the
one output writer, which holds the outputs named on the command line
(:mod:`tcr_accuracy.cli.output_paths`: no link inside an output folder followed, no input
overwritten, no two outputs on one path). Output paths are checked when the command line is
read, and large work is estimated first and refused above ``--max-memory-gb`` (every command
takes it; default 4 GB).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from contextlib import contextmanager

from .. import __version__
from . import (compare, demo, diagnose, export, iso9283, montecarlo, plan_poses, pose, prediction, report,
               sensitivity, simulate, tolerance, tracker_import, trajectory, view)
from .common import DEFAULT_MEMORY_GB, EXIT_ANALYSIS, EXIT_INPUT, EXIT_OK, Parser, add_memory_argument


# ---------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="tcr-accuracy",
        description="Motion accuracy of serial robots on Pinocchio: kinematics with error "
                    "screws, Monte Carlo accuracy, sim-to-real gap diagnosis, compensation.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    sub.required = True
    for module in COMMANDS:
        module.add_parsers(sub)
    for command_parser in set(sub.choices.values()):
        # also accepted after the command; SUPPRESS keeps a --debug given before it
        command_parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                    help=DEBUG_HELP)
        add_memory_argument(command_parser)
    return parser


DEBUG_HELP = "on an error, print the full Python traceback as well as the one-line message"


#: The commands, one module per topic, in the order --help lists them; each module's
#: ``add_parsers(sub)`` adds its subcommands. Every module imports only argparse and the
#: shared helpers at the top (heavy imports wait inside each command), so --help is instant.
COMMANDS = [pose, demo, montecarlo, sensitivity, tolerance, trajectory, simulate, tracker_import, view, diagnose,
            compare, plan_poses, prediction, iso9283, report, export]


#: Joint-limit warnings already shown in this run, by what they say of the joint: the same
#: joint values are checked by several steps (the parser, the analysis, each robot drawn in
#: the 3D view), and the user needs to read it once, named after their own argument.
_shown_limit_warnings: set[str] = set()

#: ``{dest: flag}`` of the command running (:func:`tcr_accuracy.cli.flag_names.command_flags`):
#: warnings name library parameters, the user reads them as flags.
_flags: dict[str, str] = {}


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    from ..model.robot import JointLimitWarning, MissingMeshWarning
    from .flag_names import in_flags

    text = in_flags(str(message), _flags, getattr(category, "parameter", None))
    if issubclass(category, (JointLimitWarning, MissingMeshWarning)):
        # without the source ("--q: ", "q: ", "nominal: q: "); a robot loaded twice warns of its meshes once
        key = text[text.find("joint "):] if issubclass(category, JointLimitWarning) else text
        if key in _shown_limit_warnings:
            return
        _shown_limit_warnings.add(key)
    from .staging import hold_message

    hold_message(sys.stderr, f"tcr-accuracy: warning: {text}\n", "warning")


#: How many main() calls are running (``demo`` runs ``montecarlo`` and ``diagnose`` through
#: main); an unexpected error in an inner one goes up to the outermost, which reports it.
_depth = 0


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code.

    Bad input (:class:`InputError`) is one line and exit code 2, a failed analysis
    (:class:`AnalysisError`) one line and 1, anything else (a bug, an unhandled case, no
    memory left) one line naming the command, the exception's type and message, and 1.
    With ``--debug`` the traceback is printed before that line.
    """
    global _depth, _flags

    argv = list(sys.argv[1:] if argv is None else argv)
    # read before parsing too, so that a failure while building the parser is traced as well
    debug = "--debug" in argv
    command = next((a for a in argv if not a.startswith("-")), None)
    if _depth == 0:
        _shown_limit_warnings.clear()
    _depth += 1
    outer_flags = _flags  # demo's steps run through main: each speaks of its own flags
    try:
        return _main(argv, debug, command)
    finally:
        _depth -= 1
        _flags = outer_flags


def _main(argv: list[str], debug: bool, command: str | None) -> int:
    global _flags
    from ..exceptions import AnalysisError, InputError
    from .flag_names import command_flags, in_flags

    name = f"tcr-accuracy {command}" if command else "tcr-accuracy"
    stage = None
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # --help, --version, or a usage error already said in one line
            return exc.code if isinstance(exc.code, int) else EXIT_INPUT
        _flags = command_flags(parser, args)
        from .output_paths import outputs_of_command

        outputs = outputs_of_command(parser, args)  # and no output over an input or another output
        args.argv = argv  # the command as typed, for reports
        name = f"tcr-accuracy {args.command}"
        debug = debug or getattr(args, "debug", False)  # also an abbreviated --deb
        from .staging import staged_outputs
        from ..input_files import memory_budget
        from ..model.ros_packages import package_dirs_given
        from .held import held_stdout

        # every file of the run is written at its end, together, or not at all, and what it
        # prints after them; SIGTERM and SIGHUP are interrupts until the commit is done, so that
        # one during the commit still cleans up
        budget = (getattr(args, "max_memory_gb", None) or DEFAULT_MEMORY_GB) * 1e9  # every file read is held to it
        with warnings.catch_warnings(), _terminate_as_interrupt(), held_stdout(), staged_outputs(outputs) as stage, \
                package_dirs_given(getattr(args, "package_dir", None)), \
                memory_budget(budget, "use a smaller file, or allow more with --max-memory-gb"):
            warnings.simplefilter("default", UserWarning)
            warnings.showwarning = _show_warning
            return args.run(args)
    except InputError as exc:  # a library's message names its parameters: the user reads the flags
        _report(f"{name}: error: {in_flags(str(exc), _flags, exc.parameter)}", debug)
        return EXIT_INPUT
    except AnalysisError as exc:
        _show_held_warnings(stage)
        _report(f"{name}: analysis failed: {in_flags(str(exc), _flags)}", debug)
        return EXIT_ANALYSIS
    except KeyboardInterrupt:
        if stage is not None and stage.committed:  # stopped once every file was in place: done
            return EXIT_OK
        _report("tcr-accuracy: interrupted", debug)
        return 130
    except BrokenPipeError:  # output piped into `head` and closed: not an error of ours
        import os

        try:  # so that Python's own flush of stdout at exit does not fail again
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):  # stdout is no file (captured, replaced)
            pass
        return EXIT_OK
    except MemoryError as exc:
        _show_held_warnings(stage)
        _report(f"{name}: out of memory ({_describe(exc)}); try fewer samples, poses or measurements"
                f"{'' if debug else ', or rerun with --debug for the traceback'}", debug)
        return EXIT_ANALYSIS
    except Exception as exc:
        if _depth > 1:  # an inner main (demo's steps): the outermost one reports it
            raise
        _show_held_warnings(stage)
        _report(f"{name}: unexpected error: {_describe(exc)}"
                f"{'' if debug else ' (rerun with --debug for the traceback)'}", debug)
        return EXIT_ANALYSIS


def _show_held_warnings(stage) -> None:
    if stage is not None:
        from .held import show_warnings_of

        show_warnings_of(stage)


@contextmanager
def _terminate_as_interrupt():
    """SIGTERM (a kill, a job scheduler's stop) and SIGHUP (the terminal closed) end the run as
    Ctrl-C does: through the exception handlers, so staged and temporary files are removed
    (outermost main only; :func:`tcr_accuracy.cli.signals.as_interrupt`)."""
    if _depth > 1:
        yield
        return
    from .signals import as_interrupt

    with as_interrupt():
        yield


def _describe(exc: BaseException) -> str:
    """``Type: message`` on one line (a message over several lines is joined with spaces)."""
    message = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {message}" if message else type(exc).__name__


#: The longest error line [characters]: a message quoting a huge file's content is cut.
MAX_LINE = 1000


def _report(line: str, debug: bool) -> None:
    """One line on stderr, at most MAX_LINE long; with --debug, the traceback of the exception
    being handled first."""
    if debug:
        import traceback

        traceback.print_exc(file=sys.stderr)
    line = " ".join(line.split())
    if len(line) > MAX_LINE:
        line = line[: MAX_LINE - 3] + "..."
    sys.stderr.write(line + "\n")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
