"""The ``avblocks`` command: the parser and ``main``; each sub-command is a module.

    avblocks run waypoints --set agents=300 --out out/
    avblocks run my_scenario.yaml
    avblocks run my_diagram.py --set n=50 --set drive.gain=2.0
    avblocks run waypoints --backend jax
    avblocks list [--blocks]
    avblocks diagram waypoints -o diagram.svg
    avblocks sweep formation --grid gain=0.5,1,2 --seeds 20 --out sweep.zarr
    avblocks cache clear
    avblocks lab check 1 my_unicycle.py
    avblocks edit formation
    avblocks export avblocks-out/waypoints --mcap
    avblocks --version

Sub-commands: :mod:`avblocks.commands` (run, list, diagram, sweep, cache, edit, export) and the
ROS 2 commands (:mod:`avblocks.interfaces.ros2.cli`).

Scripts may rely on the exit statuses of :data:`EXIT_STATUSES` (also the
epilog of ``avblocks --help`` and docs/cli.md), and on a command ending
quietly when the reader of its output goes away (``avblocks list | head
-1``): what is left unprinted is dropped and the status is what the command
would have returned.
"""

from __future__ import annotations

import argparse
import os
import sys

from .commands import cache as _cache
from .commands import diagram as _diagram
from .commands import edit as _edit
from .commands import export as _export
from .commands import listing as _listing
from .commands import run as _run
from .commands import sweep as _sweep
from .core.errors import AvError
from .labs import cli as _labs
from .scenarios.targets import Loaded, load_any  # noqa: F401  (importable here as before)

cmd_run = _run.cmd_run
cmd_list = _listing.cmd_list
cmd_diagram = _diagram.cmd_diagram


#: the exit statuses of every ``avblocks`` command (the epilog of ``--help``)
EXIT_STATUSES = """\
exit status:
  0      done (also when the reader of the output went away, as with `| head`)
  1      `avblocks lab check`: at least one check failed
  2      bad input: a wrong option, file, scenario, parameter or value (the
         message names it)
  3      `avblocks run`: the run failed (what was simulated is saved);
         `avblocks sweep`: a case failed
  128+N  stopped by signal N and what was simulated saved: 130 Ctrl-C (SIGINT),
         143 SIGTERM, 129 SIGHUP
"""


def build_parser():
    from . import __version__
    ap = argparse.ArgumentParser(prog="avblocks", description=(
        "Vectorized building blocks for multi-vehicle systems: run scenarios, "
        "list what is there, draw diagrams."), epilog=EXIT_STATUSES,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"avblocks {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    r = _run.add_parser(sub)
    from .interfaces.ros2.cli import add_commands, add_run_options
    add_run_options(r)
    add_commands(sub)
    _listing.add_parser(sub)
    _diagram.add_parser(sub)
    _sweep.add_parser(sub)                                   # `avblocks sweep` (issue 14)
    _cache.add_parser(sub)                                   # `avblocks cache` (issue 32)
    _labs.add_parser(sub)                                    # `avblocks lab` (issue 34)
    _edit.add_parser(sub)                                    # `avblocks edit` (issue 31)
    _export.add_parser(sub)                                  # `avblocks export` (issue 45)
    return ap


def _say(msg):
    try:
        print(msg, file=sys.stderr, flush=True)
    except (OSError, ValueError):       # stderr closed as well
        pass


def _reader_gone():
    """The reader of stdout went away: send whatever is left (and the final
    flush at exit) to the null device, so nothing raises again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


def main(argv=None):
    os.environ.setdefault("MPLBACKEND", "Agg")
    rc = 0
    try:
        args = build_parser().parse_args(argv)
        rc = args.fn(args)
        sys.stdout.flush()
        return rc
    except BrokenPipeError:
        _reader_gone()
        return rc
    except AvError as e:
        _say(f"avblocks: error: {e}")
        return 2
    except KeyboardInterrupt:
        _say("avblocks: interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
