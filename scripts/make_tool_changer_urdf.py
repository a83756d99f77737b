#!/usr/bin/env python3
"""Write the tool-changer URDF from its named dimensions.

    python scripts/make_tool_changer_urdf.py                  # rewrite robots/tool_changer.urdf
    python scripts/make_tool_changer_urdf.py --l3-mm 900 --out my_changer.urdf

Link lengths are in millimetres here (the seed's l1..l6 = 315, 210, 796, 560, 240,
165 mm); everything inside the package is SI.
"""

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from tcr_accuracy.cli.staging import write_text
from tcr_accuracy.model.tool_changer import ToolChangerDimensions, tool_changer_urdf

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "robots" / "tool_changer.urdf"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    defaults = ToolChangerDimensions()
    for k in range(1, 7):
        parser.add_argument(f"--l{k}-mm", type=float, default=getattr(defaults, f"l{k}") * 1000,
                            help=f"link length l{k} [mm] (default %(default)g)")
    parser.add_argument("--stroke-mm", type=float, default=defaults.telescope_stroke * 1000,
                        help="telescopic stroke of j4 [mm] (default %(default)g)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output URDF (default: %(default)s)")
    args = parser.parse_args(argv)
    lengths = {f"l{k}": getattr(args, f"l{k}_mm") / 1000 for k in range(1, 7)}
    if any(not (v > 0) for v in list(lengths.values()) + [args.stroke_mm]):
        print("make_tool_changer_urdf: error: lengths and stroke must be > 0 mm", file=sys.stderr)
        return 2
    dims = replace(defaults, telescope_stroke=args.stroke_mm / 1000, **lengths)
    write_text(args.out, tool_changer_urdf(dims))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
