"""The ``avblocks`` command: the parser and ``main``; each sub-command is a module.

    avblocks run waypoints --set agents=300 --out out/
    avblocks run my_scenario.yaml
    avblocks run my_diagram.py --set n=50 --set drive.gain=2.0
    avblocks run waypoints --backend jax
    avblocks list [--blocks]
    avblocks diagram waypoints -o diagram.svg
    avblocks sweep formation --grid gain=0.5,1,2 --seeds 20 --out sweep.zarr
    avblocks edit formation
    avblocks --version

Sub-commands: :mod:`avblocks.commands` (run, list, diagram, sweep, edit) and the
ROS 2 commands (:mod:`avblocks.interfaces.ros2.cli`).
"""

from __future__ import annotations

import argparse
import os
import sys

from .commands import diagram as _diagram
from .commands import edit as _edit
from .commands import listing as _listing
from .commands import run as _run
from .commands import sweep as _sweep
from .core.errors import AvError
from .scenarios.targets import Loaded, load_any  # noqa: F401  (importable here as before)

cmd_run = _run.cmd_run
cmd_list = _listing.cmd_list
cmd_diagram = _diagram.cmd_diagram


def build_parser():
    from . import __version__
    ap = argparse.ArgumentParser(prog="avblocks", description=(
        "Vectorized building blocks for multi-vehicle systems: run scenarios, "
        "list what is there, draw diagrams."))
    ap.add_argument("--version", action="version", version=f"avblocks {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    r = _run.add_parser(sub)
    from .interfaces.ros2.cli import add_commands, add_run_options
    add_run_options(r)
    add_commands(sub)
    _listing.add_parser(sub)
    _diagram.add_parser(sub)
    _sweep.add_parser(sub)                                   # `avblocks sweep` (issue 14)
    _edit.add_parser(sub)                                    # `avblocks edit` (issue 31)
    return ap


def main(argv=None):
    os.environ.setdefault("MPLBACKEND", "Agg")
    args = build_parser().parse_args(argv)
    try:
        return args.fn(args)
    except AvError as e:
        print(f"avblocks: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("avblocks: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
