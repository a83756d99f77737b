"""``tcr-accuracy view``: the robot in 3D at a pose, optionally with a sampled TCP error cloud.

Other commands add the same output options with two calls::

    from .view import add_view_arguments, emit_view
    add_view_arguments(parser)          # --view [HTML], --serve, --open
    ...
    scene = Scene(title); scene.add_robot(robot, q, "nominal"); ...
    emit_view(scene, args)              # writes and/or serves what was asked

(the analysis commands do it through :class:`tcr_accuracy.cli.output.RunOutput`).
"""

from __future__ import annotations

import argparse
import sys

from .common import (EXIT_OK, MAX_COUNT, add_quiet_argument, add_robot_arguments, check_memory, format_joint_values,
                     integer, joint_value, joint_values_si, number, output_file, output_file_only, sample_bytes,
                     seed_value, status)

DEFAULT_VIEW_FILE = "view.html"


def add_view_arguments(parser: argparse.ArgumentParser, *, always: bool = False) -> None:
    """Add ``--view [HTML]``, ``--serve`` and ``--open`` to a subcommand's parser.

    always : bool
        For ``view`` itself: ``--view FILE`` (as on every other command; ``--html`` is
        kept as its older name) names the file, written unless only ``--serve`` is asked
        for. Other commands get ``--view`` (off unless given).
    """
    if always:
        parser.add_argument("--view", "--html", dest="html", default=None, type=output_file_only, metavar="FILE",
                            help=f"write the view as one self-contained HTML file that opens in any "
                                 f"browser without a server (default: {DEFAULT_VIEW_FILE}, unless only "
                                 "--serve is given)")
    else:
        parser.add_argument("--view", nargs="?", const=DEFAULT_VIEW_FILE, default=None, type=output_file,
                            metavar="HTML",
                            help="also write a 3D view (meshcat) as one self-contained HTML file "
                                 f"(default name: {DEFAULT_VIEW_FILE})")
    parser.add_argument("--serve", action="store_true",
                        help="serve the 3D view live on http://127.0.0.1 (localhost only) until Ctrl-C")
    parser.add_argument("--open", action="store_true", help="with --serve: open the page in a browser")


def emit_view(scene, args) -> None:
    """Write and/or serve a :class:`~tcr_accuracy.view.viewer.Scene` as the arguments ask."""
    write_view(scene, args)
    serve_view(scene, args)


def view_file(args) -> str | None:
    """The file of ``--view [HTML]`` (``--html`` for ``view``, whose default is
    :data:`DEFAULT_VIEW_FILE` unless only ``--serve`` is asked for), or None."""
    html_file = getattr(args, "html", None) or getattr(args, "view", None)
    if html_file is None and not args.serve and hasattr(args, "html"):
        html_file = DEFAULT_VIEW_FILE
    return html_file


def write_view(scene, args):
    """The static page of ``--view [HTML]`` (``--html`` for ``view``), if asked; returns its path or None."""
    from .staging import write_text

    html_file = view_file(args)
    if html_file is None:
        return None
    path = write_text(html_file, scene.static_html())
    status(args, f"3D view written to {path} (open it in a browser; no server needed)")
    return path


def serve_view(scene, args) -> None:
    """With ``--serve``: serve the scene on 127.0.0.1 until Ctrl-C (or the server ends)."""
    if not args.serve:
        return
    import time

    from .staging import commit_staged

    commit_staged()  # the run's files are done: write them before serving until Ctrl-C

    live = scene.serve(open_browser=args.open)
    # on stderr (stdout may be --json -), and even with --quiet: the URL is what was asked for
    sys.stderr.write(f"3D view served at {live.url} (localhost only); Ctrl-C to stop\n")
    sys.stderr.flush()
    try:
        while live.process.poll() is None:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        live.close()


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "view", help="the robot in 3D (meshcat), optionally with a sampled TCP error cloud",
        description="Draws the robot from its URDF visuals at the given joint values (revolute "
                    "[deg], prismatic [mm]; default: the working pose). With --error-preset, "
                    "samples as-built robots from the seed's error tables and adds their TCP "
                    "positions coloured by |dP|, magnified about the nominal TCP by a factor "
                    "shown in the legend, and the worst sample's as-built robot as a ghost.",
    )
    add_robot_arguments(p)
    p.add_argument("--q", nargs="+", type=joint_value, metavar="VALUE",
                   help="joint values: revolute [deg], prismatic [mm] (default: working pose)")
    p.add_argument("--error-preset", choices=("table1", "table2"), default=None,
                   help="add a TCP error cloud sampled from the seed's Table 1 or Table 2 errors")
    p.add_argument("--samples", type=integer(low=1, high=MAX_COUNT), default=1000,
                   help="error samples for the cloud (default 1000)")
    p.add_argument("--seed", type=seed_value, default=0, help="random seed (default 0)")
    p.add_argument("--magnify", type=number(low=0, low_open=True, high=1e9), default=None,
                   help="magnification of the error cloud (default: a round factor that draws "
                        "the largest error about 0.8 m long)")
    add_view_arguments(p, always=True)
    add_quiet_argument(p)
    # the file written when no --view is given: an output too (cli.output_paths)
    p.set_defaults(run=_run_view, implied_outputs=lambda args: [view_file(args)] if args.html is None else [])


def _run_view(args) -> int:
    import numpy as np

    from ..model.errors import seed_budget
    from ..exceptions import InputError
    from .common import robot_from_args
    from ..view.viewer import Scene

    if args.open and not args.serve:
        raise InputError("--open needs --serve")
    if args.magnify is not None and args.error_preset is None:  # it magnifies the error cloud, and there is none
        raise InputError(f"--magnify {args.magnify:g}: only with --error-preset (it magnifies the TCP error cloud)")
    robot = robot_from_args(args)
    q = joint_values_si(robot, args.q)
    scene = Scene(f"{robot.name} at {format_joint_values(robot, q)}")
    scene.add_robot(robot, q, "nominal")
    if args.error_preset is not None:
        check_memory(args, f"--samples {args.samples}", args.samples * sample_bytes(robot))
        budget = seed_budget(robot, args.error_preset)
        x = budget.sample(args.samples, np.random.default_rng(args.seed))
        magnify = scene.add_tcp_error_cloud(robot, q, x, budget.error_model, magnify=args.magnify)
        scene.add_note(f"{args.samples} samples of the seed's {args.error_preset} errors, seed {args.seed}; "
                       f"cloud and ghost magnified x {magnify:g} about the nominal TCP")
    emit_view(scene, args)
    return EXIT_OK
